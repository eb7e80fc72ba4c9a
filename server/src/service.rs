//! The `meshless.v1.Simulation` gRPC service: a thin adapter that
//! validates a request, converts it, calls the registry or a session, and
//! converts the answer back.

use crate::auth::{Caller, caller};
use crate::checkpoint::Checkpoints;
use crate::error::ServiceError;
use crate::metrics::Metrics;
use crate::registry::Registry;
use crate::session::{
    Access, Command, Decoded, OptimizeJob, ParticleChange, Problem, RunTarget, Session, Simulate,
    check_observers, check_simulate, encode_snapshot, grpc_deadline,
};
use meshless_engine::Scene;
use meshless_proto::v1::{self, simulation_server::Simulation};
use meshless_wire::design::{
    SessionConstraint, SessionEdit, design_params_from_proto, edit_from_proto,
    motion_params_from_proto,
};
use meshless_wire::scene::scene_from_proto;
use std::sync::Arc;
use tokio::sync::{broadcast, mpsc};
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::sync::CancellationToken;
use tonic::{Request, Response, Status};

/// Most steps one `Step` call may ask for.
const MAX_STEPS_PER_CALL: u64 = 1_000_000;

/// Playback frames per second of design time when a motion names none.
const DEFAULT_PLAYBACK_RATE: f64 = 30.0;
/// Optimisation events queued per stream.
const OPTIMIZE_EVENTS: usize = 16;
/// Progress messages queued per `SimulateSteps` stream.
const SIMULATE_EVENTS: usize = 4;
/// Longest a `NextFrame` poll may ask to wait, ms: long enough that an
/// idle session costs a viewer one request a minute, short enough that a
/// stalled poll is noticed.
const MAX_FRAME_WAIT_MS: u32 = 60_000;

#[derive(Debug)]
pub struct SimulationService {
    registry: Arc<Registry>,
    info: v1::ServerInfo,
    /// Where deleted sessions' checkpoints are removed, when the server
    /// keeps any.
    checkpoints: Option<Arc<Checkpoints>>,
    metrics: Arc<Metrics>,
    shutdown: CancellationToken,
}

impl SimulationService {
    pub fn new(
        registry: Arc<Registry>,
        info: v1::ServerInfo,
        checkpoints: Option<Arc<Checkpoints>>,
        metrics: Arc<Metrics>,
        shutdown: CancellationToken,
    ) -> Self {
        Self {
            registry,
            info,
            checkpoints,
            metrics,
            shutdown,
        }
    }

    /// The largest snapshot blob, bytes.
    fn snapshot_limit(&self) -> usize {
        usize::try_from(self.info.max_snapshot_bytes).unwrap_or(usize::MAX)
    }

    fn session_id(id: &str) -> Result<&str, ServiceError> {
        if id.is_empty() {
            Err(ServiceError::invalid("session_id", "is required"))
        } else {
            Ok(id)
        }
    }

    /// The session `id` names, if `caller` may see it.
    fn read(&self, id: &str, caller: &Caller) -> Result<Arc<Session>, ServiceError> {
        let session = self.registry.get(Self::session_id(id)?)?;
        session.access.check_read(&session.id, caller)?;
        Ok(session)
    }

    /// The session `id` names, if `caller` may `action` it (and now
    /// drives it).
    fn drive(
        &self,
        id: &str,
        caller: &Caller,
        action: &'static str,
    ) -> Result<Arc<Session>, ServiceError> {
        let session = self.registry.get(Self::session_id(id)?)?;
        session.access.check_drive(&session.id, caller, action)?;
        Ok(session)
    }

    async fn command(
        &self,
        id: &str,
        caller: &Caller,
        action: &'static str,
        command: Command,
    ) -> Result<v1::Session, ServiceError> {
        let session = self.drive(id, caller, action)?;
        session.command(command).await?;
        Ok(session.to_proto())
    }
}

