//! Elastic, hourglass and damping forces as exact derivatives of one
//! energy, evaluated in three parallel passes without locks:
//!
//! 1. **per particle** `i`: `F_i = I + sum_j (u_j - u_i) g_ij^T` (Eq. 37
//!    in material coordinates), the stress state, and `T_i = dU_i/dF_i`;
//! 2. **per edge** `e = (i -> j)`: the pairwise forces;
//! 3. **per particle** `k`, gathering: `f_k = -dU/dx_k`.
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
//! **Damping** is pairwise, `c_e (v_j - v_i)` with `c_e = alpha m_i
//! w~_ij`, equal and opposite on the pair: it damps relative motion only,
//! so a falling or spinning body is not slowed.

use super::elastic::ElasticSolid;
use super::material::{Material, StressState};
use super::topology::Topology;
use crate::math::{Real, Vector};
use nalgebra::Matrix3;
use rayon::prelude::*;

/// Particles per parallel work item.
const CHUNK: usize = 512;

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
}

impl Model<'_> {
    /// `F_i` at positions `x`.
    fn deformation_gradient(&self, i: usize, x: &[Vector]) -> Matrix3<Real> {
        let t = self.topology;
        let edges = t.gradients.neighbour_indices();
        let g = t.gradients.all_weights();
        let mut f = Matrix3::identity();
        for e in t.gradients.range(i) {
            let j = edges[e] as usize;
            let du = x[j] - x[i] - t.rest_offset[e];
            f += du * g[e].transpose();
        }
        f
    }

    /// `x_j - x_i - F_i X_ij` of edge `e` (the hourglass error).
    fn edge_error(&self, e: usize, x: &[Vector], f: &Matrix3<Real>) -> Vector {
        let t = self.topology;
        let i = t.owner[e] as usize;
        let j = t.gradients.neighbour_indices()[e] as usize;
        x[j] - x[i] - f * t.rest_offset[e]
    }

    /// Pass 1: the stress state and `T_i` of every particle at `x`;
    /// returns the total potential energy (elastic, volume, hourglass).
    pub fn stress_pass(
        &self,
        x: &[Vector],
        states: &mut [StressState],
        stress: &mut [Matrix3<Real>],
    ) -> Real {
        states
            .par_chunks_mut(CHUNK)
            .zip(stress.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(c, (states, stress))| {
                let mut energy = 0.0;
                for (k, (state, t_i)) in states.iter_mut().zip(stress.iter_mut()).enumerate() {
                    let i = c * CHUNK + k;
                    let f = self.deformation_gradient(i, x);
                    *state = self.material.state(f, self.plastic.map(|p| &p[i]));
                    let v = self.volumes[i];
                    energy += v * self.material.energy_density(state);
                    *t_i = self.material.first_piola(state) * v;
                    if self.hourglass > 0.0 {
                        let kappa = self.hourglass * v;
                        let mut g_h = Matrix3::zeros();
                        for e in self.topology.gradients.range(i) {
                            let w = self.topology.pair_weight[e];
                            let err = self.edge_error(e, x, &f);
                            energy += 0.5 * kappa * w * err.norm_squared();
                            g_h -= err * self.topology.rest_offset[e].transpose() * (kappa * w);
                        }
                        *t_i += g_h;
                    }
                }
                energy
            })
            .sum()
    }

    /// Pass 2: the pairwise force of every edge on its owner: hourglass
    /// at `x` with the gradients of `states`, plus damping when velocities
    /// `v` are given.
    pub fn edge_pass(
        &self,
        x: &[Vector],
        states: &[StressState],
        v: Option<&[Vector]>,
        edge: &mut [Vector],
    ) {
        let t = self.topology;
        let edges = t.gradients.neighbour_indices();
        let damped = v.filter(|_| self.damping > 0.0);
        edge.par_iter_mut().enumerate().for_each(|(e, out)| {
            let i = t.owner[e] as usize;
            let w = t.pair_weight[e];
            let mut force = Vector::zeros();
            if self.hourglass > 0.0 {
                force += self.edge_error(e, x, &states[i].f) * (self.hourglass * self.volumes[i] * w);
            }
            if let Some(v) = damped {
                force += (v[edges[e] as usize] - v[i]) * (self.damping * self.masses[i] * w);
            }
            *out = force;
        });
    }

    /// The damping force `f_d(v) = -D v` of velocities `v` on every
    /// particle, using `edge` as scratch.
    pub fn damping_forces(&self, v: &[Vector], edge: &mut [Vector], out: &mut [Vector]) {
        let t = self.topology;
        let edges = t.gradients.neighbour_indices();
        edge.par_iter_mut().enumerate().for_each(|(e, out)| {
            let i = t.owner[e] as usize;
            *out = (v[edges[e] as usize] - v[i]) * (self.damping * self.masses[i] * t.pair_weight[e]);
        });
        out.par_iter_mut().enumerate().for_each(|(k, f)| {
            let mut sum = Vector::zeros();
            for e in t.gradients.range(k) {
                sum += edge[e];
            }
            for &e in t.incoming(k) {
                sum -= edge[e as usize];
            }
            *f = sum;
        });
    }

    /// Pass 3: `f_k = T_k s_k - sum_(i->k) T_i g_ik + sum_(k->j) h_kj -
    /// sum_(i->k) h_ik` for every particle.
    pub fn gather(&self, stress: &[Matrix3<Real>], edge: &[Vector], out: &mut [Vector]) {
        let t = self.topology;
        let g = t.gradients.all_weights();
        out.par_iter_mut().enumerate().for_each(|(k, f)| {
            let mut sum = stress[k] * t.sum_g[k];
            for e in t.gradients.range(k) {
                sum += edge[e];
            }
            for &e in t.incoming(k) {
                let e = e as usize;
                sum -= stress[t.owner[e] as usize] * g[e] + edge[e];
            }
            *f = sum;
        });
    }

    /// Pass 1 linearised: `dT_i` along displacements `w` about `states`
    /// (which hold `F_i` at the linearisation point); `df` receives `dF_i`.
    pub fn stress_derivative_pass(
        &self,
        w: &[Vector],
        states: &[StressState],
        df: &mut [Matrix3<Real>],
        dstress: &mut [Matrix3<Real>],
    ) {
        df.par_iter_mut()
            .zip(dstress.par_iter_mut())
            .enumerate()
            .for_each(|(i, (df, dt))| {
                let t = self.topology;
                let edges = t.gradients.neighbour_indices();
                let g = t.gradients.all_weights();
                let mut d = Matrix3::zeros();
                for e in t.gradients.range(i) {
                    d += (w[edges[e] as usize] - w[i]) * g[e].transpose();
                }
                *df = d;
                let v = self.volumes[i];
                *dt = self.material.first_piola_derivative(&states[i], &d) * v;
                if self.hourglass > 0.0 {
                    let kappa = self.hourglass * v;
                    for e in t.gradients.range(i) {
                        let derr = w[edges[e] as usize] - w[i] - d * t.rest_offset[e];
                        *dt -= derr * t.rest_offset[e].transpose() * (kappa * t.pair_weight[e]);
                    }
                }
            });
    }

    /// Pass 2 linearised (hourglass only; damping is not a function of
    /// position).
    pub fn edge_derivative_pass(&self, w: &[Vector], df: &[Matrix3<Real>], edge: &mut [Vector]) {
        let t = self.topology;
        let edges = t.gradients.neighbour_indices();
        edge.par_iter_mut().enumerate().for_each(|(e, out)| {
            *out = if self.hourglass > 0.0 {
                let i = t.owner[e] as usize;
                let derr = w[edges[e] as usize] - w[i] - df[i] * t.rest_offset[e];
                derr * (self.hourglass * self.volumes[i] * t.pair_weight[e])
            } else {
                Vector::zeros()
            };
        });
    }

    /// Damping power `sum_e c_e |v_j - v_i|^2 / 2` (the Rayleigh
    /// dissipation function), W.
    pub fn dissipation(&self, v: &[Vector]) -> Real {
        if self.damping == 0.0 {
            return 0.0;
        }
        let t = self.topology;
        let edges = t.gradients.neighbour_indices();
        (0..edges.len())
            .into_par_iter()
            .map(|e| {
                let i = t.owner[e] as usize;
                let dv = v[edges[e] as usize] - v[i];
                0.5 * self.damping * self.masses[i] * t.pair_weight[e] * dv.norm_squared()
            })
            .sum()
    }
}

