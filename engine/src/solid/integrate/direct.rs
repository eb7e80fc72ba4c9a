//! The implicit integrator's Newton matrix assembled and solved by sparse
//! Cholesky, for bodies (slender ones in bending above all) where
//! conjugate gradients converge too slowly.
//!
//! `H = M + dt^2 Hess U + dt D` is exact at the current stress states,
//! assembled in `dim x dim` blocks over the free particles only (anchored
//! rows and columns are removed, and a 2D body's constant `z` is left
//! out, so `H` is not singular):
//!
//! - **elastic and volume**: `U_i = V_i W(F_i)` with `F_i = I + sum_e (x_j -
//!   x_i - X_ij) g_e^T`, so `dF_i/dx_n = e_a c_n^T` with `c_n = g_e` for a
//!   neighbour `n = j` and `c_i = -sum_j g_ij`, and
//!   `d^2 U_i / dx_(n,a) dx_(m,b) = V_i (dP[e_a c_n^T] c_m)_b` with `dP` the
//!   exact derivative of the first Piola stress (`material.rs`);
//! - **hourglass**: `U_h,i = kappa_i / 2 sum_e w~_e |e_e|^2` is quadratic in
//!   `x`: each edge error is `e_e = sum_n alpha_n x_n` with `alpha_j += 1`,
//!   `alpha_i -= 1`, `alpha_n -= c_n . X_e`, so block `(m, n)` gains
//!   `kappa_i sum_e w~_e alpha_m alpha_n I`;
//! - **damping**: each edge `(i -> j)` adds `c_e [[nn^T, -nn^T], [-nn^T, nn^T]]` on
//!   `(i, j)`, `c_e = alpha m_i w~_e` (`forces.rs`).
//!
//! Each block column `n` gathers its blocks from the particles `i` whose
//! neighbourhood holds `n` (the edges ending at `n`), so columns are
//! assembled in parallel without locks (`linalg::sparse` stores them, as
//! the lower triangle of full block columns, and factorises). The pattern
//! and the fill-reducing ordering depend only on the topology and the
//! anchors, so they are computed once and reused until either changes.

use super::super::body::Body;
use super::super::material::StressState;
use crate::linalg::{BlockColumn, BlockPattern, SparseCholesky};
use crate::math::{Real, Vector};
use nalgebra::Matrix3;
use rayon::prelude::*;
use std::sync::Arc;

/// Marks an anchored particle in [`Pattern::index`].
const ANCHORED: u32 = u32::MAX;

/// The sparsity of `H` over the free particles, and what it was built for.
#[derive(Debug)]
struct Pattern {
    /// The neighbour lists and anchors it was built for: a plastic re-base
    /// or new anchors invalidate it.
    edges: Vec<u32>,
    fixed: Vec<bool>,
    /// Each particle's place among the free ones, or [`ANCHORED`].
    index: Vec<u32>,
    /// The free particles in that order.
    free: Vec<u32>,
    /// Block rows and symbolic factorisation, over the free particles.
    blocks: BlockPattern,
}

/// The direct solver's state, kept between Newton steps so that neither
/// the symbolic analysis nor the value arrays are redone.
#[derive(Debug, Clone, Default)]
pub(super) struct Direct {
    /// Shared, not copied, when a world is cloned: it depends only on the
    /// topology and the anchors.
    pattern: Option<Arc<Pattern>>,
    cholesky: SparseCholesky,
}

impl Direct {
    /// Bytes held by the last Cholesky factor.
    pub fn factor_bytes(&self) -> usize {
        self.cholesky.factor_bytes()
    }