type Reply<T> = Result<Response<T>, Status>;

/// When the caller stops waiting, from its `grpc-timeout` header.
fn deadline_of<T>(request: &Request<T>) -> Option<std::time::Instant> {
    request
        .metadata()
        .get("grpc-timeout")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| grpc_deadline(v, std::time::Instant::now()))
}

/// When a unary handler answers DEADLINE_EXCEEDED itself: a little before
/// `deadline`, since tonic's timer on the same header started first and
/// answers CANCELLED when it fires.
fn answer_by(deadline: Option<std::time::Instant>) -> Option<std::time::Instant> {
    const MARGIN: std::time::Duration = std::time::Duration::from_millis(20);
    let deadline = deadline?;
    let left = deadline.saturating_duration_since(std::time::Instant::now());
    Some(deadline - MARGIN.min(left / 2))
}

/// The engine job of an `Optimize` request.
fn optimize_job(
    system: u32,
    design: Option<v1::DesignSettings>,
    problem: Option<v1::optimize_request::Problem>,
    playback: bool,
) -> Result<OptimizeJob, ServiceError> {
    let problem = match problem {
        Some(v1::optimize_request::Problem::Shape(v1::ShapeProblem {})) => Problem::Shape,
        Some(v1::optimize_request::Problem::Motion(v1::MotionProblem {
            settings,
            playback_rate,
        })) => {
            let playback_rate = playback_rate.unwrap_or(DEFAULT_PLAYBACK_RATE);
            if !(playback_rate.is_finite() && playback_rate > 0.0) {
                return Err(ServiceError::invalid(
                    "motion.playback_rate",
                    format!(
                        "must be a finite number of frames per second > 0, got {playback_rate}"
                    ),
                ));
            }
            Problem::Motion {
                params: motion_params_from_proto(settings),
                playback_rate,
            }
        }
        None => return Err(ServiceError::invalid("problem", "set shape or motion")),
    };
    Ok(OptimizeJob {
        system: system as usize,
        params: design_params_from_proto(design)?,
        problem,
        playback,
    })
}

#[tonic::async_trait]
impl Simulation for SimulationService {
    async fn get_server_info(&self, _: Request<v1::GetServerInfoRequest>) -> Reply<v1::ServerInfo> {
        let routers = self.registry.zenoh().info().routers_zid().await.count();
        Ok(Response::new(v1::ServerInfo {
            zenoh_routers: u32::try_from(routers).unwrap_or(u32::MAX),
            ..self.info.clone()
        }))
    }

    async fn create_session(
        &self,
        request: Request<v1::CreateSessionRequest>,
    ) -> Reply<v1::Session> {
        let caller = caller(&request)?;
        let v1::CreateSessionRequest { source, observers } = request.into_inner();
        check_observers(&observers)?;
        let scene = match source {
            Some(v1::create_session_request::Source::Scene(spec)) => {
                scene_from_proto(spec).map_err(ServiceError::from)?
            }
            Some(v1::create_session_request::Source::SceneToml(text)) => {
                Scene::from_toml_str(&text).map_err(ServiceError::from)?
            }
            None => return Err(ServiceError::invalid("source", "set scene or scene_toml").into()),
        };
        let session = self
            .registry
            .create(scene, Access::new(&caller, observers))
            .await?;
        tracing::info!(
            session = %session.id,
            owner = %caller.principal,
            particles = session.particle_count,
            "session created"
        );
        Ok(Response::new(session.to_proto()))
    }

    async fn get_session(&self, request: Request<v1::SessionRef>) -> Reply<v1::Session> {
        let caller = caller(&request)?;
        let id = request.into_inner().session_id;
        Ok(Response::new(self.read(&id, &caller)?.to_proto()))
    }

