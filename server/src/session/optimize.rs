//! Optimisation on a session's compute thread (tutorial Section 8): the
//! job a gRPC handler hands the worker, the solve with its progress and
//! cancellation, the result kept for `GetDesign` and the playback frames.

use crate::error::ServiceError;
use meshless_engine::design::{
    ConstraintSet, DesignParams, DesignTarget, MotionParams, Progress, solve_motion_cancellable,
    solve_shape_cancellable,
};
use meshless_engine::math::Vector;
use meshless_engine::{Cancel, Frame, World};
use meshless_proto::v1;
use meshless_wire::design::{
    design_params_from_proto, design_settings_to_proto, info_to_proto, progress_to_proto,
};
use meshless_wire::snapshot::{flatten, vectors};
use std::ops::ControlFlow;
use std::sync::Arc;
use tokio::sync::{mpsc, oneshot};
use tokio_util::sync::CancellationToken;

/// Most playback frames one motion publishes; a higher rate is cut there.
const MAX_PLAYBACK_FRAMES: usize = 10_000;

/// What to optimise.
#[derive(Debug, Clone, PartialEq)]
pub struct OptimizeJob {
    /// The scene system (an elastic solid).
    pub system: usize,
    pub params: DesignParams,
    pub problem: Problem,
    /// Publish the result as frames.
    pub playback: bool,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Problem {
    Shape,
    Motion {
        params: MotionParams,
        /// Playback frames per second of design time, > 0.
        playback_rate: f64,
    },
}

/// Where an optimisation reports, and how it is stopped.
#[derive(Debug)]
pub struct Channels {
    /// Progress, dropped when the reader is behind.
    pub progress: mpsc::Sender<v1::DesignProgress>,
    pub result: oneshot::Sender<Result<Arc<v1::DesignResult>, ServiceError>>,
    /// Raised by `CancelOptimize`, when the client drops the stream, and
    /// when the session shuts down; the solver reads it within its
    /// iterations.
    pub cancel: Cancel,
}

/// The last shape solve, to start the next one of the same system and
/// settings from (dragging a handle re-solves from where the shape is).
#[derive(Debug, Clone)]
pub struct WarmStart {
    system: usize,
    params: DesignParams,
    displacements: Vec<Vector>,
}

impl WarmStart {
    /// Its message, for a snapshot.
    pub fn to_proto(&self) -> v1::DesignWarmStart {
        v1::DesignWarmStart {
            system: u32::try_from(self.system).unwrap_or(u32::MAX),
            settings: Some(design_settings_to_proto(&self.params)),
            displacements: flatten(&self.displacements),
        }
    }

    /// A snapshot's warm start, checked against `world`: a solid's system
    /// and one finite displacement per particle of its design
    /// discretisation.
    ///
    /// # Errors
    /// What does not fit, as text.
    pub fn from_proto(message: v1::DesignWarmStart, world: &World) -> Result<Self, String> {
        let v1::DesignWarmStart {
            system,
            settings,
            displacements,
        } = message;
        let system = system as usize;
        let params = design_params_from_proto(settings).map_err(|e| e.to_string())?;
        // The design's own particles, as the next solve samples them.
        let target = DesignTarget::new(world, system, &params).map_err(|e| e.to_string())?;
        let count = target.body().rest().len();
        if displacements.len() != 3 * count || displacements.iter().any(|d| !d.is_finite()) {
            return Err(format!(
                "its warm start holds {} values, not 3 finite values for each of the {count} \
                 design particles of systems[{system}]",
                displacements.len()
            ));
        }
        Ok(Self {
            system,
            params,
            displacements: vectors(displacements, "warm_start.displacements")
                .map_err(|e| e.to_string())?,
        })
    }
}

/// A solved design, ready to keep and to play back.
#[derive(Debug)]
pub struct Solved {
    pub result: v1::DesignResult,
    /// Set for a shape: the next warm start.
    pub warm: Option<WarmStart>,
    /// The design posed at each playback time (empty without playback).
    pub playback: Vec<Frame>,
}

/// Solves `job` on `world`'s solid against `constraints`. Stops with
/// [`meshless_engine::design::DesignError::Cancelled`] once `cancel` or
/// `shutdown` is set (within an iteration: whoever sets either raises
/// `cancel`), or the progress reader is gone.
///
/// # Errors
/// The engine's design errors; nothing is changed.
pub fn solve(
    id: &str,
    world: &World,
    constraints: &ConstraintSet,
    job: &OptimizeJob,
    warm: Option<&WarmStart>,
    channels: &Channels,
    shutdown: &CancellationToken,
) -> Result<Solved, ServiceError> {
    let mut observer = |p: &Progress| {
        // `channels.cancel` the solver reads itself.
        if shutdown.is_cancelled() || channels.progress.is_closed() {
            return ControlFlow::Break(());
        }
        // A full queue drops this report: the reader sees later ones.
        let _ = channels.progress.try_send(progress_to_proto(p));
        ControlFlow::Continue(())
    };
    let target = DesignTarget::new(world, job.system, &job.params)?;
    let body = target.body();
    let rest_positions = flatten(body.rest());
    let now = world.clock().time;
    let (kind, info, times, frames, warm, playback) = match job.problem {
        Problem::Shape => {
            let warm = warm
                .filter(|w| w.system == job.system && w.params == job.params)
                .map(|w| w.displacements.as_slice());
            let solution = solve_shape_cancellable(
                body,
                constraints,
                &job.params,
                warm,
                &mut observer,
                &channels.cancel,
            )?;
            let playback = if job.playback {
                vec![target.frame(world, &solution.displacements, now)]
            } else {
                Vec::new()
            };
            let frames = flatten(&solution.displacements);
            let warm = WarmStart {
                system: job.system,
                params: job.params,
                displacements: solution.displacements,
            };
            (
                v1::DesignKind::Shape,
                solution.info,
                vec![0.0],
                frames,
                Some(warm),
                playback,
            )
        }
        Problem::Motion {
            params,
            playback_rate,
        } => {
            let solution = solve_motion_cancellable(
                body,
                constraints,
                &job.params,
                &params,
                &mut observer,
                &channels.cancel,
            )?;
            let mut playback = Vec::new();
            if job.playback {
                let (start, end) = solution.span();
                let count =
                    (((end - start) * playback_rate).floor() as usize + 1).min(MAX_PLAYBACK_FRAMES);
                for k in 0..count {
                    let t = (start + k as f64 / playback_rate).min(end);
                    let u = solution.displacements_at(t)?;
                    playback.push(target.frame(world, &u, t));
                }
            }
            let frames = solution.frames().iter().flat_map(|f| flatten(f)).collect();
            (
                v1::DesignKind::Motion,
                solution.info,
                solution.times().to_vec(),
                frames,
                None,
                playback,
            )
        }
    };
    Ok(Solved {
        result: v1::DesignResult {
            session_id: id.to_owned(),
            system: u32::try_from(job.system).unwrap_or(u32::MAX),
            kind: kind as i32,
            info: Some(info_to_proto(&info)),
            rest_positions,
            times,
            displacements: frames,
        },
        warm,
        playback,
    })
}
