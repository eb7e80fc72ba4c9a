//! Modal warping (Choi & Ko 2005; Guo & Qin Sec. 5.3.2, Eq. 26-30): each
//! node carries a local frame rotated by its rotation vector
//! `w_I = W_I z` (Eq. 27). The modal ODEs are solved in those frames, so
//! loads are rotated into them (`F_z = Psi^T R^T F`, Eq. 29-30), and the
//! local displacement `u^L_I = Psi_I z` is warped back by integrating
//! the rotation along the straight path `s z`, `s` in `[0, 1]`:
//! `u_I = (int_0^1 R(s w_I) ds) u^L_I`. A linear (unwarped) body uses
//! `F_z = Psi^T F` and `u_I = u^L_I` (Eq. 25).
//!
//! [`NodeFrames`] holds the per-node kinematics at the current
//! amplitudes: a step's force reads the rotations at the amplitudes it
//! starts from, which are the ones the previous step (or state change)
//! ended on, so each basis matrix is read once per step for the nodal
//! state and `Psi` once more for the force, and each node's sine and
//! cosine are taken once. Both passes run in parallel over fixed chunks
//! of nodes, each chunk one dense matrix-vector product (faer's, which
//! picks the widest SIMD the processor has at run time) and a per-node
//! loop; the modal force sums the chunks' partial sums in chunk order, so
//! its bits do not depend on the thread count.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::{DVector, Matrix3};
use rayon::prelude::*;

use super::ModalBasis;
use crate::math::{Real, Vector};

/// Nodes per parallel chunk: fixed rather than per thread so that the
/// summation order of the modal force is reproducible. 256 nodes are a
/// task of some `1500 l` flops and 256 sines and cosines, well above
/// rayon's per-task cost, and a 1,000-node body still gives two threads
/// two chunks each.
pub(super) const NODES_PER_CHUNK: usize = 256;

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
    rotation_and_integral(w).1
}

/// `R(w)` (Rodrigues: `I + sin t / t [w]x + (1 - cos t) / t^2 [w]x^2`)
/// and [`rotation_integral`], from one sine and cosine: they share the
/// coefficient of `[w]x^2` in `R` with that of `[w]x` in the integral.
fn rotation_and_integral(w: &Vector) -> (Matrix3<Real>, Matrix3<Real>) {
    let [s, a, b] = coefficients(w.norm());
    let k = w.cross_matrix();
    let k2 = k * k;
    (
        Matrix3::identity() + k * s + k2 * a,
        Matrix3::identity() + k * a + k2 * b,
    )
}

/// `[sin t / t, (1 - cos t) / t^2, (t - sin t) / t^3]`, by series below
/// [`SERIES_THRESHOLD`].
fn coefficients(t: Real) -> [Real; 3] {
    if t < SERIES_THRESHOLD {
        series(t * t)
    } else {
        closed(t)
    }
}

/// The closed forms of [`coefficients`].
fn closed(t: Real) -> [Real; 3] {
    let (sin, cos) = t.sin_cos();
    let t2 = t * t;
    [sin / t, (1.0 - cos) / t2, (t - sin) / (t2 * t)]
}

/// The Taylor series of [`coefficients`] in `t2 = t^2`, through `t^8`:
/// `sum_k (-1)^k t^2k / (2k+1+j)!` for `j = 0, 1, 2` (`sin t / t`
/// truncates at `t^10 / 11!`, below the other two).
fn series(t2: Real) -> [Real; 3] {
    let s = 1.0 - t2 * (1.0 / 6.0 - t2 * (1.0 / 120.0 - t2 * (1.0 / 5_040.0 - t2 / 362_880.0)));
    let a = 1.0 / 2.0
        - t2 * (1.0 / 24.0 - t2 * (1.0 / 720.0 - t2 * (1.0 / 40_320.0 - t2 / 3_628_800.0)));
    let b = 1.0 / 6.0
        - t2 * (1.0 / 120.0 - t2 * (1.0 / 5_040.0 - t2 * (1.0 / 362_880.0 - t2 / 39_916_800.0)));
    [s, a, b]
}