    async fn list_sessions(
        &self,
        request: Request<v1::ListSessionsRequest>,
    ) -> Reply<v1::ListSessionsResponse> {
        let caller = caller(&request)?;
        let sessions = self
            .registry
            .list()
            .iter()
            .filter(|s| s.access.may_read(&caller))
            .map(|s| s.summary())
            .collect();
        Ok(Response::new(v1::ListSessionsResponse { sessions }))
    }

    async fn delete_session(
        &self,
        request: Request<v1::SessionRef>,
    ) -> Reply<v1::DeleteSessionResponse> {
        let caller = caller(&request)?;
        let id = request.into_inner().session_id;
        self.drive(&id, &caller, "delete")?;
        self.registry.delete(&id).await?;
        if let Some(checkpoints) = &self.checkpoints {
            checkpoints.forget(&id);
        }
        tracing::info!(session = %id, "session deleted");
        Ok(Response::new(v1::DeleteSessionResponse {}))
    }

    async fn step(&self, request: Request<v1::StepRequest>) -> Reply<v1::Session> {
        let caller = caller(&request)?;
        let deadline = deadline_of(&request);
        let v1::StepRequest { session_id, steps } = request.into_inner();
        if steps == 0 || steps > MAX_STEPS_PER_CALL {
            return Err(ServiceError::invalid(
                "steps",
                format!("must be in [1, {MAX_STEPS_PER_CALL}], got {steps}"),
            )
            .into());
        }
        // Answered before tonic's own timer, which would say CANCELLED:
        // dropping the command stops it at its step in progress.
        let step = self.command(&session_id, &caller, "step", Command::Step(steps));
        match answer_by(deadline) {
            Some(at) => match tokio::time::timeout_at(at.into(), step).await {
                Ok(session) => Ok(Response::new(session?)),
                Err(_) => Err(Status::deadline_exceeded(
                    "the call's deadline passed while stepping; the session stopped at its last \
                     completed step (GetSession has it): give a longer deadline or fewer steps, \
                     or use SimulateSteps for progress",
                )),
            },
            None => Ok(Response::new(step.await?)),
        }
    }

    async fn run(&self, request: Request<v1::RunRequest>) -> Reply<v1::Session> {
        let caller = caller(&request)?;
        let v1::RunRequest {
            session_id,
            until,
            realtime_factor,
        } = request.into_inner();
        // No cap on how far ahead: however long a run is, Pause, Delete
        // and shutdown stop it within a sub-step (`session/interrupt.rs`).
        let until = match until {
            Some(v1::run_request::Until::UntilTime(t)) => Some(RunTarget::check_until(t)?),
            Some(v1::run_request::Until::Forever(true)) => None,
            Some(v1::run_request::Until::Forever(false)) | None => {
                return Err(ServiceError::invalid(
                    "until",
                    "set until_time, or forever = true to run until paused",
                )
                .into());
            }
        };
        let realtime_factor = RunTarget::check_realtime_factor(realtime_factor)?;
        let target = RunTarget {
            until,
            realtime_factor,
        };
        Ok(Response::new(
            self.command(&session_id, &caller, "run", Command::Run(target))
                .await?,
        ))
    }

    async fn pause(&self, request: Request<v1::SessionRef>) -> Reply<v1::Session> {
        let caller = caller(&request)?;
        let id = request.into_inner().session_id;
        Ok(Response::new(
            self.command(&id, &caller, "pause", Command::Pause).await?,
        ))
    }

    async fn resume(&self, request: Request<v1::SessionRef>) -> Reply<v1::Session> {
        let caller = caller(&request)?;
        let id = request.into_inner().session_id;
        Ok(Response::new(
            self.command(&id, &caller, "resume", Command::Resume)
                .await?,
        ))
    }

    async fn reset(&self, request: Request<v1::SessionRef>) -> Reply<v1::Session> {
        let caller = caller(&request)?;
        let id = request.into_inner().session_id;
        Ok(Response::new(
            self.command(&id, &caller, "reset", Command::Reset).await?,
        ))
    }

    type WatchStatusStream = ReceiverStream<Result<v1::SessionStatus, Status>>;