impl ElasticSolid {
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
        }
    }

    /// Recomputes the stress states at the current positions (or at
    /// `at`); returns the potential energy.
    pub(super) fn evaluate_stress(&mut self, at: Option<&[Vector]>) -> Real {
        let n = self.len();
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.states.resize(n, Material::rest_state());
        scratch.stress.resize(n, Matrix3::zeros());
        scratch.forces.resize(n, Vector::zeros());
        scratch.edge.resize(self.topology.owner.len(), Vector::zeros());
        let x = at.unwrap_or(&self.positions);
        let energy = self
            .model()
            .stress_pass(x, &mut scratch.states, &mut scratch.stress);
        self.scratch = scratch;
        energy
    }

    /// Internal (elastic, hourglass, damping) forces at the current
    /// positions and velocities, into `scratch.forces`; expects the stress
    /// states to be current.
    pub(super) fn internal_forces(&mut self, x: Option<&[Vector]>, v: Option<&[Vector]>) {
        let mut scratch = std::mem::take(&mut self.scratch);
        let model = self.model();
        let x = x.unwrap_or(&self.positions);
        model.edge_pass(x, &scratch.states, v, &mut scratch.edge);
        model.gather(&scratch.stress, &scratch.edge, &mut scratch.forces);
        self.scratch = scratch;
    }

    /// Potential energy at the current positions (elastic, volume and
    /// hourglass), J.
    pub fn potential_energy(&self) -> Real {
        let n = self.len();
        let mut states = vec![Material::rest_state(); n];
        let mut stress = vec![Matrix3::zeros(); n];
        self.model().stress_pass(&self.positions, &mut states, &mut stress)
    }

    /// The internal force on every particle at the current state (for
    /// tests and diagnostics; the integrators use the scratch buffers).
    pub fn forces(&self) -> Vec<Vector> {
        let n = self.len();
        let model = self.model();
        let mut states = vec![Material::rest_state(); n];
        let mut stress = vec![Matrix3::zeros(); n];
        let mut edge = vec![Vector::zeros(); self.topology.owner.len()];
        let mut out = vec![Vector::zeros(); n];
        model.stress_pass(&self.positions, &mut states, &mut stress);
        model.edge_pass(&self.positions, &states, Some(&self.velocities), &mut edge);
        model.gather(&stress, &edge, &mut out);
        out
    }
}
