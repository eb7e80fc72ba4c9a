//! The dam break: a water column of width `a` and height `2a` collapsing
//! against a wall, measured by Martin & Moyce (1952). The measured surge
//! front, the front of a simulation, their error, and a whole run of a
//! dam-break scene that measures it (`meshless study`'s sweeps).

use meshless_engine::math::{Real, Vector};
use meshless_engine::scene::{FluidSpec, SystemSpec};
use meshless_engine::{BuildOptions, Scene, SceneError, StepError};
use std::time::Instant;

/// Surge front of a collapsing water column of width `a` and height `2a`:
/// `(T, Z)` with `T = t sqrt(2 g / a)` and `Z = x_front / a`, `x` measured
/// from the wall behind the column.
///
/// Source: J. C. Martin and W. J. Moyce (1952), "An experimental study of
/// the collapse of liquid columns on a rigid horizontal plane", Phil.
/// Trans. R. Soc. A 244, 312-324, as tabulated in the project's reference
/// set (`shared/reference/dam_break_martin_moyce_1952.csv`); independent
/// digitisations agree within a few percent.
pub const MARTIN_MOYCE_FRONT: [(Real, Real); 15] = [
    (0.41, 1.11),
    (0.84, 1.22),
    (1.19, 1.44),
    (1.43, 1.67),
    (1.63, 1.89),
    (1.83, 2.11),
    (1.98, 2.33),
    (2.20, 2.56),
    (2.32, 2.78),
    (2.51, 3.00),
    (2.65, 3.22),
    (2.83, 3.44),
    (2.98, 3.67),
    (3.11, 3.89),
    (3.33, 4.11),
];

/// The dam break's time scale: `T = t * time_scale(a, g)`.
pub fn dam_break_time_scale(column_width: Real, gravity: Real) -> Real {
    (2.0 * gravity / column_width).sqrt()
}

/// The surge front `Z = x / a`: the 99.5th percentile of `x` among
/// particles lower than `a / 6`, so a stray particle does not define it.
/// `None` when no particle is that low.
pub fn surge_front(positions: &[Vector], column_width: Real) -> Option<Real> {
    let mut xs: Vec<Real> = positions
        .iter()
        .filter(|p| p.y < column_width / 6.0)
        .map(|p| p.x)
        .collect();
    if xs.is_empty() {
        return None;
    }
    xs.sort_by(Real::total_cmp);
    Some(xs[((xs.len() - 1) as Real * 0.995).round() as usize] / column_width)
}

/// Linear interpolation of a `(T, Z)` curve sorted by `T`.
pub fn interpolate(curve: &[(Real, Real)], t: Real) -> Option<Real> {
    if curve.len() < 2 || t < curve[0].0 || t > curve[curve.len() - 1].0 {
        return None;
    }
    let k = curve
        .partition_point(|&(ct, _)| ct < t)
        .clamp(1, curve.len() - 1);
    let ((t0, z0), (t1, z1)) = (curve[k - 1], curve[k]);
    Some(z0 + (z1 - z0) * (t - t0) / (t1 - t0))
}

/// Worst and root-mean-square relative error of a simulated front curve
/// against [`MARTIN_MOYCE_FRONT`] for `1 <= T <= 3`; `None` when the curve
/// does not cover that range.
pub fn front_error(curve: &[(Real, Real)]) -> Option<(Real, Real)> {
    let errors: Vec<Real> = MARTIN_MOYCE_FRONT
        .iter()
        .filter(|(t, _)| (1.0..=3.0).contains(t))
        .map(|&(t, z)| interpolate(curve, t).map(|zs| (zs - z) / z))
        .collect::<Option<_>>()?;
    let worst = errors.iter().fold(0.0, |w: Real, e| w.max(e.abs()));
    let rms = (errors.iter().map(|e| e * e).sum::<Real>() / errors.len() as Real).sqrt();
    Some((worst, rms))
}

/// Why a scene is not a Martin & Moyce dam break.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ColumnError {
    /// The first system is not a fluid.
    #[error("the scene's first system is no fluid to study")]
    NoFluid,
    /// The fluid starts with no block of water.
    #[error("the fluid has no block")]
    NoBlock,
    /// The first block is not a column of width `a`, height `2a`, in the
    /// corner.
    #[error(
        "the study compares with Martin & Moyce: the first block must be a column of width a \
         and height 2a standing in the corner at the domain's min x and min y"
    )]
    NotAColumn,
}

/// The first system of `scene`, when it is a fluid.
fn first_fluid(scene: &Scene) -> Option<&FluidSpec> {
    scene.systems.first().and_then(SystemSpec::as_fluid)
}