    async fn watch_status(
        &self,
        request: Request<v1::SessionRef>,
    ) -> Reply<Self::WatchStatusStream> {
        let caller = caller(&request)?;
        let id = request.into_inner().session_id;
        let session = self.read(&id, &caller)?;
        let mut events = session.subscribe();
        let (tx, rx) = mpsc::channel(16);
        let shutdown = self.shutdown.clone();
        tokio::spawn(async move {
            let closed = v1::SessionState::Closed as i32;
            let mut next = Ok(session.status());
            loop {
                let status = match next {
                    Ok(status) => status,
                    Err(broadcast::error::RecvError::Lagged(_)) => session.status(),
                    Err(broadcast::error::RecvError::Closed) => break,
                };
                let last = status.state == closed;
                if tx.send(Ok(status)).await.is_err() || last {
                    break;
                }
                next = tokio::select! {
                    () = tx.closed() => break,
                    () = shutdown.cancelled() => break,
                    event = events.recv() => event,
                };
            }
        });
        Ok(Response::new(ReceiverStream::new(rx)))
    }

    async fn get_latest_frame(&self, request: Request<v1::SessionRef>) -> Reply<v1::Frame> {
        let caller = caller(&request)?;
        let id = request.into_inner().session_id;
        let session = self.read(&id, &caller)?;
        let frame = session.latest_frame();
        // Encoded once on the compute thread; decoding copies tens of
        // megabytes at a million particles, kept off the I/O threads.
        let message = tokio::task::spawn_blocking(move || frame.to_proto())
            .await
            .map_err(|e| ServiceError::Internal(format!("frame decoding failed: {e}")))?
            .map_err(|e| {
                ServiceError::Internal(format!("the latest frame does not decode: {e}"))
            })?;
        Ok(Response::new(message))
    }

    async fn next_frame(
        &self,
        request: Request<v1::NextFrameRequest>,
    ) -> Reply<v1::NextFrameResponse> {
        let caller = caller(&request)?;
        let answer_by = answer_by(deadline_of(&request));
        let request = request.into_inner();
        if request.wait_ms > MAX_FRAME_WAIT_MS {
            return Err(ServiceError::invalid(
                "wait_ms",
                format!(
                    "is {} ms; ask for at most {MAX_FRAME_WAIT_MS} ms and poll again",
                    request.wait_ms
                ),
            )
            .into());
        }
        let session = self.read(&request.session_id, &caller)?;
        let mut wait = std::time::Duration::from_millis(u64::from(request.wait_ms));
        if let Some(by) = answer_by {
            wait = wait.min(by.saturating_duration_since(std::time::Instant::now()));
        }
        // A shutdown ends the wait: the server does not stop for polls.
        let latest = tokio::select! {
            latest = session.next_frame(request.after, wait) => latest,
            () = self.shutdown.cancelled() => None,
        };
        Ok(Response::new(match latest {
            Some(latest) => v1::NextFrameResponse {
                number: latest.number,
                frame: latest.frame.to_bytes(),
            },
            None => v1::NextFrameResponse {
                number: request.after,
                frame: Default::default(),
            },
        }))
    }

    async fn edit_constraints(
        &self,
        request: Request<v1::EditConstraintsRequest>,
    ) -> Reply<v1::ConstraintList> {
        let caller = caller(&request)?;
        let v1::EditConstraintsRequest { session_id, edits } = request.into_inner();
        let session = self.drive(&session_id, &caller, "edit the constraints of")?;
        let mut edits = edits
            .into_iter()
            .enumerate()
            .map(|(k, e)| edit_from_proto(e, &format!("edits[{k}]")))
            .collect::<Result<Vec<_>, _>>()
            .map_err(ServiceError::from)?;
        // An obstacle's mesh file is read under the same policy as a
        // scene's, before anything changes.
        let options = self.registry.options();
        for edit in &mut edits {
            if let SessionEdit::Add(SessionConstraint::Design(constraint))
            | SessionEdit::Replace(SessionConstraint::Design(constraint)) = edit
            {
                constraint
                    .load_mesh(&options.mesh_files, options.max_mesh_bytes)
                    .map_err(|e| ServiceError::Design(e.into()))?;
            }
        }
        let constraints = session.edit_constraints(&edits).await?;
        Ok(Response::new(v1::ConstraintList { constraints }))
    }

