//! A session: one world stepping on its own compute thread, driven by
//! commands from gRPC handlers and publishing frames and status on zenoh.

mod access;
mod constraints;
mod encoded;
mod frame_queue;
mod interrupt;
mod latest;
mod optimize;
mod publish;
mod run_target;
mod simulate;
mod snapshot;
mod worker;

use crate::error::ServiceError;
use interrupt::Interrupts;
use meshless_engine::Cancel;
use meshless_engine::design::{self, ConstraintSet, Context};
use meshless_engine::world::Controls;
use meshless_engine::{BuildOptions, Scene, World};
use meshless_proto::{keys, v1};
use meshless_wire::design::SessionEdit;
use meshless_wire::frame::pack_vectors;
use meshless_wire::scene::scene_echo_to_proto;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use tokio::sync::{broadcast, mpsc, oneshot, watch};
use tokio_util::sync::CancellationToken;

pub use access::{Access, check_observers};
pub use encoded::EncodedFrame;
pub use latest::{LatestFrame, Numbered};
pub use optimize::{OptimizeJob, Problem};
pub use publish::Outlet;
pub use run_target::RunTarget;
use simulate::Progress;
pub use simulate::{Simulate, check_request as check_simulate, grpc_deadline};
pub use snapshot::{Decoded, Resumed, encode as encode_snapshot, unfit as snapshot_unfit};
pub use worker::ParticleChange;
use worker::{Message, Queued};

/// A request to the compute thread; applied between steps, except that
/// a Pause (and a deletion, and a `Step` caller giving up) interrupts the
/// step in progress (see `interrupt.rs`).
///
/// The steps of one stepping call (`Step`, `SimulateSteps`) are one
/// command, taken whole before the next stepping command: calls sent
/// together take their steps one after the other, each counting its own.
#[derive(Debug)]
pub enum Command {
    Step(u64),
    /// A `SimulateSteps` call's steps: as `Step`, with how far they are
    /// reported on the channel after each one.
    Simulate(u64, watch::Sender<Option<Progress>>),
    Run(RunTarget),
    Pause,
    Resume,
    Reset,
}

type Reply = oneshot::Sender<Result<v1::SessionStatus, ServiceError>>;

/// Status changes buffered per watcher.
const STATUS_EVENTS: usize = 64;
/// Progress reports queued per optimisation before new ones are dropped.
const PROGRESS_QUEUE: usize = 16;

/// A session's constraints and designs, shared by the gRPC handlers and
/// the compute thread. Never locked across a solve.
#[derive(Debug, Default)]
pub struct DesignState {
    /// What the optimiser meets.
    pub constraints: ConstraintSet,
    /// The world's runtime controls (grabs), as the compute thread last
    /// set them; they share the constraints' names.
    pub controls: Controls,
    /// The last successful optimisation.
    pub last: Option<Arc<v1::DesignResult>>,
    /// The cancel flag of the optimisation queued or running, if any.
    pub running: Option<Cancel>,
    /// Counts changes of the constraints and the last design, so that a
    /// checkpoint knows whether they changed since it was written.
    pub revision: u64,
}

type SharedDesign = Arc<Mutex<DesignState>>;

fn lock(design: &SharedDesign) -> std::sync::MutexGuard<'_, DesignState> {
    design
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// An optimisation handed to the compute thread: its progress reports,
/// then its outcome. Dropping it cancels the optimisation.
#[derive(Debug)]
pub struct Optimization {
    pub progress: mpsc::Receiver<v1::DesignProgress>,
    pub result: oneshot::Receiver<Result<Arc<v1::DesignResult>, ServiceError>>,
    cancel: Cancel,
}

/// On the struct itself rather than a guard field: a type with `Drop`
/// is captured whole, so the task that reads `progress` and `result`
/// holds the flag too. With a `RaiseOnDrop` field, an `async move` block
/// capturing just those two fields left the guard behind, dropped with
/// the handler's frame, and cancelled every optimisation at once.
impl Drop for Optimization {
    fn drop(&mut self) {
        self.cancel.cancel();
    }
}

/// The sending end of the compute thread's channel: it numbers each
/// message (see `interrupt.rs`) and interrupts the work in progress for
/// the messages that cannot wait their turn.
#[derive(Debug)]
struct Mailbox {
    commands: std::sync::mpsc::Sender<Queued>,
    interrupts: Arc<Interrupts>,
}

