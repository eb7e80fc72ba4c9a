//! The compute thread of a session. It owns the world, applies commands
//! between steps, and hands frames and status to the publishing tasks
//! without ever waiting on them. Each step reads the flag of the work it
//! belongs to (`interrupt.rs`), so a Pause or a deletion stops it within
//! a sub-step; the step is undone and the session keeps its last
//! completed step.
//!
//! A stepping call (`Step`, `SimulateSteps`, up to a billion steps) is
//! one command, but between two of its steps the thread serves what a
//! running session serves between steps: snapshots and checkpoints
//! (`Capture`) and runtime controls (grabs). A restore is refused meanwhile, as while
//! running; every other message waits for the call, in order, so that
//! the steps of two calls never interleave.

use super::encoded::EncodedFrame;
use super::frame_queue::FrameSender;
use super::interrupt::Interrupts;
use super::optimize::{self, Channels, OptimizeJob, WarmStart};
use super::run_target::RunTarget;
use super::simulate::Progress;
use super::snapshot::{Captured, Resumed, ResumedSession};
use super::{Command, LatestFrame, Origin, Reply, SharedDesign, lock};
use crate::error::{ServiceError, state_name};
use crate::metrics::Metrics;
use meshless_engine::world::Controls;
use meshless_engine::{BuildOptions, Cancel, StepError, World};
use meshless_proto::v1::{SessionState, SessionStatus};
use std::collections::VecDeque;
use std::panic::AssertUnwindSafe;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, RecvTimeoutError, TryRecvError};
use std::time::{Duration, Instant};
use tokio::sync::{broadcast, watch};
use tokio_util::sync::CancellationToken;

/// A message to the compute thread.
#[derive(Debug)]
pub enum Message {
    Command(Command, Reply),
    Optimize(Box<OptimizeJob>, Channels),
    /// Hands over the state a snapshot keeps, between two steps; a run
    /// goes on.
    Capture(tokio::sync::oneshot::Sender<Captured>),
    /// Swaps in a restored world and the session state around it.
    Restore(Box<Resumed>, Reply),
    /// Replaces the world's runtime controls (grabs of modal solids,
    /// besides each scene's own) from the next step; a run goes on.
    Controls(
        Controls,
        tokio::sync::oneshot::Sender<Result<(), ServiceError>>,
    ),
    /// Removes and adds particles from the next step (see
    /// [`ParticleChange`]); a run goes on.
    Particles(
        ParticleChange,
        tokio::sync::oneshot::Sender<Result<std::ops::Range<u32>, ServiceError>>,
    ),
    /// Stop and exit; sent on delete and server shutdown.
    Shutdown,
}

/// A `ChangeParticles` request: which particles of which system leave by
/// id, and the new ones' positions and velocities.
#[derive(Debug)]
pub struct ParticleChange {
    /// The system's index in the scene.
    pub system: usize,
    /// Ids of the particles to remove.
    pub remove: Vec<usize>,
    /// Where the new particles start, m.
    pub positions: Vec<[f64; 3]>,
    /// Their velocities, m/s.
    pub velocities: Vec<[f64; 3]>,
}

/// A message with its number in the channel's order (see `interrupt.rs`).
pub type Queued = (u64, Message);

/// Where the worker's results go.
#[derive(Debug)]
pub struct Outputs {
    pub status: watch::Sender<SessionStatus>,
    pub events: broadcast::Sender<SessionStatus>,
    pub frames: FrameSender,
    pub latest: LatestFrame,
    pub metrics: Arc<Metrics>,
    /// The last step's real-time factor, as `f64` bits.
    pub realtime_factor: Arc<std::sync::atomic::AtomicU64>,
}

/// Wall-clock pacing of a run with a real-time factor.
#[derive(Debug, Clone, Copy)]
struct Pacing {
    wall_start: Instant,
    sim_start: f64,
    factor: f64,
}

/// Longest single wait of a paced run: the loop wakes at least this often
/// to notice cancellation, however slow the factor.
const MAX_PACING_WAIT: Duration = Duration::from_millis(100);

impl Pacing {
    /// How long to wait before the next step to keep to the factor, at
    /// most [`MAX_PACING_WAIT`]. Never panics: a wait too long for a
    /// `Duration` (a tiny factor) is the cap.
    fn wait(&self, sim_time: f64) -> Option<Duration> {
        let due = (sim_time - self.sim_start) / self.factor;
        let elapsed = self.wall_start.elapsed().as_secs_f64();
        (due > elapsed).then(|| {
            Duration::try_from_secs_f64(due - elapsed)
                .map_or(MAX_PACING_WAIT, |wait| wait.min(MAX_PACING_WAIT))
        })
    }
}

