//! Modal warping (Choi & Ko 2005; Guo & Qin Sec. 5.3.2, Eq. 26-30): each
//! node carries a local frame rotated by its rotation vector
//! `w_I = W_I z` (Eq. 27). The modal ODEs are solved in those frames, so
//! loads are rotated into them (`F_z = Psi^T R^T F`, Eq. 29-30), and the
//! local displacement `u^L_I = Psi_I z` is warped back by integrating
//! the rotation along the straight path `s z`, `s` in `[0, 1]`:
//! `u_I = (int_0^1 R(s w_I) ds) u^L_I`. A linear (unwarped) body uses
//! `F_z = Psi^T F` and `u_I = u^L_I` (Eq. 25).
//!
//! Both per-node loops run in parallel over fixed chunks of nodes; the
//! modal force sums the chunks' partial sums in chunk order, so its bits
//! do not depend on the thread count.

use nalgebra::{DVector, DVectorView, DVectorViewMut, Matrix3, Rotation3};
use rayon::prelude::*;

use super::ModalBasis;
use crate::math::{Real, Vector};

/// Nodes per parallel chunk: fixed rather than per thread so that the
/// summation order of the modal force is reproducible; 512 nodes make a
/// task of some `3000 l` flops, well above rayon's per-task cost.
pub(super) const NODES_PER_CHUNK: usize = 512;

/// Below this angle (radians) the coefficients of [`rotation_integral`]
/// come from their Taylor series. The closed forms lose digits to
/// cancellation: `1 - cos t` and `t - sin t` carry relative errors of
/// about `2 eps / t^2` and `6 eps / t^2`, at most `1.3e-13` above
/// `t = 0.1` (and they multiply `[w]x` and `[w]x^2`, of size `t` and
/// `t^2`, so the matrix keeps ~1e-15 absolute).
/// The series through `t^8` truncates at `2 t^10 / 12!` relative, `4e-19`
/// at `t = 0.1`, so both branches are exact to rounding at the switch.
const SERIES_THRESHOLD: Real = 0.1;

/// `int_0^1 R(s w) ds` for the rotation vector `w` (angle `t = |w|` about
/// `w / t`): with `R(s w) = I + sin(st) [n]x + (1 - cos(st)) [n]x^2`,
/// `n = w / t`, integrating over `s` gives
/// `I + (1 - cos t) / t^2 [w]x + (t - sin t) / t^3 [w]x^2`.
/// It warps a local displacement into the world frame (Choi & Ko 2005;
/// Guo & Qin Sec. 5.3.2), and is
/// public so that points between the nodes (surface samples) can be
/// warped with their own interpolated `w`.
pub fn rotation_integral(w: &Vector) -> Matrix3<Real> {
    let (a, b) = coefficients(w.norm());
    let k = w.cross_matrix();
    Matrix3::identity() + k * a + k * k * b
}

/// `((1 - cos t) / t^2, (t - sin t) / t^3)`, by series below
/// [`SERIES_THRESHOLD`].
fn coefficients(t: Real) -> (Real, Real) {
    if t < SERIES_THRESHOLD {
        series(t * t)
    } else {
        closed(t)
    }
}

/// The closed forms of [`coefficients`].
fn closed(t: Real) -> (Real, Real) {
    let t2 = t * t;
    ((1.0 - t.cos()) / t2, (t - t.sin()) / (t2 * t))
}

/// The Taylor series of [`coefficients`] in `t2 = t^2`, through `t^8`:
/// `sum_k (-1)^k t^2k / (2k+2)!` and `sum_k (-1)^k t^2k / (2k+3)!`.
fn series(t2: Real) -> (Real, Real) {
    let a = 1.0 / 2.0
        - t2 * (1.0 / 24.0 - t2 * (1.0 / 720.0 - t2 * (1.0 / 40_320.0 - t2 / 3_628_800.0)));
    let b = 1.0 / 6.0
        - t2 * (1.0 / 120.0 - t2 * (1.0 / 5_040.0 - t2 * (1.0 / 362_880.0 - t2 / 39_916_800.0)));
    (a, b)
}

