//! Elastic, hourglass and damping forces as exact derivatives of one
//! energy, evaluated in three parallel passes without locks:
//!
//! 1. **per particle** `i`, over its own (contiguous) edges: `F_i = I +
//!    sum_j (u_j - u_i) g_ij^T` (Eq. 37 in material coordinates), the
//!    stress state, `T_i = dU_i/dF_i`, and for every edge `e = (i -> j)`
//!    the force `-c_e` that `i`'s energy puts on `j`, and the sum of the
//!    reactions on `i` itself;
//! 2. **per particle** `k`, gathering: `f_k = own_k - sum_(i->k) c_e`.
//!
//! All the arithmetic is in pass 1, which reads memory in order; pass 2
//! reads one vector per incoming edge.
//!
//! With `U_i = V_i (W + W_vol)(F_i)` and `dF_i/dx_j = e_a (x) g_ij`, the
//! elastic force on `j` from `i` is `-V_i P_i g_ij` and on `i` itself
//! `V_i P_i sum_j g_ij`: Eq. 63-65 differentiated through the MLS
//! gradient, so linear and angular momentum are conserved and a rigid
//! motion (where `P = 0`) gives no force.
//!
//! **Hourglass term.** Nodal integration of a gradient that each particle
//! takes from its own neighbourhood leaves zero-energy modes: a lattice
//! checkerboard has `grad u = 0` everywhere. After Ganzenmüller (2015),
//! each particle also pays for how far its neighbours stray from its own
//! affine map,
//!
//! ```text
//! U_h,i = kappa_i / 2 sum_j w~_ij |x_j - x_i - F_i X_ij|^2,
//! kappa_i = c_h E V_i / h^2,   w~_ij = w_ij / sum_k w_ik,
//! ```
//!
//! which is zero for any affine motion (so still no force under rotation)
//! and whose error vanishes as `h^2` under refinement. Its dependence on
//! `F_i` is kept (`dU_h/dF_i` adds to `T_i`), so the forces stay
//! conservative for any basis order.
//!
//! **Damping** is a dashpot along each pair, `c_e n_e n_e^T (v_j - v_i)`
//! with `c_e = alpha m_i w~_ij` and `n_e` the pair's direction at the
//! start of the step, equal and opposite on the pair and along it: it
//! damps only the rate at which pairs stretch, which every deformation
//! changes and no rigid motion does, so a falling or spinning body is not
//! slowed and angular momentum is conserved. (Damping the whole relative
//! velocity `v_j - v_i`, as this did before, also damps rotation, whose
//! relative velocities are `omega x (x_j - x_i)`: a free block with
//! `damping = 5` lost 34 % of its angular momentum in 2 s without
//! deforming; engine/tests/solids.rs.) With `n_e` fixed over
//! a step the damping force stays linear in `v`, `-D v` with `D`
//! symmetric, as the implicit integrator's objective needs.

use super::body::Body;
use super::material::{Material, StressState};
use super::topology::Topology;
use crate::linalg::linop::par_sum;
use crate::math::{Real, Vector};
use nalgebra::Matrix3;
use rayon::prelude::*;

/// Particles per parallel work item.
const CHUNK: usize = 256;

/// What the passes read: the fixed parts of a solid.
#[derive(Clone, Copy)]
pub(super) struct Model<'a> {
    pub topology: &'a Topology,
    pub material: Material,
    pub volumes: &'a [Real],
    pub masses: &'a [Real],
    pub plastic: Option<&'a [Matrix3<Real>]>,
    /// `c_h E / h^2`, multiplied by `V_i` per particle.
    pub hourglass: Real,
    pub damping: Real,
    /// Positions at the start of the step, which set the dashpots'
    /// directions.
    pub positions: &'a [Vector],
}

/// The output of pass 1: per particle the force it puts on itself, per
/// edge the force its owner puts on the other end (negated).
#[derive(Debug, Clone, Default)]
pub(super) struct Split {
    pub own: Vec<Vector>,
    pub edge: Vec<Vector>,
}