#[derive(Debug)]
pub struct Worker {
    id: String,
    world: World,
    options: BuildOptions,
    out: Outputs,
    cancel: CancellationToken,
    state: SessionState,
    reason: String,
    run: Option<RunTarget>,
    pacing: Option<Pacing>,
    published_step: Option<u64>,
    dropped_frames: u64,
    design: SharedDesign,
    warm: Option<WarmStart>,
    interrupts: Arc<Interrupts>,
    /// The flag of the stepping work in hand (a `Step`, a run), which
    /// every step reads.
    work: Cancel,
    /// The stepping call in progress, while its steps are taken.
    call: Option<Call>,
    /// Messages read between the steps of a call that wait for its end,
    /// in the order they came; read before the channel.
    deferred: VecDeque<Queued>,
}

/// A stepping call as the thread takes its steps.
#[derive(Debug, Clone, Copy)]
struct Call {
    /// `Step` or `SimulateSteps`, as the protocol names it.
    name: &'static str,
    steps: u64,
    done: u64,
}

impl Call {
    fn new(name: &'static str, steps: u64) -> Self {
        Self {
            name,
            steps,
            done: 0,
        }
    }
}

impl std::fmt::Display for Call {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} of {} steps, {} done",
            self.name, self.steps, self.done
        )
    }
}

/// How one step went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Advance {
    Stepped,
    /// Interrupted and undone: the world is at the last completed step.
    Interrupted,
    /// Refused before it began (the step counter is full); the work in
    /// hand ends.
    Refused,
    /// The step failed; the session faulted.
    Faulted,
}

impl Worker {
    pub fn new(
        id: String,
        origin: Origin,
        options: BuildOptions,
        out: Outputs,
        design: SharedDesign,
        cancel: CancellationToken,
        interrupts: Arc<Interrupts>,
    ) -> Self {
        let (world, resumed) = match origin {
            Origin::Built(world) => (*world, None),
            Origin::Restored(resumed) => {
                let Resumed { world, session } = *resumed;
                (world, Some(session))
            }
        };
        let mut worker = Self {
            id,
            world,
            options,
            out,
            cancel,
            state: SessionState::Idle,
            reason: "created".into(),
            run: None,
            pacing: None,
            published_step: None,
            dropped_frames: 0,
            design,
            warm: None,
            interrupts,
            work: Cancel::new(),
            call: None,
            deferred: VecDeque::new(),
        };
        match resumed {
            Some(session) => worker.take(session),
            None => worker.publish_frame(),
        }
        worker
    }

    /// The thread's main loop: block for commands while idle, step while
    /// running, exit on shutdown. A run whose flag is up waits for the
    /// message that raised it (a Pause, a shutdown) instead of stepping.
    pub fn run(mut self, messages: Receiver<Queued>) {
        loop {
            let stepping = self.state == SessionState::Running && !self.work.is_cancelled();
            let message = if let Some(deferred) = self.deferred.pop_front() {
                Some(deferred)
            } else if stepping {
                match self.pacing.and_then(|p| p.wait(self.world.clock().time)) {
                    Some(wait) => match messages.recv_timeout(wait) {
                        Ok(m) => Some(m),
                        Err(RecvTimeoutError::Timeout) => None,
                        Err(RecvTimeoutError::Disconnected) => break,
                    },
                    None => match messages.try_recv() {
                        Ok(m) => Some(m),
                        Err(TryRecvError::Empty) => None,
                        Err(TryRecvError::Disconnected) => break,
                    },
                }
            } else {
                messages.recv().ok().or(Some((0, Message::Shutdown)))
            };
            match message {
                Some((number, Message::Command(command, reply))) => {
                    let result = self
                        .guarded(|w| w.handle(command, number, &reply, &messages))
                        .and_then(|r| r);
                    // The caller may have gone away; the command still applied.
                    let _ = reply.send(result);
                }
                Some((_, Message::Optimize(job, channels))) => {
                    // On a panic the result channel drops with the closure:
                    // the caller hears that the optimisation ended.
                    let _ = self.guarded(|w| w.optimize(&job, channels));
                }
                Some((_, Message::Capture(out))) => {
                    if let Ok(captured) = self.guarded(|w| w.capture()) {
                        // The caller may have gone away.
                        let _ = out.send(captured);
                    }
                }
                Some((_, Message::Restore(resumed, reply))) => {
                    let result = self.guarded(|w| w.restore(*resumed)).and_then(|r| r);
                    let _ = reply.send(result);
                }
                Some((_, Message::Controls(controls, reply))) => {
                    let result = self.guarded(|w| w.set_controls(controls)).and_then(|r| r);
                    let _ = reply.send(result);
                }
                Some((_, Message::Particles(change, reply))) => {
                    let result = self
                        .guarded(|w| w.change_particles(&change))
                        .and_then(|r| r);
                    let _ = reply.send(result);
                }
                Some((_, Message::Shutdown)) => break,
                None if self.cancel.is_cancelled() => break,
                None => {
                    let due = self.pacing.and_then(|p| p.wait(self.world.clock().time));
                    if due.is_none() {
                        let _ = self.guarded(Self::advance_run);
                    }
                }
            }
        }
        if self.dropped_frames > 0 {
            tracing::info!(session = %self.id, dropped = self.dropped_frames, "frames dropped under congestion");
        }
        self.set_state(SessionState::Closed, "deleted");
    }