/// The compute thread has exited.
#[derive(Debug)]
struct Gone;

impl Mailbox {
    /// Queues `message`; an `interrupting` one first interrupts the work
    /// of the messages before it.
    fn send(&self, message: Message, interrupting: bool) -> Result<u64, Gone> {
        self.interrupts.send(interrupting, |number| {
            self.commands.send((number, message)).map_err(|_| Gone)
        })
    }

    /// Sends a command and waits for its answer. A Pause interrupts the
    /// step in progress (and any queued before it), which keeps the last
    /// completed step; dropping the future of a `Step` (or a
    /// `SimulateSteps`) interrupts that step.
    async fn command(
        &self,
        command: Command,
    ) -> Result<Result<v1::SessionStatus, ServiceError>, Gone> {
        let interrupting = matches!(command, Command::Pause);
        let abandons = matches!(command, Command::Step(_) | Command::Simulate(..));
        let (reply, answer) = oneshot::channel();
        let number = self.send(Message::Command(command, reply), interrupting)?;
        let mut pending = Pending {
            answer,
            interrupts: &self.interrupts,
            number,
            abandons,
        };
        let answer = (&mut pending.answer).await;
        pending.abandons = false;
        answer.map_err(|_| Gone)
    }
}

/// A command's answer as its caller waits for it. A `Step` caller that
/// gives up (its call cancelled or past its deadline drops this) stops
/// the step in progress instead of leaving it to run out.
struct Pending<'a> {
    answer: oneshot::Receiver<Result<v1::SessionStatus, ServiceError>>,
    interrupts: &'a Interrupts,
    number: u64,
    /// Whether dropping it unanswered interrupts the command's work:
    /// only a stepping call's, since a run outlives its `Run` call.
    abandons: bool,
}

impl Drop for Pending<'_> {
    fn drop(&mut self) {
        if self.abandons {
            // Closed first: work the compute thread begins after this
            // sees the closed reply instead of the flag.
            self.answer.close();
            self.interrupts.abandon(self.number);
        }
    }
}

/// What a session starts from.
#[derive(Debug)]
pub enum Origin {
    /// A world just built from its scene (boxed, as the other: a world
    /// is hundreds of bytes).
    Built(Box<World>),
    /// A snapshot restored.
    Restored(Box<Resumed>),
}

impl Origin {
    fn world(&self) -> &World {
        match self {
            Self::Built(world) => world.as_ref(),
            Self::Restored(resumed) => &resumed.world,
        }
    }
}

/// The handle gRPC handlers hold. Cheap to share; the world itself lives
/// on the compute thread.
#[derive(Debug)]
pub struct Session {
    pub id: String,
    pub scene: Scene,
    /// The scene as `Session` messages carry it, made once (it can be
    /// large), meshes' bytes left out.
    scene_echo: v1::SceneSpec,
    pub particle_count: usize,
    /// Each modal solid's modes, fixed by the scene.
    modal_modes: Vec<v1::ModalModes>,
    /// Each shell's nodes' rest positions, fixed by the scene.
    shell_nodes: Vec<v1::ShellNodes>,
    /// Creation order, for listings.
    pub serial: u64,
    /// Who may see and drive it.
    pub access: Access,
    mailbox: Mailbox,
    status: watch::Receiver<v1::SessionStatus>,
    events: broadcast::Sender<v1::SessionStatus>,
    latest: LatestFrame,
    cancel: CancellationToken,
    thread: Mutex<Option<std::thread::JoinHandle<()>>>,
    /// What constraints are checked against; fixed by the scene.
    context: Context,
    design: SharedDesign,
    /// Held by one constraint edit from its check to its commit, so that
    /// edits that move the world's grabs apply in the order they commit.
    edits: tokio::sync::Mutex<()>,
    /// The key of the session's sealed payloads, for the callers that may
    /// read it; empty when the server does not seal.
    seal_key: Vec<u8>,
    /// Simulated seconds per wall-clock second of the last step (`f64`
    /// bits), written by the compute thread, read by the metrics.
    realtime_factor: Arc<AtomicU64>,
}