    async fn list_constraints(
        &self,
        request: Request<v1::SessionRef>,
    ) -> Reply<v1::ConstraintList> {
        let caller = caller(&request)?;
        let id = request.into_inner().session_id;
        let session = self.read(&id, &caller)?;
        Ok(Response::new(v1::ConstraintList {
            constraints: session.constraints(),
        }))
    }

    type OptimizeStream = ReceiverStream<Result<v1::OptimizeEvent, Status>>;

    async fn optimize(&self, request: Request<v1::OptimizeRequest>) -> Reply<Self::OptimizeStream> {
        let caller = caller(&request)?;
        let v1::OptimizeRequest {
            session_id,
            system,
            design,
            problem,
            playback,
        } = request.into_inner();
        let session = self.drive(&session_id, &caller, "optimise")?;
        let job = optimize_job(system, design, problem, playback)?;
        let mut run = session.optimize(job)?;
        let (tx, rx) = mpsc::channel(OPTIMIZE_EVENTS);
        // Forwards progress, then the outcome. Returning drops `run`, which
        // cancels the solve when the client has gone away.
        tokio::spawn(async move {
            let event = |e| Ok(v1::OptimizeEvent { event: Some(e) });
            loop {
                let progress = tokio::select! {
                    () = tx.closed() => return,
                    progress = run.progress.recv() => progress,
                };
                let Some(progress) = progress else { break };
                if tx
                    .send(event(v1::optimize_event::Event::Progress(progress)))
                    .await
                    .is_err()
                {
                    return;
                }
            }
            let outcome = tokio::select! {
                () = tx.closed() => return,
                outcome = &mut run.result => outcome,
            };
            let message = match outcome {
                Ok(Ok(result)) => event(v1::optimize_event::Event::Result((*result).clone())),
                Ok(Err(e)) => Err(Status::from(e)),
                Err(_) => Err(ServiceError::SessionGone(session.id.clone()).into()),
            };
            // The client may have gone away.
            let _ = tx.send(message).await;
        });
        Ok(Response::new(ReceiverStream::new(rx)))
    }

    async fn cancel_optimize(
        &self,
        request: Request<v1::SessionRef>,
    ) -> Reply<v1::CancelOptimizeResponse> {
        let caller = caller(&request)?;
        let id = request.into_inner().session_id;
        let session = self.drive(&id, &caller, "cancel the optimisation of")?;
        Ok(Response::new(v1::CancelOptimizeResponse {
            cancelled: session.cancel_optimize(),
        }))
    }

    async fn get_design(&self, request: Request<v1::SessionRef>) -> Reply<v1::DesignResult> {
        let caller = caller(&request)?;
        let id = request.into_inner().session_id;
        let session = self.read(&id, &caller)?;
        Ok(Response::new((*session.last_design()?).clone()))
    }

    type SimulateStepsStream = ReceiverStream<Result<v1::SimulateProgress, Status>>;

    async fn simulate_steps(
        &self,
        request: Request<v1::SimulateStepsRequest>,
    ) -> Reply<Self::SimulateStepsStream> {
        let caller = caller(&request)?;
        // tonic ends a call at its deadline only until the answer's
        // headers go out; a stream keeps to it here.
        let deadline = deadline_of(&request);
        let v1::SimulateStepsRequest {
            session_id,
            steps,
            progress_interval,
        } = request.into_inner();
        let interval = check_simulate(steps, progress_interval)?;
        let session = self.drive(&session_id, &caller, "step")?;
        let (tx, rx) = mpsc::channel(SIMULATE_EVENTS);
        let job = Simulate {
            steps,
            interval,
            deadline,
        };
        tokio::spawn(session.simulate(job, tx));
        Ok(Response::new(ReceiverStream::new(rx)))
    }

