//! Adaptive resampling of a fracturing solid (tutorial Section 7.3, Eq.
//! 71, after Pauly et al. 2005 and the particle splitting of Desbrun &
//! Cani 1999): particles the cracks left with too few neighbours are
//! split, so that the shape functions beside a crack keep enough samples.
//!
//! At the start of a step, before anything is saved or stepped (the
//! system seam's place for particle changes), each particle a crack cuts
//! a pair of is measured: `Q_i`, the transparency-weighted count of its
//! neighbours (Eq. 71), against `min(Q_min, N_i)`, `N_i` the neighbours
//! its support holds with no crack. Measured against its own uncut count
//! rather than `Q_min` alone, a particle on the body's surface, which
//! has fewer neighbours from the start, is not split for that: only what
//! the cracks took is put back, as the tutorial has resampling triggered
//! by the cracks passing through the solid.
//!
//! A particle short of neighbours by `Q` is split into itself and
//! `ceil(Q)` new particles rounded up to an even number, in opposite
//! pairs around it at half the new spacing, on its side of every crack
//! (directions turned until both of a pair are clear of the cracks). So
//! the parts' centre of mass is the parent's position, and with the
//! parent's velocity given to every part, linear and angular momentum
//! are kept to rounding. Volume and mass are shared evenly (the mass
//! total to rounding), and every part's support radius is the parent's
//! over `parts^(1/dim)`, which keeps the density (Pauly et al.), never
//! below `min_radius_ratio` times the solid's radius: the bound that
//! stops a particle by a crack from splitting without end. New particles
//! take the parent's deformation (placed through its deformation
//! gradient), plastic strain and fragment; anchored particles never
//! split. Splitting repeats within one step start while some particle
//! is short and may still split.
//!
//! The neighbourhoods are then built again with the particles' own radii
//! (`Topology::build_with_radii`): pairs between old particles keep the
//! terms the cracks gave them (weights only fall), new pairs get theirs
//! from the cracks as they are. A step start that splits costs a rebuild
//! of the solid; one that does not, one pass over the pairs' terms.

use super::body::Body;
use super::fracture::{
    Fracture, Resampling, SearchCache, lengthened, opacity, split, transparent_weight,
};
use super::topology::Topology;
use crate::approx::mls::{Mls, MlsParams};
use crate::math::{Real, Vector};
use nalgebra::Matrix3;

/// Splitting passes one step start makes at most: each pass can only
/// shrink radii, so the minimal radius ends it within a few.
const MAX_PASSES: usize = 8;

/// Turns of a split's directions tried to find pairs clear of the cracks.
const TURNS: usize = 8;

/// Why a resampling stopped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ResampleError {
    /// The solid would grow past the particles it was admitted with.
    #[error(
        "resampling would grow the solid to {count} particles, past its limit of {limit}; raise \
         fracture.resample.max_particles (within the host's particle limit), raise \
         min_radius_ratio or lower q_min"
    )]
    ParticleLimit {
        /// Particles it would hold.
        count: usize,
        /// The most it may hold.
        limit: usize,
    },
}

/// What one step start's resampling did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Resample {
    /// Particles split.
    pub split: u32,
    /// Particles added.
    pub added: u32,
}

/// One particle's split: the new particles' offsets from it, reference
/// frame.
struct Split {
    parent: usize,
    offsets: Vec<Vector>,
}

impl Body {
    /// Each particle's support radius, m, once resampling gave them radii
    /// of their own; `None` while all have the solid's.
    pub fn radii(&self) -> Option<&[Real]> {
        self.radii.as_deref()
    }

    /// The most particles the solid may hold: those it was built with,
    /// or what its resampling allows.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Particle `i`'s support radius, m.
    pub fn support_radius(&self, i: usize) -> Real {
        self.radii.as_ref().map_or(self.params.support, |r| r[i])
    }