impl Session {
    /// Starts the compute thread for an already built world and declares
    /// the session's zenoh publishers and queryable on `outlet`.
    pub fn start(
        id: String,
        serial: u64,
        origin: Origin,
        options: BuildOptions,
        outlet: Outlet,
        cancel: CancellationToken,
        access: Access,
    ) -> std::io::Result<Arc<Self>> {
        let world = origin.world();
        let scene = world.scene().clone();
        let scene_echo = scene_echo_to_proto(&scene);
        let particle_count = world.particle_count();
        let modal_modes = world
            .modal_solids()
            .map(|(system, solid)| v1::ModalModes {
                system: u32::try_from(system).unwrap_or(u32::MAX),
                frequencies: solid.frequencies(),
                rigid: u32::try_from(solid.zero_modes()).unwrap_or(u32::MAX),
                rest_positions: pack_vectors(solid.rest_positions()),
            })
            .collect();
        let shell_nodes = world
            .shells()
            .map(|(system, shell)| v1::ShellNodes {
                system: u32::try_from(system).unwrap_or(u32::MAX),
                rest_positions: pack_vectors(shell.model().reference()),
            })
            .collect();
        let context = design::context(world);
        let design = SharedDesign::default();
        let initial = v1::SessionStatus {
            session_id: id.clone(),
            state: v1::SessionState::Idle as i32,
            step: 0,
            time: 0.0,
            reason: "created".into(),
            run_until: None,
        };
        let (status_tx, status) = watch::channel(initial);
        let (events, _) = broadcast::channel(STATUS_EVENTS);
        let latest = LatestFrame::new(EncodedFrame::encode(&id, &world.frame()));
        let (frames_tx, frames_rx) = frame_queue::frame_queue();
        let (commands, commands_rx) = std::sync::mpsc::channel();
        let interrupts = Arc::new(Interrupts::default());
        let realtime_factor = Arc::new(AtomicU64::new(0f64.to_bits()));
        let metrics = outlet.metrics.clone();

        let seal_key = outlet
            .sealer
            .as_ref()
            .map(|sealer| sealer.key().bytes().to_vec())
            .unwrap_or_default();
        publish::spawn_frames(outlet.clone(), id.clone(), frames_rx);
        publish::spawn_status(outlet.clone(), id.clone(), events.subscribe());
        publish::spawn_latest(outlet, id.clone(), latest.clone(), cancel.clone());
        // Server shutdown cancels the token before it stops the sessions,
        // and waits for the calls in flight first: a step or optimisation
        // in progress stops now, so that those calls end.
        {
            let (cancel, interrupts, design) = (cancel.clone(), interrupts.clone(), design.clone());
            tokio::spawn(async move {
                cancel.cancelled().await;
                interrupt_all(&interrupts, &design);
            });
        }

        let worker = worker::Worker::new(
            id.clone(),
            origin,
            options,
            worker::Outputs {
                status: status_tx,
                events: events.clone(),
                frames: frames_tx,
                latest: latest.clone(),
                metrics,
                realtime_factor: realtime_factor.clone(),
            },
            design.clone(),
            cancel.clone(),
            interrupts.clone(),
        );
        // Every line the compute thread logs names its session.
        let span = tracing::info_span!("session", id = %id);
        let thread = std::thread::Builder::new()
            .name(format!("session-{id}"))
            .spawn(move || span.in_scope(|| worker.run(commands_rx)))?;
        Ok(Arc::new(Self {
            id,
            scene,
            scene_echo,
            particle_count,
            modal_modes,
            shell_nodes,
            serial,
            access,
            mailbox: Mailbox {
                commands,
                interrupts,
            },
            status,
            events,
            latest,
            cancel,
            thread: Mutex::new(Some(thread)),
            context,
            design,
            edits: tokio::sync::Mutex::new(()),
            seal_key,
            realtime_factor,
        }))
    }

    /// Simulated seconds per wall-clock second of the last step.
    pub fn realtime_factor(&self) -> f64 {
        f64::from_bits(self.realtime_factor.load(Ordering::Relaxed))
    }

    fn gone(&self) -> ServiceError {
        ServiceError::SessionGone(self.id.clone())
    }