    async fn snapshot(&self, request: Request<v1::SessionRef>) -> Reply<v1::SessionSnapshot> {
        let caller = caller(&request)?;
        let id = request.into_inner().session_id;
        let session = self.registry.get(Self::session_id(&id)?)?;
        session
            .access
            .check_owner(&session.id, &caller, "snapshot")?;
        let payload = session.snapshot().await?;
        let (step, time) = payload
            .world
            .as_ref()
            .map_or((0, 0.0), |w| (w.step, w.time));
        let limit = self.snapshot_limit();
        let data = tokio::task::spawn_blocking(move || encode_snapshot(&payload, limit))
            .await
            .map_err(|e| ServiceError::Internal(format!("snapshot encoding failed: {e}")))??;
        tracing::info!(session = %session.id, step, bytes = data.len(), "snapshot taken");
        self.metrics.snapshot();
        Ok(Response::new(v1::SessionSnapshot {
            session_id: session.id.clone(),
            step,
            time,
            data,
        }))
    }

    async fn restore(&self, request: Request<v1::RestoreRequest>) -> Reply<v1::Session> {
        let caller = caller(&request)?;
        let v1::RestoreRequest {
            data,
            session_id,
            observers,
        } = request.into_inner();
        // Into an existing session: its access is checked before the blob
        // is even read.
        let target = if session_id.is_empty() {
            None
        } else {
            Some(self.drive(&session_id, &caller, "restore a snapshot into")?)
        };
        let limit = self.snapshot_limit();
        let decoded = tokio::task::spawn_blocking(move || Decoded::from_blob(&data, limit))
            .await
            .map_err(|e| ServiceError::Internal(format!("snapshot decoding failed: {e}")))??;
        let session = match target {
            Some(session) => {
                self.registry.restore_into(&session, decoded).await?;
                session
            }
            None => {
                let observers = match observers {
                    Some(list) => list.principals,
                    None => decoded.record.observers.clone(),
                };
                check_observers(&observers)?;
                self.registry
                    .restore(decoded, Access::new(&caller, observers), None)
                    .await?
            }
        };
        let status = session.status();
        tracing::info!(
            session = %session.id,
            step = status.step,
            owner = %caller.principal,
            "snapshot restored"
        );
        self.metrics.restore();
        Ok(Response::new(session.to_proto()))
    }

    async fn change_particles(
        &self,
        request: Request<v1::ChangeParticlesRequest>,
    ) -> Reply<v1::ChangeParticlesResponse> {
        let caller = caller(&request)?;
        let v1::ChangeParticlesRequest {
            session_id,
            system,
            remove,
            insert_positions,
            insert_velocities,
        } = request.into_inner();
        if remove.is_empty() && insert_positions.is_empty() && insert_velocities.is_empty() {
            return Err(ServiceError::invalid(
                "remove",
                "the request changes nothing: name ids to remove or positions to insert",
            )
            .into());
        }
        let session = self.drive(&session_id, &caller, "change the particles of")?;
        let xyz = |v: v1::Vec3| [v.x, v.y, v.z];
        let change = ParticleChange {
            system: system as usize,
            remove: remove.into_iter().map(|id| id as usize).collect(),
            positions: insert_positions.into_iter().map(xyz).collect(),
            velocities: insert_velocities.into_iter().map(xyz).collect(),
        };
        let inserted = session.change_particles(change).await?;
        Ok(Response::new(v1::ChangeParticlesResponse {
            session: Some(session.to_proto()),
            first_inserted_id: inserted.start,
            inserted: inserted.end - inserted.start,
        }))
    }
}