    /// Solves `H d = -gradient` into `direction` by sparse Cholesky at the
    /// stress states `states` of `body`; returns false, leaving
    /// `direction` as it was, when `H` is not positive definite (the
    /// caller falls back to CG) or the factorisation cannot be had (too
    /// large, out of memory).
    pub fn direction(
        &mut self,
        body: &Body,
        states: &[StressState],
        contact: &[Matrix3<Real>],
        dt: Real,
        gradient: &[Vector],
        direction: &mut [Vector],
    ) -> bool {
        if !self.pattern.as_ref().is_some_and(|p| p.matches(body)) {
            self.pattern = Pattern::build(body).map(Arc::new);
        }
        let Some(pattern) = self.pattern.as_deref() else {
            return false;
        };
        let dim = pattern.blocks.dim();
        let rhs = pattern
            .free
            .iter()
            .flat_map(|&k| gradient[k as usize].iter().take(dim).map(|g| -g));
        let Some(solution) = self.cholesky.solve(
            &pattern.blocks,
            |n, out| assemble_column(body, states, contact, dt, pattern, n, out),
            rhs,
        ) else {
            return false;
        };
        direction.fill(Vector::zeros());
        for (d, &k) in solution.chunks_exact(dim).zip(&pattern.free) {
            for (out, v) in direction[k as usize].iter_mut().zip(d) {
                *out = *v;
            }
        }
        true
    }
}

impl Pattern {
    /// The pattern of `body`'s Hessian, or `None` when it is too large
    /// to index with 32 bits or its analysis runs out of memory.
    fn build(body: &Body) -> Option<Self> {
        let dim = body.params.dim;
        let t = &body.topology;
        let edges = t.gradients.neighbour_indices();
        let mut index = vec![ANCHORED; body.len()];
        let mut free = Vec::with_capacity(body.len());
        for (k, (slot, &fixed)) in index.iter_mut().zip(&body.fixed).enumerate() {
            if !fixed {
                *slot = free.len() as u32;
                free.push(k as u32);
            }
        }
        let columns: Vec<Vec<u32>> = free
            .par_iter()
            .enumerate()
            .map(|(n, &particle)| {
                let mut rows = Vec::new();
                for &e in t.incoming(particle as usize) {
                    let i = t.owner[e as usize] as usize;
                    for &m in &edges[t.gradients.range(i)] {
                        let m = index[m as usize];
                        if m != ANCHORED && m as usize >= n {
                            rows.push(m);
                        }
                    }
                }
                rows.sort_unstable();
                rows.dedup();
                rows
            })
            .collect();
        let blocks = BlockPattern::new(dim, &columns)?;
        Some(Self {
            edges: edges.to_vec(),
            fixed: body.fixed.clone(),
            index,
            free,
            blocks,
        })
    }

    /// Whether it still describes `body`.
    fn matches(&self, body: &Body) -> bool {
        self.blocks.dim() == body.params.dim
            && self.fixed == body.fixed
            && self.edges == body.topology.gradients.neighbour_indices()
    }
}

