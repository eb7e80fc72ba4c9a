//! Snapshots of a session: what the compute thread captures between two
//! steps, the payload made of it, and the way back: a blob checked and
//! decoded, its world rebuilt from its scene and moved to its state, its
//! constraints and design checked against that world. Every check runs
//! before a session is touched, so a refused blob changes nothing.

use super::optimize::WarmStart;
use super::run_target::RunTarget;
use super::{DesignState, Session, lock};
use crate::error::ServiceError;
use meshless_engine::design::{self, ConstraintSet, Edit};
use meshless_engine::scene::Checked;
use meshless_engine::world::Controls;
use meshless_engine::{BuildOptions, Scene, World, WorldState};
use meshless_proto::snapshot as blob;
use meshless_proto::v1::{self, SessionState};
use meshless_wire::design::{SessionConstraint, constraint_from_proto};
use meshless_wire::scene::{scene_from_proto, scene_to_proto};
use meshless_wire::snapshot::{world_state_from_proto, world_state_to_proto};
use std::sync::Arc;

/// What the compute thread hands over for a snapshot.
#[derive(Debug)]
pub struct Captured {
    pub world: WorldState,
    pub state: SessionState,
    pub reason: String,
    pub run: Option<RunTarget>,
    pub warm: Option<WarmStart>,
}

/// Where a session restored from a snapshot starts: its world already
/// moved to the snapshot's state, and the session's own state around it.
#[derive(Debug)]
pub struct Resumed {
    pub world: World,
    pub session: ResumedSession,
}

/// The session state a snapshot restores around its world.
#[derive(Debug)]
pub struct ResumedSession {
    pub state: SessionState,
    pub reason: String,
    pub run: Option<RunTarget>,
    pub warm: Option<WarmStart>,
    pub constraints: ConstraintSet,
    /// The controls, already set on the world.
    pub controls: Controls,
    pub last: Option<v1::DesignResult>,
}

impl Session {
    /// The session's state as a payload: captured by the compute thread
    /// between two steps (a running session runs on), then assembled
    /// here with the constraints and the last design.
    ///
    /// # Errors
    /// [`ServiceError::SessionGone`].
    pub async fn snapshot(&self) -> Result<v1::SnapshotPayload, ServiceError> {
        let captured = self.capture().await?;
        let (constraints, last) = {
            let design = lock(&self.design);
            (
                super::constraints::list(&design.constraints, &design.controls),
                design.last.as_deref().cloned(),
            )
        };
        let scene = self.scene.clone();
        let record = v1::SessionRecord {
            id: self.id.clone(),
            owner: self.access.owner().to_owned(),
            observers: self.access.observers().to_vec(),
            state: captured.state as i32,
            reason: captured.reason,
            run: captured.run.map(|r| v1::RunRecord {
                until_time: r.until,
                realtime_factor: r.realtime_factor,
            }),
        };
        // Flattening a large world is CPU work: off the I/O threads.
        tokio::task::spawn_blocking(move || v1::SnapshotPayload {
            scene: Some(scene_to_proto(&scene)),
            world: Some(world_state_to_proto(&captured.world)),
            session: Some(record),
            constraints,
            last_design: last,
            warm_start: captured.warm.map(|w| w.to_proto()),
        })
        .await
        .map_err(|e| ServiceError::Internal(format!("snapshot task failed: {e}")))
    }

    /// Refuses a snapshot of another scene than this session's, before
    /// anything is built for it.
    ///
    /// # Errors
    /// [`ServiceError::InvalidArgument`] naming both scenes.
    pub fn check_scene(&self, snapshot: &Decoded) -> Result<(), ServiceError> {
        if scene_to_proto(&snapshot.scene) != scene_to_proto(&self.scene) {
            return Err(ServiceError::invalid(
                "data",
                format!(
                    "the snapshot holds scene {:?}, not this session's ({:?}); restore it into \
                     a new session (leave session_id empty)",
                    crate::error::quote(&snapshot.scene.name),
                    crate::error::quote(&self.scene.name)
                ),
            ));
        }
        Ok(())
    }

    /// Moves this session to `snapshot`, which must hold this session's
    /// scene, checked as `checked` (the registry reserved its footprint):
    /// a world is built and restored off the session, then swapped in by
    /// the compute thread between two steps.
    ///
    /// # Errors
    /// [`ServiceError::InvalidArgument`] for a snapshot of another scene
    /// or one that does not fit it; [`ServiceError::WrongState`] while
    /// running. Nothing changes on error.
    pub async fn restore(
        &self,
        snapshot: Decoded,
        checked: Checked,
        options: &BuildOptions,
    ) -> Result<v1::SessionStatus, ServiceError> {
        self.check_scene(&snapshot)?;
        let options = options.clone();
        let resumed =
            tokio::task::spawn_blocking(move || snapshot.resume(checked.build(), &options))
                .await
                .map_err(|e| ServiceError::Internal(format!("restore task failed: {e}")))??;
        self.swap(resumed).await
    }
}

/// A blob checked and decoded: its scene, the state of its world, and the
/// session around it, each converted but not yet checked against a
/// world.
#[derive(Debug)]
pub struct Decoded {
    pub scene: Scene,
    pub world: WorldState,
    pub record: v1::SessionRecord,
    pub constraints: Vec<v1::Constraint>,
    pub last: Option<v1::DesignResult>,
    pub warm: Option<v1::DesignWarmStart>,
}