/// The modal force into `out`: `Psi^T (R^T F)` when `warping` (Eq. 30,
/// `R_I = R(w_I)` at the amplitudes `z` of the step's start) or
/// `Psi^T F` (Eq. 25). `partials` holds one `l`-vector per chunk of
/// [`NODES_PER_CHUNK`] nodes.
pub(super) fn modal_force(
    basis: &ModalBasis,
    z: &DVector<Real>,
    warping: bool,
    loads: &[Vector],
    partials: &mut [Real],
    out: &mut DVector<Real>,
) {
    let l = basis.mode_count();
    partials
        .par_chunks_mut(l)
        .zip(loads.par_chunks(NODES_PER_CHUNK))
        .enumerate()
        .for_each(|(chunk, (part, loads))| {
            let mut part = DVectorViewMut::from_slice(part, l);
            part.fill(0.0);
            for (k, f) in loads.iter().enumerate() {
                let node = chunk * NODES_PER_CHUNK + k;
                let local = if warping {
                    Rotation3::new(basis.rotation_vector(node, z)).inverse_transform_vector(f)
                } else {
                    *f
                };
                basis.accumulate_force(node, &local, &mut part);
            }
        });
    out.fill(0.0);
    for part in partials.chunks_exact(l) {
        *out += DVectorView::from_slice(part, l);
    }
}

/// The nodal displacements at amplitudes `z` into `out` (one per node):
/// warped `(int_0^1 R(s w_I) ds) Psi_I z` or linear `Psi_I z`.
pub(super) fn displacements(
    basis: &ModalBasis,
    z: &DVector<Real>,
    warping: bool,
    out: &mut [Vector],
) {
    out.par_chunks_mut(NODES_PER_CHUNK)
        .enumerate()
        .for_each(|(chunk, out)| {
            for (k, u) in out.iter_mut().enumerate() {
                let node = chunk * NODES_PER_CHUNK + k;
                let linear = basis.linear_displacement(node, z);
                *u = if warping {
                    rotation_integral(&basis.rotation_vector(node, z)) * linear
                } else {
                    linear
                };
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::uniform;

    /// Composite Simpson of `R(s w) u` over `s` in `[0, 1]`.
    fn simpson(w: &Vector, u: &Vector, intervals: usize) -> Vector {
        let h = 1.0 / intervals as Real;
        let mut sum = Vector::zeros();
        for i in 0..=intervals {
            let weight = if i == 0 || i == intervals {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            sum += Rotation3::new(w * (i as Real * h)) * u * weight;
        }
        sum * (h / 3.0)
    }

    #[test]
    fn rotation_integral_matches_simpson_quadrature() {
        let mut seed = 11;
        for angle in [1e-6, 1e-3, 0.05, 0.0999, 0.1001, 0.3, 1.0, 2.0, 3.0] {
            for _ in 0..3 {
                let axis = Vector::new(
                    uniform(&mut seed) - 0.5,
                    uniform(&mut seed) - 0.5,
                    uniform(&mut seed) - 0.5,
                )
                .normalize();
                let u = Vector::new(uniform(&mut seed), -uniform(&mut seed), 0.5);
                let w = axis * angle;
                let exact = rotation_integral(&w) * u;
                // Simpson's error is h^4 t^4 / 180 |u|: 7e-15 at t = 3.
                let reference = simpson(&w, &u, 2000);
                let error = (exact - reference).norm() / u.norm();
                assert!(error < 1e-12, "angle {angle}: relative error {error:e}");
            }
        }
    }

    #[test]
    fn coefficients_are_continuous_across_the_series_threshold() {
        for t in [
            0.5 * SERIES_THRESHOLD,
            SERIES_THRESHOLD,
            1.5 * SERIES_THRESHOLD,
        ] {
            let (sa, sb) = series(t * t);
            let (ca, cb) = closed(t);
            // The closed forms' own cancellation error bounds the
            // agreement: 2 eps / t^2 and 6 eps / t^2 relative.
            let bound = 8.0 * Real::EPSILON / (t * t);
            assert!(((sa - ca) / ca).abs() < bound, "t = {t}: a {sa} vs {ca}");
            assert!(((sb - cb) / cb).abs() < bound, "t = {t}: b {sb} vs {cb}");
        }
        // At the switch both branches give the same matrix to rounding:
        // no jump in the warped displacement as an angle crosses it.
        let w = Vector::new(0.3, -0.4, 1.2).normalize() * SERIES_THRESHOLD;
        let k = w.cross_matrix();
        let matrix = |(a, b): (Real, Real)| Matrix3::identity() + k * a + k * k * b;
        let t = w.norm();
        let jump = (matrix(series(t * t)) - matrix(closed(t))).norm();
        assert!(jump < 4.0 * Real::EPSILON, "jump at the threshold {jump:e}");
    }

    #[test]
    fn zero_rotation_integrates_to_identity() {
        assert_eq!(rotation_integral(&Vector::zeros()), Matrix3::identity());
    }
}