    /// Runs `work` on the worker, containing a panic in it. A panic is a
    /// bug, never a user's input, but it must not kill the compute thread
    /// (the session would stay listed and answer nothing): the session
    /// faults with the panic's message instead, keeps its last good frame,
    /// refuses steps until reset (which rebuilds the world, whatever state
    /// the panic left it in), and the caller gets INTERNAL.
    fn guarded<T>(&mut self, work: impl FnOnce(&mut Self) -> T) -> Result<T, ServiceError> {
        let payload = match std::panic::catch_unwind(AssertUnwindSafe(|| work(self))) {
            Ok(value) => return Ok(value),
            Err(payload) => payload,
        };
        let message = payload
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into());
        tracing::error!(session = %self.id, "session faulted by a panic: {message}");
        self.out.metrics.fault(None);
        lock(&self.design).running = None;
        self.run = None;
        self.pacing = None;
        let reason = format!("internal error ({message}); reset or delete the session");
        self.set_state(SessionState::Faulted, &reason);
        Err(ServiceError::Internal(reason))
    }

    /// Applies command `number`; `reply` is where its answer goes, and a
    /// closed one (the caller gave up) ends a long `Step` at the next step.
    /// A stepping call serves `inbox` between its steps.
    fn handle(
        &mut self,
        command: Command,
        number: u64,
        reply: &Reply,
        inbox: &Receiver<Queued>,
    ) -> Result<SessionStatus, ServiceError> {
        match command {
            Command::Step(steps) => self.step(Call::new("Step", steps), None, number, reply, inbox),
            Command::Simulate(steps, progress) => self.step(
                Call::new("SimulateSteps", steps),
                Some(&progress),
                number,
                reply,
                inbox,
            ),
            Command::Run(target) => self.start_run(target, number),
            Command::Pause => {
                if self.state == SessionState::Running {
                    self.publish_if_stale();
                    self.set_state(SessionState::Paused, "paused");
                }
                Ok(self.status())
            }
            Command::Resume => self.resume(number),
            Command::Reset => self.reset(),
        }
    }

    /// Runs an optimisation to its end and reports it. The world and the
    /// constraints are left as they were; a success becomes the session's
    /// last design.
    fn optimize(&mut self, job: &OptimizeJob, channels: Channels) {
        let outcome = if matches!(self.state, SessionState::Running | SessionState::Faulted) {
            Err(self.refuse("optimise", "pause it first"))
        } else {
            let constraints = lock(&self.design).constraints.clone();
            optimize::solve(
                &self.id,
                &self.world,
                &constraints,
                job,
                self.warm.as_ref(),
                &channels,
                &self.cancel,
            )
        };
        let Channels {
            progress, result, ..
        } = channels;
        // The progress stream ends before the result.
        drop(progress);
        let outcome = outcome.map(|solved| {
            if solved.warm.is_some() {
                self.warm = solved.warm;
            }
            for frame in solved.playback {
                // Waits for the publisher rather than dropping: playback
                // frames are few and each one matters.
                let frame = Arc::new(EncodedFrame::encode(&self.id, &frame));
                if self.out.frames.blocking_send(frame).is_err() {
                    self.dropped_frames += 1;
                    self.out.metrics.frame_dropped();
                }
            }
            let result = Arc::new(solved.result);
            let mut design = lock(&self.design);
            design.last = Some(result.clone());
            design.revision += 1;
            result
        });
        lock(&self.design).running = None;
        if let Err(e) = &outcome {
            tracing::info!(session = %self.id, "optimisation ended: {e}");
        }
        // The caller may have gone away.
        let _ = result.send(outcome);
    }

    /// The state a snapshot keeps. A running session is kept as paused
    /// with its run, so that a restore resumes it on request only; one
    /// inside a stepping call as paused at the step it reached, as the
    /// call would leave it (the call's other steps are the caller's).
    fn capture(&self) -> Captured {
        let (state, reason, run) = match (self.call, self.state) {
            (Some(call), _) => (
                SessionState::Paused,
                format!("stepping when the snapshot was taken ({call})"),
                None,
            ),
            (None, SessionState::Running) => (
                SessionState::Paused,
                "running when the snapshot was taken; Resume continues the run".to_owned(),
                self.run,
            ),
            (None, state) => (state, self.reason.clone(), self.run),
        };
        Captured {
            world: self.world.state(),
            state,
            reason,
            run,
            warm: self.warm.clone(),
        }
    }

    /// Holds `controls` from the next step.
    fn set_controls(&mut self, controls: Controls) -> Result<(), ServiceError> {
        self.world
            .set_controls(controls)
            .map_err(|e| ServiceError::InvalidArgument {
                field: "edits".into(),
                message: e.to_string(),
            })
    }

    /// Queues a change of particles for the next step; refused while
    /// faulted (the world is the last good one, which a reset replaces).
    fn change_particles(
        &mut self,
        change: &ParticleChange,
    ) -> Result<std::ops::Range<u32>, ServiceError> {
        if self.state == SessionState::Faulted {
            return Err(self.refuse("change the particles of", "reset it first"));
        }
        let ParticleChange {
            system,
            remove,
            positions,
            velocities,
        } = change;
        Ok(self
            .world
            .change_particles(*system, remove, positions, velocities)?)
    }

    /// Swaps in a restored world, unless running; a faulted session may
    /// be restored (as it may be reset).
    fn restore(&mut self, resumed: Resumed) -> Result<SessionStatus, ServiceError> {
        if self.state == SessionState::Running {
            return Err(ServiceError::WrongState {
                session_id: self.id.clone(),
                state: state_name(self.state),
                action: "restore a snapshot into",
                hint: "pause it first",
            });
        }
        let Resumed { world, session } = resumed;
        self.world = world;
        self.take(session);
        Ok(self.status())
    }

    /// Takes the session state around a restored world (already in
    /// place), and publishes its frame.
    fn take(&mut self, resumed: ResumedSession) {
        let ResumedSession {
            state,
            reason,
            run,
            warm,
            constraints,
            controls,
            last,
        } = resumed;
        self.run = run;
        self.pacing = None;
        self.warm = warm;
        let last = last.map(|mut design| {
            design.session_id.clone_from(&self.id);
            design
        });
        lock(&self.design).resume(constraints, controls, last);
        self.published_step = None;
        self.publish_frame();
        self.set_state(state, &reason);
    }

    /// Sets the old world's runtime controls on a world rebuilt from
    /// the same scene. They held on it, so they hold again; should one
    /// not, the world keeps its scene's grabs, the session forgets the
    /// controls and the log says why.
    fn hold_controls(&mut self, controls: Controls) {
        if controls.is_empty() {
            return;
        }
        if let Err(e) = self.world.set_controls(controls) {
            tracing::warn!(session = %self.id, "controls not held again: {e}");
            let mut design = lock(&self.design);
            design.controls = Controls::new();
            design.revision += 1;
        }
    }

    fn refuse(&self, action: &'static str, hint: &'static str) -> ServiceError {
        if self.state == SessionState::Faulted {
            ServiceError::Faulted {
                session_id: self.id.clone(),
                reason: self.reason.clone(),
            }
        } else {
            ServiceError::WrongState {
                session_id: self.id.clone(),
                state: state_name(self.state),
                action,
                hint,
            }
        }
    }

    /// Takes the steps of `call`, command `number`, reporting each on
    /// `progress`; stops early when the session is shut down, the caller
    /// is gone (an abandoned `Step(1_000_000)` would otherwise hold the
    /// session for as long as it takes) or a Pause interrupts it, the
    /// step in progress undone. Between two steps it serves `inbox` as a
    /// run does (`between_steps`).
    ///
    /// # Errors
    /// Running or faulted: [`ServiceError::WrongState`] or
    /// [`ServiceError::Faulted`]; steps that would pass the largest step
    /// count: [`ServiceError::StepCounterFull`]. Nothing changes.
    fn step(
        &mut self,
        mut call: Call,
        progress: Option<&watch::Sender<Option<Progress>>>,
        number: u64,
        reply: &Reply,
        inbox: &Receiver<Queued>,
    ) -> Result<SessionStatus, ServiceError> {
        if matches!(self.state, SessionState::Running | SessionState::Faulted) {
            return Err(self.refuse("step", "pause it first"));
        }
        self.check_counter(call.steps)?;
        self.work = self.interrupts.begin(number);
        let start = self.world.clock();
        let began = Instant::now();
        let report = |world: &World, done| {
            if let Some(progress) = progress {
                let clock = world.clock();
                progress.send_replace(Some(Progress {
                    done,
                    step: clock.step,
                    time: clock.time,
                    start_time: start.time,
                    began,
                }));
            }
        };
        report(&self.world, 0);
        let mut outcome = Advance::Stepped;
        while call.done < call.steps && !self.cancel.is_cancelled() && !reply.is_closed() {
            outcome = self.advance();
            if outcome != Advance::Stepped {
                break;
            }
            call.done += 1;
            report(&self.world, call.done);
            if call.done < call.steps && !self.between_steps(call, inbox) {
                break;
            }
        }
        if self.state != SessionState::Faulted {
            self.publish_if_stale();
            self.run = None;
            let reason = match outcome {
                Advance::Interrupted => format!(
                    "interrupted after {} of {} steps; the step in progress was undone",
                    call.done, call.steps
                ),
                Advance::Stepped | Advance::Refused | Advance::Faulted => "stepped".into(),
            };
            self.set_state(SessionState::Paused, &reason);
        }
        Ok(self.status())
    }

    /// Refuses `steps` more steps where they would pass [`u64::MAX`]:
    /// the counter never wraps.
    fn check_counter(&self, steps: u64) -> Result<(), ServiceError> {
        let step = self.world.clock().step;
        match step.checked_add(steps) {
            Some(_) => Ok(()),
            None => Err(ServiceError::StepCounterFull {
                session_id: self.id.clone(),
                step,
                steps,
            }),
        }
    }

    /// Serves the messages that came during the step just taken of
    /// `call`, as a running session does between two steps:
    /// a snapshot or checkpoint (`Capture`) sees the step reached, grabs
    /// hold from the next step, a restore is refused (the call steps on
    /// the world it would replace); everything else waits for the call,
    /// in order (a Pause has already interrupted it, another stepping
    /// call takes its own steps after it). Returns false when the session
    /// is gone: the call ends.
    fn between_steps(&mut self, call: Call, inbox: &Receiver<Queued>) -> bool {
        self.call = Some(call);
        let open = loop {
            let (number, message) = match inbox.try_recv() {
                Ok(queued) => queued,
                Err(TryRecvError::Empty) => break true,
                Err(TryRecvError::Disconnected) => {
                    self.deferred.push_back((0, Message::Shutdown));
                    break false;
                }
            };
            match message {
                Message::Capture(out) => {
                    // The caller may have gone away.
                    let _ = out.send(self.capture());
                }
                Message::Controls(controls, reply) => {
                    let _ = reply.send(self.set_controls(controls));
                }
                Message::Particles(change, reply) => {
                    let _ = reply.send(self.change_particles(&change));
                }
                Message::Restore(_, reply) => {
                    let _ = reply.send(Err(ServiceError::Stepping {
                        session_id: self.id.clone(),
                        action: "restore a snapshot into",
                        call: call.to_string(),
                    }));
                }
                message @ (Message::Command(..) | Message::Optimize(..) | Message::Shutdown) => {
                    self.deferred.push_back((number, message));
                }
            }
        };
        self.call = None;
        open
    }

    fn start_run(&mut self, target: RunTarget, number: u64) -> Result<SessionStatus, ServiceError> {
        if matches!(self.state, SessionState::Running | SessionState::Faulted) {
            return Err(self.refuse("run", "pause it first"));
        }
        self.check_counter(1)?;
        let now = self.world.clock().time;
        if let Some(until) = target.until
            && until <= now
        {
            return Err(ServiceError::invalid(
                "until_time",
                format!("must be after the session's time, {now} s; got {until} s"),
            ));
        }
        self.run = Some(target);
        self.begin_running(number);
        Ok(self.status())
    }

    fn resume(&mut self, number: u64) -> Result<SessionStatus, ServiceError> {
        match self.state {
            SessionState::Running => Ok(self.status()),
            SessionState::Paused if self.run.is_some() => {
                self.check_counter(1)?;
                self.begin_running(number);
                Ok(self.status())
            }
            _ => Err(self.refuse("resume", "only a paused run can be resumed; start a run")),
        }
    }

    /// Starts or resumes the run as the work of command `number`.
    fn begin_running(&mut self, number: u64) {
        self.work = self.interrupts.begin(number);
        let target = self.run.unwrap_or(RunTarget {
            until: None,
            realtime_factor: None,
        });
        self.pacing = target.realtime_factor.map(|factor| Pacing {
            wall_start: Instant::now(),
            sim_start: self.world.clock().time,
            factor,
        });
        let reason = match target.until {
            Some(t) => format!("running until {t} s"),
            None => "running until paused".into(),
        };
        self.set_state(SessionState::Running, &reason);
    }

    fn reset(&mut self) -> Result<SessionStatus, ServiceError> {
        let controls = self.world.controls().clone();
        self.world = self.world.scene().build(&self.options)?;
        self.hold_controls(controls);
        self.run = None;
        self.pacing = None;
        self.published_step = None;
        self.publish_frame();
        self.set_state(SessionState::Idle, "reset");
        Ok(self.status())
    }

    /// One step of a run; finishes the run at its target time.
    fn advance_run(&mut self) {
        if self.advance() != Advance::Stepped {
            return;
        }
        let until = self.run.and_then(|r| r.until);
        if let Some(until) = until
            && self.world.clock().time >= until - 1e-6 * self.world.scene().time.dt
        {
            self.publish_if_stale();
            self.run = None;
            self.set_state(SessionState::Finished, &format!("reached {until} s"));
        }
    }

    /// Steps the world once, as the work whose flag is `self.work`. On
    /// failure the session faults, keeping the last good frame; an
    /// interrupted step is undone and changes nothing.
    fn advance(&mut self) -> Advance {
        let before = self.world.stages().clone();
        let started = Instant::now();
        match self.world.step_cancellable(&self.work) {
            Ok(info) => {
                let wall = started.elapsed();
                let dt = self.world.scene().time.dt;
                self.out
                    .metrics
                    .step(&info, dt, wall, &before, self.world.stages());
                let factor = dt / wall.as_secs_f64().max(1e-9);
                self.out
                    .realtime_factor
                    .store(factor.to_bits(), std::sync::atomic::Ordering::Relaxed);
                let clock = self.world.clock();
                self.out.status.send_modify(|s| {
                    s.step = clock.step;
                    s.time = clock.time;
                });
                if self.world.is_frame_step() {
                    self.publish_frame();
                }
                Advance::Stepped
            }
            Err(StepError::Cancelled { .. }) => Advance::Interrupted,
            // Only a run gets here (a stepping call is checked first): it
            // ends at the last step there is, nothing faulted.
            Err(e @ StepError::CounterFull { .. }) => {
                self.run = None;
                self.pacing = None;
                self.publish_if_stale();
                self.set_state(SessionState::Paused, &e.to_string());
                Advance::Refused
            }
            Err(e) => {
                self.out.metrics.fault(Some(&e));
                tracing::warn!(session = %self.id, "session faulted: {e}");
                self.run = None;
                self.set_state(SessionState::Faulted, &e.to_string());
                Advance::Faulted
            }
        }
    }

    fn publish_if_stale(&mut self) {
        if self.published_step != Some(self.world.clock().step) {
            self.publish_frame();
        }
    }

    /// Hands the current frame to the publisher, encoded here once for
    /// every reader, dropping it when the publisher is behind: a slow
    /// network never slows the simulation.
    fn publish_frame(&mut self) {
        let frame = Arc::new(EncodedFrame::encode(&self.id, &self.world.frame()));
        self.out.latest.replace(frame.clone());
        if self.out.frames.try_send(frame).is_err() {
            self.dropped_frames += 1;
            self.out.metrics.frame_dropped();
        }
        self.published_step = Some(self.world.clock().step);
    }

    fn status(&self) -> SessionStatus {
        self.out.status.borrow().clone()
    }

    /// Records a new state; watchers and zenoh hear of state changes.
    fn set_state(&mut self, state: SessionState, reason: &str) {
        let changed = self.state != state;
        self.state = state;
        self.reason = reason.to_owned();
        let clock = self.world.clock();
        let run_until = self.run.and_then(|r| r.until);
        self.out.status.send_modify(|s| {
            s.state = state as i32;
            s.reason = reason.to_owned();
            s.step = clock.step;
            s.time = clock.time;
            s.run_until = run_until;
        });
        if changed {
            // No watcher is not an error.
            let _ = self.out.events.send(self.status());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Mailbox, stop};
    use super::*;
    use meshless_engine::Scene;

    /// A worker over a 27-particle fluid, with its status receiver.
    fn worker() -> (Worker, watch::Receiver<SessionStatus>) {
        let scene = Scene::from_toml_str(
            r#"
            [domain]
            min = [0.0, 0.0, 0.0]
            max = [1.0, 1.0, 1.0]
            [time]
            dt = 0.001
            [[systems]]
            kind = "fluid"
            spacing = 0.1
            stiffness = 1e4
            [[systems.blocks]]
            region = { min = [0.0, 0.0, 0.0], max = [0.3, 0.3, 0.3] }
            "#,
        )
        .expect("scene");
        let options = BuildOptions::default();
        let world = scene.build(&options).expect("world");
        let (worker, status, _) = worker_over(world);
        (worker, status)
    }

    /// A worker over `world`, with its status receiver and token.
    fn worker_over(world: World) -> (Worker, watch::Receiver<SessionStatus>, CancellationToken) {
        let options = BuildOptions::default();
        let (status, status_rx) = watch::channel(SessionStatus::default());
        let (events, _) = broadcast::channel(4);
        let (frames, _frames_rx) = crate::session::frame_queue::frame_queue();
        let out = Outputs {
            status,
            events,
            frames,
            latest: LatestFrame::new(EncodedFrame::encode("s", &world.frame())),
            metrics: Arc::new(Metrics::new()),
            realtime_factor: Arc::default(),
        };
        let cancel = CancellationToken::new();
        let worker = Worker::new(
            "s".into(),
            Origin::Built(Box::new(world)),
            options,
            out,
            SharedDesign::default(),
            cancel.clone(),
            Arc::new(Interrupts::default()),
        );
        (worker, status_rx, cancel)
    }

    /// The next message number, as the session's mailbox takes it.
    fn number(worker: &Worker) -> u64 {
        worker
            .interrupts
            .send(false, |_| Ok::<(), ()>(()))
            .expect("numbered")
    }

    /// Applies `command` with a caller that waits for the answer, and
    /// no message coming meanwhile.
    fn command(worker: &mut Worker, command: Command) -> Result<SessionStatus, ServiceError> {
        let (reply, _answer) = tokio::sync::oneshot::channel();
        let number = number(worker);
        let (_sender, inbox) = std::sync::mpsc::channel();
        worker.handle(command, number, &reply, &inbox)
    }

    #[test]
    fn an_abandoned_step_stops_at_the_next_step() {
        let (mut worker, _status) = worker();
        let (reply, answer) = tokio::sync::oneshot::channel();
        drop(answer);
        let number = number(&worker);
        let (_sender, inbox) = std::sync::mpsc::channel();
        let status = worker
            .handle(Command::Step(1_000_000), number, &reply, &inbox)
            .expect("answers");
        assert_eq!(status.step, 0, "no step for a caller that is gone");
        assert_eq!(
            command(&mut worker, Command::Step(3)).expect("steps").step,
            3
        );
    }

    #[test]
    fn a_panic_faults_the_session_and_reset_recovers() {
        let (mut worker, status) = worker();
        command(&mut worker, Command::Step(2)).expect("steps");
        let err = worker
            .guarded::<()>(|_| panic!("index out of bounds"))
            .expect_err("contained");
        assert!(matches!(err, ServiceError::Internal(_)), "{err:?}");
        let seen = status.borrow().clone();
        assert_eq!(seen.state, SessionState::Faulted as i32);
        assert!(
            seen.reason.contains("index out of bounds"),
            "{}",
            seen.reason
        );
        assert_eq!(seen.step, 2, "the last good state is kept");
        let refused = command(&mut worker, Command::Step(1)).expect_err("faulted");
        assert!(
            matches!(refused, ServiceError::Faulted { .. }),
            "{refused:?}"
        );
        let reset = command(&mut worker, Command::Reset).expect("reset");
        assert_eq!(reset.state, SessionState::Idle as i32);
        command(&mut worker, Command::Step(1)).expect("steps again");
    }

    #[test]
    fn pacing_waits_are_capped_and_never_panic() {
        let pacing = |factor| Pacing {
            wall_start: Instant::now(),
            sim_start: 0.0,
            factor,
        };
        // 1e297 s due: far beyond what a Duration holds.
        assert_eq!(pacing(1e-300).wait(1.0), Some(MAX_PACING_WAIT));
        assert_eq!(pacing(f64::MIN_POSITIVE).wait(1.0), Some(MAX_PACING_WAIT));
        // Already late: no wait.
        assert_eq!(pacing(1.0).wait(-1.0), None);
        let short = pacing(1e6).wait(1.0).expect("1 us ahead");
        assert!(short <= Duration::from_micros(1), "{short:?}");
    }

    /// Longest a Pause, a deletion or the next command may take while a
    /// step that runs for a minute is in progress.
    const PROMPT: Duration = Duration::from_secs(5);

    /// A 2D tank of 900 particles whose one step takes about 50 000
    /// sub-steps (about a minute here): only an interruption ends it in
    /// time.
    fn long_step_world() -> World {
        let scene = |dt: f64| {
            Scene::from_toml_str(&format!(
                r#"
                dimension = 2
                [domain]
                min = [0.0, 0.0, 0.0]
                max = [1.0, 1.0, 0.0]
                [time]
                dt = {dt:e}
                max_substeps = 1000000
                cfl = 0.2
                [[systems]]
                kind = "fluid"
                spacing = 0.02
                stiffness = 1000.0
                [[systems.blocks]]
                region = {{ min = [0.0, 0.0, 0.0], max = [0.6, 0.6, 0.0] }}
                "#
            ))
            .expect("scene")
        };
        let options = BuildOptions::default();
        // The sub-step length, from a short probe step.
        let probe_dt = 0.01;
        let mut probe = scene(probe_dt).build(&options).expect("world");
        let substeps = probe.step().expect("a stable probe step").substeps;
        let dt = 50_000.0 * probe_dt / f64::from(substeps);
        scene(dt).build(&options).expect("world")
    }

    /// A worker on its own thread, as a session runs it.
    struct Threaded {
        mailbox: Mailbox,
        status: watch::Receiver<SessionStatus>,
        cancel: CancellationToken,
        design: SharedDesign,
        thread: std::thread::JoinHandle<()>,
    }

    impl Threaded {
        fn start(world: World) -> Self {
            let (worker, status, cancel) = worker_over(world);
            let (commands, messages) = std::sync::mpsc::channel();
            let mailbox = Mailbox {
                commands,
                interrupts: worker.interrupts.clone(),
            };
            let design = worker.design.clone();
            let thread = std::thread::spawn(move || worker.run(messages));
            Self {
                mailbox,
                status,
                cancel,
                design,
                thread,
            }
        }

        /// Polls `step`, a `Step` command sent after the work of message
        /// `before` began, until its own work has begun.
        async fn until_begun<F: std::future::Future>(
            &self,
            before: Option<u64>,
            step: &mut std::pin::Pin<&mut F>,
        ) {
            let started = Instant::now();
            while self.mailbox.interrupts.begun() == before {
                assert!(started.elapsed() < PROMPT, "the step never began");
                if tokio::time::timeout(Duration::from_millis(10), step.as_mut())
                    .await
                    .is_ok()
                {
                    panic!("the step ended before it was interrupted");
                }
            }
        }
    }

    async fn promptly<T>(what: &str, future: impl std::future::Future<Output = T>) -> T {
        tokio::time::timeout(PROMPT, future)
            .await
            .unwrap_or_else(|_| panic!("{what} took over {PROMPT:?} during a long step"))
    }

    #[tokio::test]
    async fn a_pause_interrupts_a_long_step_which_the_session_takes_again() {
        let session = Threaded::start(long_step_world());
        for attempt in 0..2 {
            let before = session.mailbox.interrupts.begun();
            let step = session.mailbox.command(Command::Step(1));
            tokio::pin!(step);
            session.until_begun(before, &mut step).await;
            let started = Instant::now();
            let paused = promptly("Pause", session.mailbox.command(Command::Pause))
                .await
                .expect("the thread runs")
                .expect("paused");
            let stepped = promptly("the interrupted Step", step)
                .await
                .expect("the thread runs")
                .expect("answered");
            println!("attempt {attempt}: paused in {:?}", started.elapsed());
            assert_eq!(paused.state, SessionState::Paused as i32);
            assert_eq!(paused.step, 0, "the last completed step is kept");
            assert_eq!(stepped.step, 0);
            assert!(
                stepped.reason.contains("interrupted after 0 of 1 steps"),
                "{}",
                stepped.reason
            );
            // Not faulted: the next attempt steps again from step 0.
            assert_eq!(session.status.borrow().step, 0);
        }
    }

    #[tokio::test]
    async fn deleting_a_session_interrupts_its_long_step_and_ends_its_thread() {
        let session = Threaded::start(long_step_world());
        let step = session.mailbox.command(Command::Step(1));
        tokio::pin!(step);
        session.until_begun(None, &mut step).await;
        let started = Instant::now();
        // What `Session::shut_down` does before it joins the thread.
        stop(&session.cancel, &session.mailbox, &session.design);
        let thread = session.thread;
        let joined = promptly("the compute thread's exit", async {
            while !thread.is_finished() {
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
            thread.join()
        })
        .await;
        println!("thread gone {:?} after the delete", started.elapsed());
        joined.expect("the thread did not panic");
        // The caller hears of it: the interrupted step, or the session gone.
        let _ = promptly("the Step caller's answer", step).await;
    }

    #[tokio::test]
    async fn an_abandoned_step_is_interrupted_mid_step() {
        let session = Threaded::start(long_step_world());
        {
            let step = session.mailbox.command(Command::Step(1));
            tokio::pin!(step);
            session.until_begun(None, &mut step).await;
            // The caller gives up (a cancelled call, a deadline): dropped.
        }
        // A command that interrupts nothing is answered as soon as the
        // abandoned step has stopped.
        let refused = promptly("the next command", session.mailbox.command(Command::Resume))
            .await
            .expect("the thread runs")
            .expect_err("no run to resume");
        assert!(
            matches!(refused, ServiceError::WrongState { .. }),
            "{refused:?}"
        );
        let status = session.status.borrow().clone();
        assert_eq!(status.step, 0);
        assert_eq!(
            status.state,
            SessionState::Paused as i32,
            "{}",
            status.reason
        );
    }
}