impl Decoded {
    /// Checks and decodes `data`, at most `limit` bytes. Blocking (a blob
    /// can be large): call off the I/O threads.
    ///
    /// # Errors
    /// [`ServiceError::Snapshot`] for a blob that is not one of this
    /// build's; [`ServiceError::InvalidArgument`] for a payload that does
    /// not convert.
    pub fn from_blob(data: &[u8], limit: usize) -> Result<Self, ServiceError> {
        let payload = blob::decode(data, limit)?;
        let v1::SnapshotPayload {
            scene,
            world,
            session,
            constraints,
            last_design,
            warm_start,
        } = payload;
        let missing =
            |what: &str| ServiceError::invalid("data", format!("the snapshot has no {what}"));
        let scene = scene_from_proto(scene.ok_or_else(|| missing("scene"))?)?;
        let world = world_state_from_proto(world.ok_or_else(|| missing("world"))?)?;
        let record = session.ok_or_else(|| missing("session record"))?;
        Ok(Self {
            scene,
            world,
            record,
            constraints,
            last: last_design,
            warm: warm_start,
        })
    }

    /// The session state this snapshot restores into `world`, a world
    /// freshly built from its scene. Blocking.
    ///
    /// # Errors
    /// [`ServiceError::InvalidArgument`] naming what does not fit.
    pub fn resume(self, world: World, options: &BuildOptions) -> Result<Resumed, ServiceError> {
        let mut world = world.restored(&self.world).map_err(|e| unfit(&e))?;
        let context = design::context(&world);
        let mut edits = Vec::with_capacity(self.constraints.len());
        let mut controls = Controls::new();
        for (k, c) in self.constraints.into_iter().enumerate() {
            let field = format!("constraints[{k}]");
            match constraint_from_proto(c, &field)? {
                SessionConstraint::Design(mut constraint) => {
                    constraint
                        .load_mesh(&options.mesh_files, options.max_mesh_bytes)
                        .map_err(|e| unfit(&e))?;
                    edits.push(Edit::Add(constraint));
                }
                SessionConstraint::Control(name, control) => {
                    if controls.insert(name.clone(), control).is_some() {
                        let name = crate::error::quote(&name);
                        return Err(unfit(&format!("{field}: a second constraint {name}")));
                    }
                }
            }
        }
        let mut constraints = ConstraintSet::default();
        constraints.apply(&edits, &context).map_err(|e| unfit(&e))?;
        if let Some(c) = constraints.iter().find(|c| controls.get(&c.name).is_some()) {
            let name = crate::error::quote(&c.name);
            return Err(unfit(&format!("two constraints are called {name}")));
        }
        world
            .set_controls(controls.clone())
            .map_err(|e| unfit(&e))?;
        let warm = self
            .warm
            .map(|w| WarmStart::from_proto(w, &world))
            .transpose()
            .map_err(|e| unfit(&e))?;
        let state = match SessionState::try_from(self.record.state) {
            Ok(SessionState::Running) => SessionState::Paused,
            Ok(
                state @ (SessionState::Idle
                | SessionState::Paused
                | SessionState::Finished
                | SessionState::Faulted),
            ) => state,
            Ok(SessionState::Unspecified | SessionState::Closed) | Err(_) => {
                return Err(unfit(&format!(
                    "its session state {} is not one a session resumes in",
                    self.record.state
                )));
            }
        };
        // A run target is checked as `Run` checks one: a forged blob must
        // not pace a run at -1 or NaN times real time.
        let run = self
            .record
            .run
            .map(|r| {
                Ok::<_, ServiceError>(RunTarget {
                    until: r.until_time.map(RunTarget::check_until).transpose()?,
                    realtime_factor: RunTarget::check_realtime_factor(r.realtime_factor)?,
                })
            })
            .transpose()
            .map_err(|e| unfit(&format!("its run target: {e}")))?;
        // The blob's reason is input like any other: quoted short.
        let reason = format!(
            "restored at step {}; it was {}",
            world.clock().step,
            crate::error::quote(&self.record.reason)
        );
        Ok(Resumed {
            world,
            session: ResumedSession {
                state,
                reason,
                run,
                warm,
                constraints,
                controls,
                last: self.last,
            },
        })
    }
}

/// The error of a snapshot whose content its scene refuses, saying why.
pub fn unfit(e: &dyn std::fmt::Display) -> ServiceError {
    ServiceError::invalid("data", format!("the snapshot does not fit its scene: {e}"))
}

/// A blob of `payload`, refused when over `limit` bytes.
///
/// # Errors
/// [`ServiceError::SnapshotTooLarge`].
pub fn encode(payload: &v1::SnapshotPayload, limit: usize) -> Result<Vec<u8>, ServiceError> {
    let data = blob::encode(payload);
    if data.len() > limit {
        return Err(ServiceError::SnapshotTooLarge {
            size: data.len(),
            limit,
        });
    }
    Ok(data)
}

impl DesignState {
    /// Takes a restored session's constraints, controls and last design.
    pub(super) fn resume(
        &mut self,
        constraints: ConstraintSet,
        controls: Controls,
        last: Option<v1::DesignResult>,
    ) {
        self.constraints = constraints;
        self.controls = controls;
        self.last = last.map(Arc::new);
        self.revision += 1;
    }
}