    /// The explicit step limit. Once particles were split, the wave limit
    /// `cfl spacing / c_p` is shortened by the square root of how much
    /// stiffer the stiffest particle is than the stiffest of the solid as
    /// built (the largest `(1 / V_j) sum_i V_i |g_ij|^2`, with its own
    /// term, over particles `j`): a split particle's gradient weights
    /// grow as its radius shrinks, and one beside a crack, fitted over a
    /// lopsided neighbourhood, more (its moment matrix conditioned up to
    /// `max_refit_condition`), which a limit from the radius alone misses
    /// (found spinning a ductile bar: a split particle on its edge blew up
    /// within three sub-steps). A pass over the pairs a step, paid only by
    /// a solid that split.
    pub fn stable_dt(&self, cfl: Real) -> Real {
        let mut params = self.params;
        if self.radii.is_some() {
            let ratio = self.built_stiffness / self.stiffness();
            params.spacing *= ratio.sqrt().min(1.0);
        }
        params.stable_dt(cfl)
    }

    /// The largest `(1 / V_j) (sum_{i != j} V_i |g_ij|^2 + V_j |sum_k
    /// g_jk|^2)` over particles `j`, `g` the gradient weights: how the
    /// elastic stiffness a particle feels, per unit of its mass, grows
    /// with its gradient weights (the strain of each neighbour `i` reads
    /// `u_j` through `g_ij`, its own through their sum), 1/m^2.
    pub(super) fn stiffness(&self) -> Real {
        let t = &self.topology;
        let g = t.gradients.all_weights();
        (0..self.len())
            .map(|j| {
                let column: Real = t
                    .incoming(j)
                    .iter()
                    .map(|&e| e as usize)
                    .filter(|&e| t.owner[e] as usize != j)
                    .map(|e| self.volumes[t.owner[e] as usize] * g[e].norm_squared())
                    .sum();
                column / self.volumes[j] + t.sum_g[j].norm_squared()
            })
            .fold(0.0, Real::max)
    }

    /// Eq. 71's count `Q_i` and the uncut count `N_i` of every particle.
    pub fn sampling(&self) -> (Vec<Real>, Vec<Real>) {
        (0..self.len()).map(|i| self.sample(i)).unzip()
    }

    /// Eq. 71's count `Q_i` and the uncut count `N_i` of particle `i`.
    fn sample(&self, i: usize) -> (Real, Real) {
        let p = &self.params;
        let t = &self.topology;
        let kernel = MlsParams::new(p.order, p.support).weight;
        let inv_h = 1.0 / p.support;
        let extra = self.fracture.as_ref().map(|f| f.extra.as_slice());
        let edges = t.gradients.neighbour_indices();
        let mut count = 0.0;
        let mut q = 0.0;
        for e in t.gradients.range(i) {
            if edges[e] as usize == i {
                continue;
            }
            let qe = t.q(e, inv_h);
            if let Some(plain) = transparent_weight(kernel, qe, 0.0) {
                count += 1.0;
                let term = extra.map_or(0.0, |x| x[e]);
                q += transparent_weight(kernel, qe, term).unwrap_or(0.0) / plain;
            }
        }
        (q, count)
    }

    /// Splits the particles the cracks left short of neighbours (the
    /// module documentation); nothing for a solid that does not resample.
    ///
    /// # Errors
    /// [`ResampleError::ParticleLimit`] when a pass would grow the solid
    /// past [`Self::capacity`]; the body is then as it was before the
    /// first pass.
    pub(super) fn resample(&mut self) -> Result<Resample, ResampleError> {
        let Some(rule) = self.fracture.as_ref().and_then(|f| f.params.resample) else {
            return Ok(Resample::default());
        };
        let mut done = Resample::default();
        // Kept only once something splits, which rebuilds the solid anyway.
        let mut before: Option<Box<Body>> = None;
        for _ in 0..MAX_PASSES {
            let plan = self.plan(&rule);
            if plan.is_empty() {
                break;
            }
            let added: usize = plan.iter().map(|s| s.offsets.len()).sum();
            let count = self.len() + added;
            if count > self.capacity {
                if let Some(before) = before {
                    *self = *before;
                }
                return Err(ResampleError::ParticleLimit {
                    count,
                    limit: self.capacity,
                });
            }
            before.get_or_insert_with(|| Box::new(self.clone()));
            self.split_particles(&plan);
            done.split += plan.len() as u32;
            done.added += added as u32;
        }
        Ok(done)
    }

