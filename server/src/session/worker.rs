//! The compute thread of a session. It owns the world, applies commands
//! between steps, and hands frames and status to the publishing tasks
//! without ever waiting on them.

use super::optimize::{self, Channels, OptimizeJob, WarmStart};
use super::{Command, LatestFrame, Reply, SharedDesign, lock};
use crate::error::{ServiceError, state_name};
use meshless_engine::{BuildOptions, Frame, World};
use meshless_proto::v1::{SessionState, SessionStatus};
use std::panic::AssertUnwindSafe;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, RecvTimeoutError, TryRecvError};
use std::time::{Duration, Instant};
use tokio::sync::{broadcast, mpsc, watch};
use tokio_util::sync::CancellationToken;

/// What a run steps towards.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunTarget {
    /// Simulated time to stop at; `None` runs until paused.
    pub until: Option<f64>,
    /// Simulated seconds per wall-clock second; `None` is unpaced.
    pub realtime_factor: Option<f64>,
}

/// A message to the compute thread.
#[derive(Debug)]
pub enum Message {
    Command(Command, Reply),
    Optimize(Box<OptimizeJob>, Channels),
    /// Stop and exit; sent on delete and server shutdown.
    Shutdown,
}

/// Where the worker's results go.
#[derive(Debug)]
pub struct Outputs {
    pub status: watch::Sender<SessionStatus>,
    pub events: broadcast::Sender<SessionStatus>,
    pub frames: mpsc::Sender<Arc<Frame>>,
    pub latest: LatestFrame,
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
}