    /// The state a snapshot keeps, handed over by the compute thread
    /// between two steps.
    async fn capture(&self) -> Result<snapshot::Captured, ServiceError> {
        let (out, captured) = oneshot::channel();
        self.mailbox
            .send(Message::Capture(out), false)
            .map_err(|Gone| self.gone())?;
        captured.await.map_err(|_| self.gone())
    }

    /// Has the compute thread swap in a restored world.
    async fn swap(&self, resumed: Resumed) -> Result<v1::SessionStatus, ServiceError> {
        let (reply, answer) = oneshot::channel();
        self.mailbox
            .send(Message::Restore(Box::new(resumed), reply), false)
            .map_err(|Gone| self.gone())?;
        answer.await.map_err(|_| self.gone())?
    }

    /// Sends a command to the compute thread and waits for its answer. A
    /// Pause interrupts the step in progress (and any queued before it),
    /// which keeps the last completed step; dropping the future of a
    /// `Step` interrupts that step.
    ///
    /// # Errors
    /// What the worker refused, or [`ServiceError::SessionGone`].
    pub async fn command(&self, command: Command) -> Result<v1::SessionStatus, ServiceError> {
        self.mailbox
            .command(command)
            .await
            .map_err(|Gone| self.gone())?
    }

    /// Applies constraint edits all or nothing; returns the constraints
    /// and controls. When the batch changes the world's controls (grabs
    /// of modal solids), the compute thread sets them on the world
    /// between two steps (a run goes on) before the batch commits, so a
    /// control the world refuses (a point off the solid) refuses the
    /// whole batch.
    ///
    /// # Errors
    /// [`ServiceError::Design`] naming the constraint at fault,
    /// [`ServiceError::InvalidArgument`] for controls the world refuses;
    /// nothing is changed.
    pub async fn edit_constraints(
        &self,
        edits: &[SessionEdit],
    ) -> Result<Vec<v1::Constraint>, ServiceError> {
        let _serial = self.edits.lock().await;
        let (next, controls, moved) = {
            let design = lock(&self.design);
            let (next, controls) =
                constraints::plan(&design.constraints, &design.controls, edits, &self.context)
                    .map_err(design::DesignError::from)?;
            let moved = controls != design.controls;
            (next, controls, moved)
        };
        if moved {
            let (reply, answer) = oneshot::channel();
            self.mailbox
                .send(Message::Controls(controls.clone(), reply), false)
                .map_err(|Gone| self.gone())?;
            answer.await.map_err(|_| self.gone())??;
        }
        let mut design = lock(&self.design);
        design.constraints = next;
        design.controls = controls;
        design.revision += 1;
        Ok(constraints::list(&design.constraints, &design.controls))
    }

    /// Queues a change of particles for the next step, between two steps
    /// (a run goes on); returns the ids the new particles get.
    ///
    /// # Errors
    /// [`ServiceError::Particles`] for a change the world refuses (nothing
    /// is queued then), [`ServiceError::Faulted`] for a faulted session.
    pub async fn change_particles(
        &self,
        change: ParticleChange,
    ) -> Result<std::ops::Range<u32>, ServiceError> {
        let (reply, answer) = oneshot::channel();
        self.mailbox
            .send(Message::Particles(change, reply), false)
            .map_err(|Gone| self.gone())?;
        answer.await.map_err(|_| self.gone())?
    }

    /// The constraints and controls in name order.
    pub fn constraints(&self) -> Vec<v1::Constraint> {
        let design = lock(&self.design);
        constraints::list(&design.constraints, &design.controls)
    }

    /// Changes of the constraints and the last design so far.
    pub fn design_revision(&self) -> u64 {
        lock(&self.design).revision
    }

    /// The last successful design.
    ///
    /// # Errors
    /// [`ServiceError::NoDesign`] before the first.
    pub fn last_design(&self) -> Result<Arc<v1::DesignResult>, ServiceError> {
        lock(&self.design)
            .last
            .clone()
            .ok_or_else(|| ServiceError::NoDesign(self.id.clone()))
    }