    /// The particles to split and where their new particles go.
    fn plan(&self, rule: &Resampling) -> Vec<Split> {
        let Some(fracture) = self.fracture.as_ref() else {
            return Vec::new();
        };
        let dim = self.params.dim;
        let smallest = rule.min_radius_ratio * self.params.support;
        let t = &self.topology;
        // Only a particle a crack cut a pair of can have lost neighbours.
        let touched: Vec<usize> = (0..self.len())
            .filter(|&i| !self.fixed[i] && t.gradients.range(i).any(|e| fracture.extra[e] > 0.0))
            .collect();
        if touched.is_empty() {
            return Vec::new();
        }
        let mut plan = Vec::new();
        for i in touched {
            let (q, count) = self.sample(i);
            let target = rule.q_min.min(count);
            if q >= target {
                continue;
            }
            let radius = self.support_radius(i);
            // Parts whose radius stays at or above the smallest, as an
            // even number of new particles besides the parent.
            let parts = (radius / smallest).powi(dim as i32) * (1.0 + 1e-12);
            let room = ((parts.floor() as usize).saturating_sub(1) / 2) * 2;
            let wanted = ((target - q).ceil() as usize).div_ceil(2) * 2;
            let children = wanted.min(room).min(Resampling::MAX_PARTS - 1);
            if children < 2 {
                continue;
            }
            let offsets = self.place(i, children, radius, fracture);
            if !offsets.is_empty() {
                plan.push(Split { parent: i, offsets });
            }
        }
        plan
    }

    /// Offsets of `children` (even) new particles around particle `i` of
    /// support `radius`, in opposite pairs at half the new spacing, both
    /// of a pair on `i`'s side of every crack: the first turn of the
    /// directions that clears them all, or the most pairs any turn clears;
    /// where no turn clears a pair, the same at a half and a quarter of
    /// that distance (a crack next to the particle). Empty where a crack
    /// runs through it.
    fn place(&self, i: usize, children: usize, radius: Real, fracture: &Fracture) -> Vec<Vector> {
        let p = &self.params;
        let parts = (children + 1) as Real;
        let spacing = p.spacing * radius / p.support;
        let distance = 0.5 * spacing / parts.powf(1.0 / p.dim as Real);
        let x = self.rest[i];
        let clear = |d: &Vector| {
            fracture
                .cracks
                .iter()
                .all(|c| c.crossing(&x, &(x + d)).is_none())
        };
        let mut best = Vec::new();
        for scale in [1.0, 0.5, 0.25] {
            for turn in 0..TURNS {
                let found: Vec<Vector> = directions(p.dim, children / 2, turn)
                    .map(|u| u * (distance * scale))
                    .filter(|d| clear(d) && clear(&-d))
                    .flat_map(|d| [d, -d])
                    .collect();
                if found.len() > best.len() {
                    best = found;
                    if best.len() == children {
                        return best;
                    }
                }
            }
            if !best.is_empty() {
                break;
            }
        }
        best
    }