/// The per-node kinematics at one set of amplitudes `z`: `u^L = Psi z`,
/// `w = W z`, each node's rotation `R(w_I)` (the identity when not
/// warping) and its displacement, plus the scratch of the force pass.
/// Sized once; updating allocates nothing.
#[derive(Debug, Clone)]
pub(super) struct NodeFrames {
    /// `u^L`, `3n`.
    linear: Vec<Real>,
    /// `w`, `3n`.
    rotation_vectors: Vec<Real>,
    /// `R(w_I)`.
    rotations: Vec<Matrix3<Real>>,
    /// Warped or linear displacement per node.
    displacements: Vec<Vector>,
    /// `R_I^T F_I`, `3n`: the force pass's scratch.
    local_loads: Vec<Real>,
    /// One `l`-vector of partial modal force per chunk of nodes.
    partials: Vec<Real>,
}

impl NodeFrames {
    /// The frames of `basis` at rest (`z = 0`).
    pub(super) fn new(basis: &ModalBasis) -> Self {
        let n = basis.node_count();
        let chunks = n.div_ceil(NODES_PER_CHUNK);
        Self {
            linear: vec![0.0; 3 * n],
            rotation_vectors: vec![0.0; 3 * n],
            rotations: vec![Matrix3::identity(); n],
            displacements: vec![Vector::zeros(); n],
            local_loads: vec![0.0; 3 * n],
            partials: vec![0.0; chunks * basis.mode_count()],
        }
    }

    /// Recomputes everything at amplitudes `z`: warped displacements
    /// `(int_0^1 R(s w_I) ds) Psi_I z` when `warping`, linear `Psi_I z`
    /// otherwise.
    pub(super) fn update(&mut self, basis: &ModalBasis, z: &DVector<Real>, warping: bool) {
        let l = basis.mode_count();
        let z = MatRef::from_column_major_slice(z.as_slice(), l, 1);
        let slab = 3 * NODES_PER_CHUNK;
        self.linear
            .par_chunks_mut(slab)
            .zip(self.rotation_vectors.par_chunks_mut(slab))
            .zip(self.rotations.par_chunks_mut(NODES_PER_CHUNK))
            .zip(self.displacements.par_chunks_mut(NODES_PER_CHUNK))
            .enumerate()
            .for_each(|(chunk, (((linear, w), rotations), displacements))| {
                let dofs = chunk * slab..chunk * slab + linear.len();
                let rows = linear.len();
                let product = |t: &[Real], out: &mut [Real]| {
                    let block =
                        MatRef::from_column_major_slice(&t[l * dofs.start..l * dofs.end], l, rows);
                    matmul(
                        MatMut::from_column_major_slice_mut(out, rows, 1),
                        Accum::Replace,
                        block.transpose(),
                        z,
                        1.0,
                        Par::Seq,
                    );
                };
                product(basis.psi_t(), linear);
                product(basis.w_t(), w);
                let (linear, w) = (&*linear, &*w);
                for (k, (r, u)) in rotations.iter_mut().zip(displacements).enumerate() {
                    let local = Vector::from_column_slice(&linear[3 * k..3 * k + 3]);
                    if warping {
                        let (rotation, integral) =
                            rotation_and_integral(&Vector::from_column_slice(&w[3 * k..3 * k + 3]));
                        *r = rotation;
                        *u = integral * local;
                    } else {
                        *r = Matrix3::identity();
                        *u = local;
                    }
                }
            });
    }

