//! Experimental reference data for validation, with their sources, and the
//! measurements that compare a simulation with them.

use crate::math::{Real, Vector};

pub mod cantilever;
pub mod design;

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
}
