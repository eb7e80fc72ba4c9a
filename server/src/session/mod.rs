//! A session: one world stepping on its own compute thread, driven by
//! commands from gRPC handlers and publishing frames and status on zenoh.

mod publish;
mod worker;

use crate::convert::scene_to_proto;
use crate::error::ServiceError;
use meshless_engine::{BuildOptions, Frame, Scene, World};
use meshless_proto::{keys, v1};
use std::sync::{Arc, Mutex};
use tokio::sync::{broadcast, mpsc, oneshot, watch};
use tokio_util::sync::CancellationToken;

use worker::Message;
pub use worker::RunTarget;

/// A request to the compute thread; applied between steps.
#[derive(Debug)]
pub enum Command {
    Step(u64),
    Run(RunTarget),
    Pause,
    Resume,
    Reset,
}

type Reply = oneshot::Sender<Result<v1::SessionStatus, ServiceError>>;

/// The most recent frame, shared by the worker (writer) and the latest
/// queryable and `GetLatestFrame` (readers).
pub type LatestFrame = Arc<Mutex<Arc<Frame>>>;

/// Frames queued for zenoh before new ones are dropped.
const FRAME_QUEUE: usize = 4;
/// Status changes buffered per watcher.
const STATUS_EVENTS: usize = 64;

/// The handle gRPC handlers hold. Cheap to share; the world itself lives
/// on the compute thread.
#[derive(Debug)]
pub struct Session {
    pub id: String,
    pub scene: Scene,
    pub particle_count: usize,
    /// Creation order, for listings.
    pub serial: u64,
    commands: std::sync::mpsc::Sender<Message>,
    status: watch::Receiver<v1::SessionStatus>,
    events: broadcast::Sender<v1::SessionStatus>,
    latest: LatestFrame,
    cancel: CancellationToken,
    thread: Mutex<Option<std::thread::JoinHandle<()>>>,
}

impl Session {
    /// Starts the compute thread for an already built world and declares
    /// the session's zenoh publishers and queryable.
    pub fn start(
        id: String,
        serial: u64,
        world: World,
        options: BuildOptions,
        zenoh: &zenoh::Session,
        cancel: CancellationToken,
    ) -> std::io::Result<Arc<Self>> {
        let scene = world.scene().clone();
        let particle_count = world.particle_count();
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
        let latest: LatestFrame = Arc::new(Mutex::new(Arc::new(world.frame())));
        let (frames_tx, frames_rx) = mpsc::channel(FRAME_QUEUE);
        let (commands, commands_rx) = std::sync::mpsc::channel();

        publish::spawn_frames(zenoh.clone(), id.clone(), frames_rx);
        publish::spawn_status(zenoh.clone(), id.clone(), events.subscribe());
        publish::spawn_latest(zenoh.clone(), id.clone(), latest.clone(), cancel.clone());

        let worker = worker::Worker::new(
            id.clone(),
            world,
            options,
            worker::Outputs {
                status: status_tx,
                events: events.clone(),
                frames: frames_tx,
                latest: latest.clone(),
            },
            cancel.clone(),
        );
        let thread = std::thread::Builder::new()
            .name(format!("session-{id}"))
            .spawn(move || worker.run(commands_rx))?;
        Ok(Arc::new(Self {
            id,
            scene,
            particle_count,
            serial,
            commands,
            status,
            events,
            latest,
            cancel,
            thread: Mutex::new(Some(thread)),
        }))
    }

    /// Sends a command to the compute thread and waits for its answer.
    ///
    /// # Errors
    /// What the worker refused, or [`ServiceError::SessionGone`].
    pub async fn command(&self, command: Command) -> Result<v1::SessionStatus, ServiceError> {
        let (reply, answer) = oneshot::channel();
        self.commands
            .send(Message::Command(command, reply))
            .map_err(|_| ServiceError::SessionGone(self.id.clone()))?;
        answer
            .await
            .map_err(|_| ServiceError::SessionGone(self.id.clone()))?
    }

    /// The current status (step and time are kept current while running).
    pub fn status(&self) -> v1::SessionStatus {
        self.status.borrow().clone()
    }

    /// Every state change from now on.
    pub fn subscribe(&self) -> broadcast::Receiver<v1::SessionStatus> {
        self.events.subscribe()
    }

    pub fn latest_frame(&self) -> Arc<Frame> {
        self.latest
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }

    /// The `Session` message for this session.
    pub fn to_proto(&self) -> v1::Session {
        v1::Session {
            id: self.id.clone(),
            name: self.scene.name.clone(),
            status: Some(self.status()),
            zenoh_key_prefix: keys::session_prefix(&self.id),
            particle_count: self.particle_count as u64,
            scene: Some(scene_to_proto(&self.scene)),
        }
    }

    /// Stops the compute thread (it finishes the step in hand) and waits
    /// for it. Blocking: call from a blocking context.
    pub fn shut_down(&self) {
        self.cancel.cancel();
        // Wakes a worker blocked waiting for commands; it may be gone already.
        let _ = self.commands.send(Message::Shutdown);
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