    /// The modal force into `out` at the amplitudes of the last
    /// [`Self::update`]: `Psi^T (R^T F)` (Eq. 30; `R` the identity when
    /// not warping, Eq. 25). `loads` has one entry per node.
    pub(super) fn modal_force(
        &mut self,
        basis: &ModalBasis,
        loads: &[Vector],
        out: &mut DVector<Real>,
    ) {
        let l = basis.mode_count();
        let slab = 3 * NODES_PER_CHUNK;
        let psi_t = basis.psi_t();
        self.partials
            .par_chunks_mut(l)
            .zip(self.local_loads.par_chunks_mut(slab))
            .zip(self.rotations.par_chunks(NODES_PER_CHUNK))
            .zip(loads.par_chunks(NODES_PER_CHUNK))
            .enumerate()
            .for_each(|(chunk, (((part, local), rotations), loads))| {
                for (k, (r, f)) in rotations.iter().zip(loads).enumerate() {
                    local[3 * k..3 * k + 3].copy_from_slice(r.tr_mul(f).as_slice());
                }
                let start = l * chunk * slab;
                matmul(
                    MatMut::from_column_major_slice_mut(part, l, 1),
                    Accum::Replace,
                    MatRef::from_column_major_slice(
                        &psi_t[start..start + l * local.len()],
                        l,
                        local.len(),
                    ),
                    MatRef::from_column_major_slice(local, local.len(), 1),
                    1.0,
                    Par::Seq,
                );
            });
        out.fill(0.0);
        for part in self.partials.chunks_exact(l) {
            for (o, p) in out.iter_mut().zip(part) {
                *o += p;
            }
        }
    }

    /// The nodal displacements at the last update.
    pub(super) fn displacements(&self) -> &[Vector] {
        &self.displacements
    }

    /// `u^L = Psi z` at the last update, `3n` values (node-major).
    pub(super) fn linear(&self) -> &[Real] {
        &self.linear
    }

    /// Node `node`'s rotation `R(w_I)` at the last update (the identity
    /// when not warping).
    pub(super) fn rotation(&self, node: usize) -> &Matrix3<Real> {
        &self.rotations[node]
    }

    /// Node `node`'s rotation vector `w_I = W_I z` at the last update
    /// (with or without warping: a point cloud's normals turn by it).
    pub(super) fn rotation_vector(&self, node: usize) -> Vector {
        Vector::from_column_slice(&self.rotation_vectors[3 * node..3 * node + 3])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::uniform;
    use nalgebra::Rotation3;

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
            let series = series(t * t);
            let closed = closed(t);
            // The closed forms' own cancellation error bounds the
            // agreement: 2 eps / t^2 and 6 eps / t^2 relative (sin t / t
            // has none).
            let bound = 8.0 * Real::EPSILON / (t * t);
            for (j, (s, c)) in series.iter().zip(&closed).enumerate() {
                assert!(
                    ((s - c) / c).abs() < bound,
                    "t = {t}, coefficient {j}: {s} vs {c}"
                );
            }
        }
        // At the switch both branches give the same matrices to rounding:
        // no jump in the warped displacement as an angle crosses it.
        let w = Vector::new(0.3, -0.4, 1.2).normalize() * SERIES_THRESHOLD;
        let k = w.cross_matrix();
        let t = w.norm();
        let [s0, a0, b0] = series(t * t);
        let [s1, a1, b1] = closed(t);
        for ((x0, y0), (x1, y1)) in [((s0, a0), (s1, a1)), ((a0, b0), (a1, b1))] {
            let jump = (k * (x0 - x1) + k * k * (y0 - y1)).norm();
            assert!(jump < 4.0 * Real::EPSILON, "jump at the threshold {jump:e}");
        }
    }

    #[test]
    fn the_shared_coefficients_give_rodrigues_rotation() {
        let mut seed = 5;
        for angle in [0.0, 1e-7, 0.05, 0.0999, 0.1001, 1.0, 3.1] {
            let axis = Vector::new(
                uniform(&mut seed) - 0.5,
                uniform(&mut seed) - 0.5,
                uniform(&mut seed) - 0.5,
            )
            .normalize();
            let w = axis * angle;
            let (rotation, integral) = rotation_and_integral(&w);
            let error = (rotation - Rotation3::new(w).into_inner()).norm();
            assert!(
                error < 8.0 * Real::EPSILON,
                "angle {angle}: |R - Rotation3| = {error:e}"
            );
            assert_eq!(integral, rotation_integral(&w));
        }
    }

    #[test]
    fn zero_rotation_integrates_to_identity() {
        assert_eq!(rotation_integral(&Vector::zeros()), Matrix3::identity());
    }
}