impl Split {
    pub fn resize(&mut self, particles: usize, edges: usize) {
        self.own.resize(particles, Vector::zeros());
        self.edge.resize(edges, Vector::zeros());
    }

    /// Splits into one work item per chunk of particles, each with the
    /// edges those particles own.
    fn chunks<'s>(
        &'s mut self,
        topology: &Topology,
    ) -> Vec<(usize, &'s mut [Vector], &'s mut [Vector])> {
        let mut items = Vec::new();
        let mut edges = self.edge.as_mut_slice();
        for (c, own) in self.own.chunks_mut(CHUNK).enumerate() {
            let first = c * CHUNK;
            let lo = topology.gradients.range(first).start;
            let hi = topology.gradients.range(first + own.len() - 1).end;
            let (mine, rest) = edges.split_at_mut(hi - lo);
            edges = rest;
            items.push((first, own, mine));
        }
        items
    }
}

impl Model<'_> {
    /// `F_i` at positions `x` (or `dF_i` along displacements `x` when
    /// `identity` is 0).
    fn gradient_of(&self, i: usize, x: &[Vector], rest: Real) -> Matrix3<Real> {
        let t = self.topology;
        let edges = t.gradients.neighbour_indices();
        let g = t.gradients.all_weights();
        let mut f = Matrix3::identity() * rest;
        for e in t.gradients.range(i) {
            let j = edges[e] as usize;
            let du = x[j] - x[i] - t.rest_offset[e] * rest;
            f += du * g[e].transpose();
        }
        f
    }

    /// Pass 1 at positions `x` (and velocities `v`, for damping): stress
    /// states into `states` and the split forces into `split`. Returns the
    /// potential energy (elastic, volume, hourglass) when `energy` is
    /// asked for, else 0.
    pub fn particle_pass(
        &self,
        x: &[Vector],
        v: Option<&[Vector]>,
        states: &mut [StressState],
        split: &mut Split,
        energy: bool,
    ) -> Real {
        let t = self.topology;
        let edges = t.gradients.neighbour_indices();
        let g = t.gradients.all_weights();
        let damped = v.filter(|_| self.damping > 0.0);
        split
            .chunks(t)
            .into_par_iter()
            .zip(states.par_chunks_mut(CHUNK))
            .map(|((first, own, edge), states)| {
                let base = t.gradients.range(first).start;
                let mut total = 0.0;
                for (k, (own, state)) in own.iter_mut().zip(states.iter_mut()).enumerate() {
                    let i = first + k;
                    let range = t.gradients.range(i);
                    let f = self.gradient_of(i, x, 1.0);
                    *state = self.material.state(f, self.plastic.map(|p| &p[i]));
                    let volume = self.volumes[i];
                    if energy {
                        total += volume * self.material.energy_density(state);
                    }
                    let mut stress = self.material.first_piola(state) * volume;
                    // Pairwise terms first: the hourglass's dU/dF joins T_i.
                    let kappa = self.hourglass * volume;
                    let mut pair_sum = Vector::zeros();
                    for e in range.clone() {
                        let j = edges[e] as usize;
                        let w = t.pair_weight[e];
                        let mut c = Vector::zeros();
                        if kappa > 0.0 {
                            let err = x[j] - x[i] - f * t.rest_offset[e];
                            if energy {
                                total += 0.5 * kappa * w * err.norm_squared();
                            }
                            stress -= err * t.rest_offset[e].transpose() * (kappa * w);
                            c += err * (kappa * w);
                        }
                        if let Some(v) = damped {
                            c += self.dashpot(i, j, e, v);
                        }
                        pair_sum += c;
                        edge[e - base] = c;
                    }
                    for e in range {
                        edge[e - base] += stress * g[e];
                    }
                    *own = stress * t.sum_g[i] + pair_sum;
                }
                total
            })
            .sum()
    }

    /// Pass 1 linearised: the split of `K w`, the directional derivative
    /// of the (non-damping) forces along displacements `w`, about the
    /// stress states `states`.
    pub fn derivative_pass(&self, w: &[Vector], states: &[StressState], split: &mut Split) {
        let t = self.topology;
        let edges = t.gradients.neighbour_indices();
        let g = t.gradients.all_weights();
        split
            .chunks(t)
            .into_par_iter()
            .for_each(|(first, own, edge)| {
                let base = t.gradients.range(first).start;
                for (k, own) in own.iter_mut().enumerate() {
                    let i = first + k;
                    let range = t.gradients.range(i);
                    let df = self.gradient_of(i, w, 0.0);
                    let volume = self.volumes[i];
                    let mut stress = self.material.first_piola_derivative(&states[i], &df) * volume;
                    let kappa = self.hourglass * volume;
                    let mut pair_sum = Vector::zeros();
                    for e in range.clone() {
                        let mut c = Vector::zeros();
                        if kappa > 0.0 {
                            let w_e = t.pair_weight[e];
                            let derr = w[edges[e] as usize] - w[i] - df * t.rest_offset[e];
                            stress -= derr * t.rest_offset[e].transpose() * (kappa * w_e);
                            c = derr * (kappa * w_e);
                        }
                        pair_sum += c;
                        edge[e - base] = c;
                    }
                    for e in range {
                        edge[e - base] += stress * g[e];
                    }
                    *own = stress * t.sum_g[i] + pair_sum;
                }
            });
    }

    /// The dashpot force `c_e n_e n_e^T (v_j - v_i)` of edge `e = (i -> j)`.
    #[inline]
    fn dashpot(&self, i: usize, j: usize, e: usize, v: &[Vector]) -> Vector {
        let along = self.positions[j] - self.positions[i];
        let length2 = along.norm_squared();
        if length2 == 0.0 {
            return Vector::zeros();
        }
        let c = self.damping * self.masses[i] * self.topology.pair_weight[e];
        along * (c * (v[j] - v[i]).dot(&along) / length2)
    }

    /// The split of the damping force `f_d(v) = -D v`.
    pub fn damping_pass(&self, v: &[Vector], split: &mut Split) {
        let t = self.topology;
        let edges = t.gradients.neighbour_indices();
        split
            .chunks(t)
            .into_par_iter()
            .for_each(|(first, own, edge)| {
                let base = t.gradients.range(first).start;
                for (k, own) in own.iter_mut().enumerate() {
                    let i = first + k;
                    let mut sum = Vector::zeros();
                    for e in t.gradients.range(i) {
                        let c = self.dashpot(i, edges[e] as usize, e, v);
                        edge[e - base] = c;
                        sum += c;
                    }
                    *own = sum;
                }
            });
    }

    /// Pass 2: `f_k = own_k - sum_(i->k) c_e`.
    pub fn gather(&self, split: &Split, out: &mut [Vector]) {
        let t = self.topology;
        out.par_iter_mut().enumerate().for_each(|(k, f)| {
            let mut sum = split.own[k];
            for &e in t.incoming(k) {
                sum -= split.edge[e as usize];
            }
            *f = sum;
        });
    }

    /// Stress states at `x` alone (for frames and diagnostics).
    pub fn states(&self, x: &[Vector], out: &mut [StressState]) {
        out.par_iter_mut().enumerate().for_each(|(i, state)| {
            let f = self.gradient_of(i, x, 1.0);
            *state = self.material.state(f, self.plastic.map(|p| &p[i]));
        });
    }

    /// Potential energy (elastic, volume, hourglass) at positions `x`,
    /// particle by particle with no buffers: the energy watch reads it
    /// every step, and a pass that kept states and split forces for it
    /// raised a 27k-particle solid's peak memory by 9 MB.
    pub fn energy(&self, x: &[Vector]) -> Real {
        par_sum(x.len(), |i| self.particle_energy(i, x))
    }

    /// Particle `i`'s share of [`Self::energy`]: its own strain, volume
    /// and hourglass terms, which read only its own gradient and pair
    /// weights (so a crack that reweighs some particles changes the
    /// energy by exactly their shares' change).
    pub fn particle_energy(&self, i: usize, x: &[Vector]) -> Real {
        let t = self.topology;
        let edges = t.gradients.neighbour_indices();
        let f = self.gradient_of(i, x, 1.0);
        let state = self.material.state(f, self.plastic.map(|p| &p[i]));
        let volume = self.volumes[i];
        let kappa = self.hourglass * volume;
        let mut total = volume * self.material.energy_density(&state);
        if kappa > 0.0 {
            for e in t.gradients.range(i) {
                let err = x[edges[e] as usize] - x[i] - f * t.rest_offset[e];
                total += 0.5 * kappa * t.pair_weight[e] * err.norm_squared();
            }
        }
        total
    }

    /// Damping power `sum_e c_e (n_e . (v_j - v_i))^2 / 2` (the Rayleigh
    /// dissipation function), W.
    pub fn dissipation(&self, v: &[Vector]) -> Real {
        if self.damping == 0.0 {
            return 0.0;
        }
        let t = self.topology;
        let edges = t.gradients.neighbour_indices();
        par_sum(edges.len(), |e| {
            let (i, j) = (t.owner[e] as usize, edges[e] as usize);
            0.5 * self.dashpot(i, j, e, v).dot(&(v[j] - v[i]))
        })
    }
}