impl Worker {
    pub fn new(
        id: String,
        world: World,
        options: BuildOptions,
        out: Outputs,
        design: SharedDesign,
        cancel: CancellationToken,
    ) -> Self {
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
        };
        worker.publish_frame();
        worker
    }

    /// The thread's main loop: block for commands while idle, step while
    /// running, exit on shutdown.
    pub fn run(mut self, messages: Receiver<Message>) {
        loop {
            let message = if self.state == SessionState::Running {
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
                messages.recv().ok().or(Some(Message::Shutdown))
            };
            match message {
                Some(Message::Command(command, reply)) => {
                    let result = self.guarded(|w| w.handle(command, &reply)).and_then(|r| r);
                    // The caller may have gone away; the command still applied.
                    let _ = reply.send(result);
                }
                Some(Message::Optimize(job, channels)) => {
                    // On a panic the result channel drops with the closure:
                    // the caller hears that the optimisation ended.
                    let _ = self.guarded(|w| w.optimize(&job, channels));
                }
                Some(Message::Shutdown) => break,
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
        lock(&self.design).running = None;
        self.run = None;
        self.pacing = None;
        let reason = format!("internal error ({message}); reset or delete the session");
        self.set_state(SessionState::Faulted, &reason);
        Err(ServiceError::Internal(reason))
    }

    /// Applies one command; `reply` is where its answer goes, and a closed
    /// one (the caller gave up) ends a long `Step` at the next step.
    fn handle(&mut self, command: Command, reply: &Reply) -> Result<SessionStatus, ServiceError> {
        match command {
            Command::Step(steps) => self.step(steps, reply),
            Command::Run(target) => self.start_run(target),
            Command::Pause => {
                if self.state == SessionState::Running {
                    self.publish_if_stale();
                    self.set_state(SessionState::Paused, "paused");
                }
                Ok(self.status())
            }
            Command::Resume => self.resume(),
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
                if self.out.frames.blocking_send(Arc::new(frame)).is_err() {
                    self.dropped_frames += 1;
                }
            }
            let result = Arc::new(solved.result);
            lock(&self.design).last = Some(result.clone());
            result
        });
        lock(&self.design).running = None;
        if let Err(e) = &outcome {
            tracing::info!(session = %self.id, "optimisation ended: {e}");
        }
        // The caller may have gone away.
        let _ = result.send(outcome);
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

    /// Takes up to `steps` steps; stops early when the session is shut
    /// down or the caller is gone (an abandoned `Step(1_000_000)` would
    /// otherwise hold the session for as long as it takes).
    fn step(&mut self, steps: u64, reply: &Reply) -> Result<SessionStatus, ServiceError> {
        if matches!(self.state, SessionState::Running | SessionState::Faulted) {
            return Err(self.refuse("step", "pause it first"));
        }
        for _ in 0..steps {
            if self.cancel.is_cancelled() || reply.is_closed() || !self.advance() {
                break;
            }
        }
        if self.state != SessionState::Faulted {
            self.publish_if_stale();
            self.run = None;
            self.set_state(SessionState::Paused, "stepped");
        }
        Ok(self.status())
    }

    fn start_run(&mut self, target: RunTarget) -> Result<SessionStatus, ServiceError> {
        if matches!(self.state, SessionState::Running | SessionState::Faulted) {
            return Err(self.refuse("run", "pause it first"));
        }
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
        self.begin_running();
        Ok(self.status())
    }

    fn resume(&mut self) -> Result<SessionStatus, ServiceError> {
        match self.state {
            SessionState::Running => Ok(self.status()),
            SessionState::Paused if self.run.is_some() => {
                self.begin_running();
                Ok(self.status())
            }
            _ => Err(self.refuse("resume", "only a paused run can be resumed; start a run")),
        }
    }

    fn begin_running(&mut self) {
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
        self.world = self.world.scene().build(&self.options)?;
        self.run = None;
        self.pacing = None;
        self.published_step = None;
        self.publish_frame();
        self.set_state(SessionState::Idle, "reset");
        Ok(self.status())
    }

    /// One step of a run; finishes the run at its target time.
    fn advance_run(&mut self) {
        if !self.advance() {
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

    /// Steps the world once. On failure the session faults, keeping the
    /// last good frame. Returns whether the step succeeded.
    fn advance(&mut self) -> bool {
        match self.world.step() {
            Ok(_) => {
                let clock = self.world.clock();
                self.out.status.send_modify(|s| {
                    s.step = clock.step;
                    s.time = clock.time;
                });
                if self.world.is_frame_step() {
                    self.publish_frame();
                }
                true
            }
            Err(e) => {
                tracing::warn!(session = %self.id, "session faulted: {e}");
                self.run = None;
                self.set_state(SessionState::Faulted, &e.to_string());
                false
            }
        }
    }

    fn publish_if_stale(&mut self) {
        if self.published_step != Some(self.world.clock().step) {
            self.publish_frame();
        }
    }

    /// Hands the current frame to the publisher, dropping it when the
    /// publisher is behind: a slow network never slows the simulation.
    fn publish_frame(&mut self) {
        let frame = Arc::new(self.world.frame());
        *self
            .out
            .latest
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = frame.clone();
        if self.out.frames.try_send(frame).is_err() {
            self.dropped_frames += 1;
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
        let (status, status_rx) = watch::channel(SessionStatus::default());
        let (events, _) = broadcast::channel(4);
        let (frames, _frames_rx) = mpsc::channel(4);
        let out = Outputs {
            status,
            events,
            frames,
            latest: Arc::new(std::sync::Mutex::new(Arc::new(world.frame()))),
        };
        let worker = Worker::new(
            "s".into(),
            world,
            options,
            out,
            SharedDesign::default(),
            CancellationToken::new(),
        );
        (worker, status_rx)
    }

    /// Applies `command` with a caller that waits for the answer.
    fn command(worker: &mut Worker, command: Command) -> Result<SessionStatus, ServiceError> {
        let (reply, _answer) = tokio::sync::oneshot::channel();
        worker.handle(command, &reply)
    }

    #[test]
    fn an_abandoned_step_stops_at_the_next_step() {
        let (mut worker, _status) = worker();
        let (reply, answer) = tokio::sync::oneshot::channel();
        drop(answer);
        let status = worker
            .handle(Command::Step(1_000_000), &reply)
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
}