/// Block column `n` of `H` at the stress states `states` into `out`.
fn assemble_column(
    body: &Body,
    states: &[StressState],
    contact: &[Matrix3<Real>],
    dt: Real,
    pattern: &Pattern,
    n: usize,
    out: &mut BlockColumn<'_>,
) {
    let dim = pattern.blocks.dim();
    let model = body.model();
    let t = &body.topology;
    let edges = t.gradients.neighbour_indices();
    let g = t.gradients.all_weights();
    let dt2 = dt * dt;
    let pn = pattern.free[n] as usize;

    for &e_n in t.incoming(pn) {
        let e_n = e_n as usize;
        let i = t.owner[e_n] as usize;
        // `c` of the node an edge of `i` ends at.
        let c = |e: usize| {
            if edges[e] as usize == i {
                g[e] - t.sum_g[i]
            } else {
                g[e]
            }
        };
        let c_n = c(e_n);
        let volume = model.volumes[i] * dt2;
        let mut piola = [Matrix3::zeros(); 3];
        for (a, p) in piola.iter_mut().enumerate().take(dim) {
            let mut df = Matrix3::zeros();
            df.set_row(a, &c_n.transpose());
            *p = model.material.first_piola_derivative(&states[i], &df) * volume;
        }
        // Hourglass: `beta_e = w~_e alpha_n(e)`, summed plainly and
        // against `X_e`, give `sum_e w~_e alpha_n alpha_m` for any `m`
        // in O(1).
        let kappa = model.hourglass * model.volumes[i] * dt2;
        let beta = |e: usize| {
            let own = if e == e_n { 1.0 } else { 0.0 } - if pn == i { 1.0 } else { 0.0 };
            t.pair_weight[e] * (own - c_n.dot(&t.rest_offset[e]))
        };
        let (beta_sum, beta_x) = if kappa > 0.0 {
            t.gradients
                .range(i)
                .fold((0.0, Vector::zeros()), |(s, x), e| {
                    let b = beta(e);
                    (s + b, x + t.rest_offset[e] * b)
                })
        } else {
            (0.0, Vector::zeros())
        };
        for e_m in t.gradients.range(i) {
            let m = edges[e_m] as usize;
            let Some(slot) = out.slot(pattern.index[m]) else {
                // Anchored, or above the diagonal.
                continue;
            };
            let c_m = c(e_m);
            for (a, p) in piola.iter().enumerate().take(dim) {
                let column = p * c_m;
                for b in 0..dim {
                    out.add(slot, a, b, column[b]);
                }
            }
            if kappa > 0.0 {
                let own = if m == i { beta_sum } else { 0.0 };
                let s = kappa * (beta(e_m) - own - c_m.dot(&beta_x));
                for a in 0..dim {
                    out.add(slot, a, a, s);
                }
            }
        }
    }

    // The diagonal block is the first: every other row is below it. The
    // dashpots add `c_e n n^T` there and subtract it at the pair's block.
    let mut diagonal = Matrix3::from_diagonal_element(body.masses[pn]) + contact[pn];
    if model.damping > 0.0 {
        let pairs = t
            .gradients
            .range(pn)
            .map(|e| (edges[e] as usize, body.masses[pn], e))
            .chain(t.incoming(pn).iter().map(|&e| {
                let i = t.owner[e as usize] as usize;
                (i, body.masses[i], e as usize)
            }));
        for (other, mass, e) in pairs {
            let along = body.positions[other] - body.positions[pn];
            let length2 = along.norm_squared();
            if other == pn || length2 == 0.0 {
                continue;
            }
            let c = along
                * along.transpose()
                * (dt * model.damping * mass * t.pair_weight[e] / length2);
            diagonal += c;
            if let Some(slot) = out.slot(pattern.index[other]) {
                for a in 0..dim {
                    for b in 0..dim {
                        out.sub(slot, a, b, c[(a, b)]);
                    }
                }
            }
        }
    }
    for a in 0..dim {
        for b in 0..dim {
            out.add(0, a, b, diagonal[(a, b)]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::approx::mls::Order;
    use crate::geometry::Shape;
    use crate::solid::forces::InternalForces;
    use crate::solid::integrate::implicit::hessian_product;
    use crate::solid::{Integrator, Material, Obstacles, SolidParams};

    /// A deterministic pseudo-random number in [-1, 1).
    fn noise(seed: &mut u64) -> Real {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*seed >> 11) as Real / (1u64 << 52) as Real - 1.0
    }

    /// A bent, damped block with volume and hourglass terms and its left
    /// end anchored, and the stress states there.
    fn bent(dim: usize) -> (Body, Vec<StressState>) {
        let spacing = 0.1;
        let young = 1e5;
        let p = SolidParams {
            dim,
            spacing,
            density: 1000.0,
            young,
            material: Material::from_young_poisson(young, 0.3, 3e4),
            order: Order::Linear,
            support: 2.0 * spacing,
            hourglass: 0.5,
            damping: 5.0,
            friction: 0.0,
            integrator: Integrator::Explicit { cfl: 0.5 },
            plasticity: None,
            fracture: None,
        };
        let rest = Shape::Box {
            half_extents: Vector::new(0.4, 0.2, 0.2),
        }
        .sample_volume(spacing, dim)
        .expect("samples");
        let n = rest.len();
        let fixed = rest.iter().map(|x| x.x < -0.3).collect();
        let mut body = Body::new(
            p,
            rest,
            vec![Vector::zeros(); n],
            fixed,
            Obstacles::default(),
        )
        .expect("solid");
        let x = body
            .rest_positions()
            .iter()
            .map(|x| {
                Vector::new(
                    x.x + 0.1 * x.y * x.y,
                    x.y + 0.05 * x.x * x.y,
                    x.z + 0.08 * x.x * x.z,
                )
            })
            .collect();
        body.set_state(x, vec![Vector::zeros(); n])
            .expect("same length");
        // The stress states the Hessian linearises about.
        let mut forces = InternalForces::default();
        forces.evaluate(&body, None, None, false);
        (body, forces.states)
    }

    /// `H p` from the stored lower triangle, over the free particles.
    fn product(pattern: &Pattern, values: &[Real], p: &[Vector]) -> Vec<Vector> {
        let dim = pattern.blocks.dim();
        let x: Vec<Real> = pattern
            .free
            .iter()
            .flat_map(|&k| p[k as usize].iter().take(dim).copied().collect::<Vec<_>>())
            .collect();
        let y = pattern.blocks.product(values, &x);
        let mut out = vec![Vector::zeros(); p.len()];
        for (chunk, &k) in y.chunks_exact(dim).zip(&pattern.free) {
            for (o, v) in out[k as usize].iter_mut().zip(chunk) {
                *o = *v;
            }
        }
        out
    }

    fn relative_difference(a: &[Vector], b: &[Vector], dim: usize) -> Real {
        let diff: Real = a
            .iter()
            .zip(b)
            .map(|(a, b)| (a - b).rows(0, dim).norm_squared())
            .sum();
        let scale: Real = b.iter().map(|b| b.rows(0, dim).norm_squared()).sum();
        (diff / scale).sqrt()
    }

    #[test]
    fn assembled_hessian_matches_the_matrix_free_product_and_solves() {
        for dim in [2, 3] {
            let (body, states) = bent(dim);
            // Long enough that stiffness outweighs mass in `H`.
            let dt = 0.05;
            let pattern = Pattern::build(&body).expect("pattern");
            // Every third particle touches a floor (and, in 3D, a side
            // wall), with a contact stiffness of a few masses.
            let contact: Vec<Matrix3<Real>> = (0..body.len())
                .map(|k| match (k % 3, dim) {
                    (0, 2) => Matrix3::from_diagonal(&Vector::new(0.0, 3.0, 0.0)) * body.masses[k],
                    (0, _) => Matrix3::from_diagonal(&Vector::new(2.0, 3.0, 0.0)) * body.masses[k],
                    _ => Matrix3::zeros(),
                })
                .collect();
            let mut values = Vec::new();
            pattern.blocks.assemble(&mut values, |n, out| {
                assemble_column(&body, &states, &contact, dt, &pattern, n, out);
            });
            let mut seed = 7;
            let p: Vec<Vector> = (0..body.len())
                .map(|k| {
                    let mut v = Vector::new(noise(&mut seed), noise(&mut seed), noise(&mut seed));
                    if dim == 2 {
                        v.z = 0.0;
                    }
                    if body.fixed[k] { Vector::zeros() } else { v }
                })
                .collect();
            let assembled = product(&pattern, &values, &p);
            let matrix_free = hessian_product(&body, &states, &contact, dt, &p);
            let error = relative_difference(&assembled, &matrix_free, dim);
            assert!(error < 1e-8, "{dim}D: H p differs by {error:e}");

            // The solve inverts the matrix-free operator.
            let mut solver = Direct::default();
            let rhs: Vec<Vector> = matrix_free.iter().map(|v| -v).collect();
            let mut direction = vec![Vector::zeros(); body.len()];
            assert!(solver.direction(&body, &states, &contact, dt, &rhs, &mut direction));
            let error = relative_difference(&direction, &p, dim);
            assert!(error < 1e-8, "{dim}D: solution differs by {error:e}");
            assert!(solver.factor_bytes() > 0);
        }
    }
}