    /// Queues an optimisation on the compute thread; it starts once the
    /// commands before it are done, and commands after it wait for it.
    ///
    /// # Errors
    /// [`ServiceError::WrongState`] while another optimisation is queued
    /// or running; [`ServiceError::SessionGone`].
    pub fn optimize(&self, job: OptimizeJob) -> Result<Optimization, ServiceError> {
        let cancel = Cancel::new();
        {
            let mut design = lock(&self.design);
            if design.running.is_some() {
                return Err(ServiceError::WrongState {
                    session_id: self.id.clone(),
                    state: "optimising",
                    action: "optimise",
                    hint: "cancel the running optimisation or wait for it",
                });
            }
            design.running = Some(cancel.clone());
        }
        let (progress_tx, progress) = mpsc::channel(PROGRESS_QUEUE);
        let (result_tx, result) = oneshot::channel();
        let channels = optimize::Channels {
            progress: progress_tx,
            result: result_tx,
            cancel: cancel.clone(),
        };
        if let Err(Gone) = self
            .mailbox
            .send(Message::Optimize(Box::new(job), channels), false)
        {
            lock(&self.design).running = None;
            return Err(self.gone());
        }
        Ok(Optimization {
            progress,
            result,
            cancel,
        })
    }

    /// Cancels the optimisation queued or running; returns whether there
    /// was one.
    pub fn cancel_optimize(&self) -> bool {
        match &lock(&self.design).running {
            Some(cancel) => {
                cancel.cancel();
                true
            }
            None => false,
        }
    }

    /// The current status (step and time are kept current while running).
    pub fn status(&self) -> v1::SessionStatus {
        self.status.borrow().clone()
    }

    /// Every state change from now on.
    pub fn subscribe(&self) -> broadcast::Receiver<v1::SessionStatus> {
        self.events.subscribe()
    }

    pub fn latest_frame(&self) -> Arc<EncodedFrame> {
        self.latest.get().frame
    }

    /// The latest frame once it is newer than frame number `after`,
    /// waiting at most `wait`; `None` when none came in time or the
    /// session was deleted meanwhile.
    pub async fn next_frame(&self, after: u64, wait: std::time::Duration) -> Option<Numbered> {
        tokio::select! {
            latest = self.latest.newer_than(after, wait) => latest,
            () = self.cancel.cancelled() => None,
        }
    }

    /// The `Session` message for this session, without its scene: what
    /// `ListSessions` returns, so that a list of many sessions stays small
    /// however large their scenes (up to `--max-request-mb` each).
    pub fn summary(&self) -> v1::Session {
        v1::Session {
            scene: None,
            ..self.to_proto()
        }
    }

    /// The `Session` message for this session, seal key included: only
    /// for callers that may read it.
    pub fn to_proto(&self) -> v1::Session {
        v1::Session {
            id: self.id.clone(),
            name: self.scene.name.clone(),
            status: Some(self.status()),
            zenoh_key_prefix: keys::session_prefix(&self.id),
            particle_count: self.particle_count as u64,
            scene: Some(self.scene_echo.clone()),
            owner: self.access.owner().to_owned(),
            observers: self.access.observers().to_vec(),
            seal_key: self.seal_key.clone(),
            modal_modes: self.modal_modes.clone(),
            shell_nodes: self.shell_nodes.clone(),
            system_kinds: self
                .scene
                .systems
                .iter()
                .map(|s| s.kind_name().to_owned())
                .collect(),
            realtime_factor: self.realtime_factor(),
        }
    }

    /// Stops the compute thread (interrupting the step or optimisation
    /// in hand) and waits for it. Blocking: call from a blocking context.
    pub fn shut_down(&self) {
        stop(&self.cancel, &self.mailbox, &self.design);
        let thread = self
            .thread
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        if let Some(thread) = thread
            && thread.join().is_err()
        {
            tracing::error!(session = %self.id, "compute thread panicked");
        }
    }
}

/// Tells the compute thread to exit: the token, then every flag of its
/// work in hand, then the message that wakes it if it waits for one.
fn stop(cancel: &CancellationToken, mailbox: &Mailbox, design: &SharedDesign) {
    cancel.cancel();
    interrupt_all(&mailbox.interrupts, design);
    // The thread may be gone already.
    let _ = mailbox.send(Message::Shutdown, false);
}

/// Interrupts every step and the optimisation of a session shutting down.
fn interrupt_all(interrupts: &Interrupts, design: &SharedDesign) {
    interrupts.interrupt_all();
    if let Some(cancel) = &lock(design).running {
        cancel.cancel();
    }
}