/// The column width `a` of a dam-break scene, checking that its first
/// fluid block is a Martin & Moyce column: width `a`, height `2a` (within
/// 1 %), standing in the corner at the domain's min x and min y.
///
/// # Errors
/// A [`ColumnError`] saying which of these the scene is not.
pub fn column_width(scene: &Scene) -> Result<Real, ColumnError> {
    let domain_min = scene.domain.min;
    let fluid = first_fluid(scene).ok_or(ColumnError::NoFluid)?;
    let column = fluid.blocks.first().ok_or(ColumnError::NoBlock)?.region;
    let (a, height) = (column.max[0] - column.min[0], column.max[1] - column.min[1]);
    if (column.min[0] - domain_min[0]).abs() > 1e-9
        || (column.min[1] - domain_min[1]).abs() > 1e-9
        || (height - 2.0 * a).abs() > 0.01 * a
    {
        return Err(ColumnError::NotAColumn);
    }
    Ok(a)
}

/// How a [`FrontRun`] ended.
#[derive(Debug, Clone)]
pub enum RunStatus {
    /// It reached `T = 3.4`.
    Ok,
    /// The scene did not build.
    Invalid(SceneError),
    /// A step failed; the run stopped there.
    Failed(StepError),
}

impl std::fmt::Display for RunStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Ok => write!(f, "ok"),
            Self::Invalid(e) => write!(f, "invalid: {e}"),
            Self::Failed(e) => write!(f, "failed: {e}"),
        }
    }
}

/// What one run of a dam-break scene measured.
#[derive(Debug, Clone)]
pub struct FrontRun {
    /// Particles of the world (0 when it did not build).
    pub particles: usize,
    /// Sub-steps, summed over the steps.
    pub substeps: u64,
    /// Pressure-solver iterations, summed over the steps.
    pub iterations: u64,
    /// Wall time of the stepping and measuring, s.
    pub seconds: f64,
    /// Worst and rms front error for `1 <= T <= 3` ([`front_error`]), when
    /// the run covered that range.
    pub error: Option<(Real, Real)>,
    /// How the run ended.
    pub status: RunStatus,
}

/// Runs a dam-break scene with column width `a` to `T = 3.4`, measuring
/// the surge front after every step; `on_step` hears each step's `T` (for
/// progress). A scene that does not build or a step that fails ends the
/// run with what was measured so far.
pub fn run_front(scene: &Scene, a: Real, mut on_step: impl FnMut(Real)) -> FrontRun {
    let scale = dam_break_time_scale(a, -scene.gravity[1]);
    let mut run = FrontRun {
        particles: 0,
        substeps: 0,
        iterations: 0,
        seconds: 0.0,
        error: None,
        status: RunStatus::Ok,
    };
    let mut world = match scene.build(&BuildOptions::default()) {
        Ok(world) => world,
        Err(e) => {
            run.status = RunStatus::Invalid(e);
            return run;
        }
    };
    run.particles = world.particle_count();
    let start = Instant::now();
    let mut curve = Vec::new();
    while world.clock().time * scale < 3.4 {
        match world.step() {
            Ok(info) => {
                run.substeps += u64::from(info.substeps);
                run.iterations += u64::from(info.solver_iterations);
            }
            Err(e) => {
                run.status = RunStatus::Failed(e);
                break;
            }
        }
        if let Some(z) = world.fluid().and_then(|f| surge_front(&f.positions, a)) {
            curve.push((world.clock().time * scale, z));
        }
        on_step(world.clock().time * scale);
    }
    run.seconds = start.elapsed().as_secs_f64();
    run.error = front_error(&curve);
    run
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_measured_curve_has_no_error_against_itself() {
        let (worst, rms) = front_error(&MARTIN_MOYCE_FRONT).expect("covers 1..3");
        assert!(worst < 1e-12 && rms < 1e-12);
        let shifted: Vec<_> = MARTIN_MOYCE_FRONT
            .iter()
            .map(|&(t, z)| (t, 1.1 * z))
            .collect();
        let (worst, _) = front_error(&shifted).expect("covers 1..3");
        assert!((worst - 0.1).abs() < 1e-12);
        assert!(front_error(&MARTIN_MOYCE_FRONT[..3]).is_none());
    }

    #[test]
    fn the_front_ignores_high_and_stray_particles() {
        let a = 0.3;
        let mut positions: Vec<Vector> = (0..1000)
            .map(|i| Vector::new(i as Real * 1e-3, 0.0, 0.0))
            .collect();
        positions.push(Vector::new(5.0, 0.0, 0.0));
        positions.push(Vector::new(9.0, 1.0, 0.0));
        let z = surge_front(&positions, a).expect("particles on the floor");
        assert!((z - 0.995 / a).abs() < 0.01, "{z}");
    }

    /// The shipped dam break is a Martin & Moyce column of width 0.3 m;
    /// a taller column or a solid is refused.
    #[test]
    fn columns_are_recognised() {
        let mut scene = Scene::from_toml_str(include_str!("../../scenes/dam_break.toml"))
            .expect("shipped scene");
        assert_eq!(column_width(&scene), Ok(0.3));
        let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
            panic!("the dam break is a fluid")
        };
        fluid.blocks[0].region.max[1] *= 1.5;
        assert_eq!(column_width(&scene), Err(ColumnError::NotAColumn));
        let jelly = Scene::from_toml_str(include_str!("../../scenes/jelly_drop.toml"))
            .expect("shipped scene");
        assert_eq!(column_width(&jelly), Err(ColumnError::NoFluid));
    }
}