    /// Applies one pass's splits: the new particles appended (their ids
    /// follow the solid's), then the neighbourhoods built again with the
    /// particles' radii and the fragments the smaller radii parted split.
    fn split_particles(&mut self, plan: &[Split]) {
        let p = self.params;
        let dim = p.dim;
        let n = self.len();
        let Some(mut fracture) = self.fracture.take() else {
            return;
        };
        let old = std::mem::take(&mut self.topology);
        let displacement: Vec<Vector> = self
            .positions
            .iter()
            .zip(&self.rest)
            .map(|(x, r)| x - r)
            .collect();
        let mut radii = self.radii.take().unwrap_or_else(|| vec![p.support; n]);
        for s in plan {
            let i = s.parent;
            let parts = (s.offsets.len() + 1) as Real;
            let f = Matrix3::identity() + old.gradients.vector_gradient(i, &displacement);
            radii[i] /= parts.powf(1.0 / dim as Real);
            self.volumes[i] /= parts;
            self.masses[i] = self.volumes[i] * p.density;
            for d in &s.offsets {
                self.rest.push(self.rest[i] + d);
                self.positions.push(self.positions[i] + f * d);
                self.velocities.push(self.velocities[i]);
                self.volumes.push(self.volumes[i]);
                self.masses.push(self.masses[i]);
                self.fixed.push(false);
                radii.push(radii[i]);
                fracture.fragments.push(fracture.fragments[i]);
                if let Some(plastic) = &mut self.plastic {
                    plastic.push(plastic[i]);
                }
            }
        }

        let kernel = MlsParams::new(p.order, p.support).weight;
        let inv_h = 1.0 / p.support;
        let old_edges = old.gradients.neighbour_indices();
        // The pairs a parent had: a smaller radius can part them.
        let mut parted: Vec<(usize, usize)> = plan
            .iter()
            .flat_map(|s| {
                old.gradients
                    .range(s.parent)
                    .filter(|&e| {
                        old_edges[e] as usize != s.parent
                            && transparent_weight(kernel, old.q(e, inv_h), fracture.extra[e])
                                .is_some()
                    })
                    .map(|e| {
                        let j = old_edges[e] as usize;
                        (s.parent.min(j), s.parent.max(j))
                    })
            })
            .collect();
        parted.sort_unstable();
        parted.dedup();

        let rest = &self.rest;
        let discontinuity = fracture.params.discontinuity;
        let spacing = p.spacing;
        let old_extra = &fracture.extra;
        let cracks = &fracture.cracks;
        let term = |a: usize, b: usize| -> Real {
            if a < n
                && b < n
                && let Some(e) = old.gradients.range(a).find(|&e| old_edges[e] as usize == b)
            {
                return old_extra[e];
            }
            // One direction for both edges of the pair, as `recut` has it.
            let (x, y) = if a < b {
                (rest[a], rest[b])
            } else {
                (rest[b], rest[a])
            };
            cracks
                .iter()
                .filter_map(|c| c.crossing(&x, &y))
                .map(|c| opacity(discontinuity, c.to_front, spacing))
                .sum()
        };
        let mls = Mls::new(dim, MlsParams::new(p.order, p.support))
            .expect("the solid's MLS parameters were valid when it was built");
        let (topology, extra) = Topology::build_with_radii(
            rest,
            &radii,
            (dim, p.order, p.support),
            term,
            lengthened(&mls),
        )
        .expect("the solid's MLS parameters were valid when it was built");
        self.topology = topology;
        fracture.extra = extra;
        fracture.search = SearchCache::default();
        self.radii = Some(radii);

        let edges = self.topology.gradients.neighbour_indices();
        let joined = |a: usize, b: usize| {
            self.topology.gradients.range(a).any(|e| {
                edges[e] as usize == b
                    && transparent_weight(kernel, self.topology.q(e, inv_h), fracture.extra[e])
                        .is_some()
            })
        };
        let parted: Vec<(usize, usize)> =
            parted.into_iter().filter(|&(a, b)| !joined(a, b)).collect();
        for (a, b) in parted {
            split(
                a,
                b,
                |i| self.connected_neighbours(i, &fracture.extra),
                &mut fracture.fragments,
                &mut fracture.fragment_count,
            );
        }
        self.fracture = Some(fracture);
    }
}

/// `pairs` unit directions, no two opposite, turned by `turn` of
/// [`TURNS`]: in 2D spread over half a circle, in 3D over a half sphere
/// (a Fibonacci spiral), so that with their opposites they surround the
/// parent evenly.
fn directions(dim: usize, pairs: usize, turn: usize) -> impl Iterator<Item = Vector> {
    use std::f64::consts::PI;
    let golden = PI * (3.0 - (5.0 as Real).sqrt());
    let offset = turn as Real / TURNS as Real;
    (0..pairs).map(move |m| {
        if dim == 2 {
            let angle = PI * (m as Real + offset) / pairs as Real;
            Vector::new(angle.cos(), angle.sin(), 0.0)
        } else {
            let z = 1.0 - (m as Real + 0.5) / pairs as Real;
            let rho = (1.0 - z * z).sqrt();
            let phi = m as Real * golden + 2.0 * PI * offset;
            Vector::new(rho * phi.cos(), rho * phi.sin(), z)
        }
    })
}

#[cfg(test)]
mod tests;