/// The buffers of one evaluation of the internal forces, which every
/// integrator owns one of: the stress states there (which plasticity and
/// the blow-up check read after a step), the split of pass 1 and the
/// gathered forces.
#[derive(Debug, Clone, Default)]
pub(super) struct InternalForces {
    pub states: Vec<StressState>,
    pub split: Split,
    pub forces: Vec<Vector>,
}

impl InternalForces {
    /// Internal forces (elastic, hourglass, damping) of `body` at
    /// positions `x` (default: the current ones) and velocities `v` into
    /// `self.forces`, with the stress states there in `self.states`;
    /// returns the potential energy when `energy` is asked for.
    pub fn evaluate(
        &mut self,
        body: &Body,
        x: Option<&[Vector]>,
        v: Option<&[Vector]>,
        energy: bool,
    ) -> Real {
        let n = body.len();
        self.states.resize(n, Material::rest_state());
        self.forces.resize(n, Vector::zeros());
        self.split.resize(n, body.topology.owner.len());
        let model = body.model();
        let x = x.unwrap_or(&body.positions);
        let total = model.particle_pass(x, v, &mut self.states, &mut self.split, energy);
        model.gather(&self.split, &mut self.forces);
        total
    }
}

impl Body {
    /// The fixed parts the force passes read.
    pub(super) fn model(&self) -> Model<'_> {
        let p = &self.params;
        Model {
            topology: &self.topology,
            material: p.material,
            volumes: &self.volumes,
            masses: &self.masses,
            plastic: self.plastic.as_deref(),
            hourglass: p.hourglass * p.young / (p.support * p.support),
            damping: p.damping,
            positions: &self.positions,
        }
    }

    /// The stress state of every particle at the current positions.
    pub(super) fn current_states(&self) -> Vec<StressState> {
        let mut states = vec![Material::rest_state(); self.len()];
        self.model().states(&self.positions, &mut states);
        states
    }

    /// Potential energy at the current positions (elastic, volume and
    /// hourglass), J.
    pub fn potential_energy(&self) -> Real {
        self.model().energy(&self.positions)
    }

    /// The internal force on every particle at the current state (for
    /// tests and diagnostics; the integrators use their own buffers).
    pub fn forces(&self) -> Vec<Vector> {
        let n = self.len();
        let model = self.model();
        let mut states = vec![Material::rest_state(); n];
        let mut split = Split::default();
        split.resize(n, self.topology.owner.len());
        let mut out = vec![Vector::zeros(); n];
        model.particle_pass(
            &self.positions,
            Some(&self.velocities),
            &mut states,
            &mut split,
            false,
        );
        model.gather(&split, &mut out);
        out
    }
}
