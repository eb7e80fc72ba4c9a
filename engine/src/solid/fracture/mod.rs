//! Fracture of MLS solids (tutorial Section 7.3, after Pauly et al. 2005):
//! cracks that start where the material fails, run along the stress
//! field, and cut the interactions of the particles on either side, so
//! that a body splits into fragments.
//!
//! After every step the solid
//!
//! 1. advances each running crack front normal to the largest principal
//!    stress where that stress still passes the threshold, stopping a
//!    front node that leaves the body or meets another crack (joining);
//! 2. starts a crack at each particle past the threshold (largest
//!    first) that no crack is near yet, its plane normal to the
//!    particle's principal direction;
//! 3. recomputes the weights of the pairs the moved fronts can have
//!    changed (Eq. 70, `transparency.rs`), and refits the gradient
//!    weights of only the particles whose pairs changed: the cost of a
//!    running crack is proportional to the particles near its front, not
//!    to the body;
//! 4. labels the fragments, the sets of particles still connected by a
//!    pair of positive weight (`fragments.rs`).
//!
//! Weights only ever fall (a crack does not heal), as in Pauly et al.
//!
//! - `params.rs`: thresholds, criterion, knobs;
//! - `crack.rs`: crack surfaces as triangulated fronts;
//! - `transparency.rs`: Eq. 70 and the under-sampling measure Eq. 71;
//! - `fragments.rs`: connected fragments;
//! - `surface.rs`: the crack faces a frame shows, each carried by its own
//!   side's material.

mod crack;
mod fragments;
mod params;
mod surface;
mod transparency;

#[cfg(test)]
mod tests;

pub use crack::{Crack, Crossing, FrontNode};
pub use params::{CrackCriterion, Discontinuity, FractureParams, FractureParamsError, Threshold};
pub use transparency::{opacity, transparent_weight, undersampling};

use super::body::Body;
use super::material::StressState;
use super::topology::Reweigh;
use crate::approx::mls::{Mls, MlsParams};
use crate::math::{Real, Vector};
use crate::neighbors::{CandidateSearch, KdTree};
use crate::snapshot::{SnapshotError, check_length};
use nalgebra::{Matrix3, SymmetricEigen};
use rayon::prelude::*;
use std::time::{Duration, Instant};

/// Crack vertices a solid may hold per particle (beyond a fixed
/// allowance): a bound on the geometry's memory that a running crack
/// cannot pass silently.
pub const VERTICES_PER_PARTICLE: usize = 32;

/// A fracturing solid's cracks and what they did to its pairs: its state,
/// which snapshots keep.
#[derive(Debug, Clone, PartialEq)]
pub struct Fracture {
    params: FractureParams,
    cracks: Vec<Crack>,
    /// Per topology edge, the term the cracks added to its normalised
    /// distance (0 where none crossed; infinite where a crack removed it).
    extra: Vec<Real>,
    /// Fragment of each particle: the body's connected parts as built,
    /// then each part a crack cuts off numbered next.
    fragments: Vec<u32>,
    fragment_count: u32,
    /// The neighbour search over the reference shape, kept between
    /// updates (the shape never moves: a fracturing solid does not
    /// re-base), so a step's cost follows the particles near the fronts.
    search: SearchCache,
}

/// A kd-tree over the reference shape and the radius it answers, built
/// at the first update: a cache, not state, so it takes no part in
/// comparisons and snapshots.
#[derive(Clone, Default)]
struct SearchCache(Option<(Real, KdTree)>);

impl SearchCache {
    fn get(&mut self, radius: Real, rest: &[Vector]) -> &KdTree {
        if !self.0.as_ref().is_some_and(|(r, _)| *r == radius) {
            let mut tree = KdTree::new(radius);
            tree.rebuild(rest);
            self.0 = Some((radius, tree));
        }
        let (_, tree) = self.0.as_ref().expect("built above");
        tree
    }
}

impl PartialEq for SearchCache {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl std::fmt::Debug for SearchCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SearchCache")
    }
}

/// What a snapshot keeps of a fracturing solid: its cracks, the term they
/// added to each pair, and the fragments (whose numbers record the order
/// the parts split off in).
#[derive(Debug, Clone, PartialEq)]
pub struct FractureSnapshot {
    /// The cracks, in the order they started.
    pub cracks: Vec<Crack>,
    /// Per topology edge, [`Fracture::extra`].
    pub extra: Vec<Real>,
    /// Each particle's fragment, [`Fracture::fragments`].
    pub fragments: Vec<u32>,
}

/// What one fracture update did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FractureStep {
    /// Cracks started.
    pub started: u32,
    /// Front nodes that advanced.
    pub advanced: u32,
    /// Particles whose shape functions were refitted.
    pub refitted: u32,
    /// What the reweighing changed the stored energy by at the current
    /// positions, J: a change of the energy's form, not work done on the
    /// solid (the energy watch moves its start by it).
    pub energy_change: Real,
    /// Time spent looking for particles past the threshold: the one
    /// pass over every particle.
    pub scan: Duration,
    /// Time spent reweighing the pairs near what moved, refitting their
    /// particles and checking the fragments: what follows the crack.
    pub refit: Duration,
}

/// Why a fracture update stopped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FractureError {
    /// The cracks' geometry outgrew its bound.
    #[error(
        "the cracks grew to {vertices} vertices, past the bound of {limit} for {particles} particles; raise the fracture threshold or lower its advance"
    )]
    Geometry {
        /// Vertices the cracks would hold.
        vertices: usize,
        /// The bound.
        limit: usize,
        /// The solid's particles.
        particles: usize,
    },
}

/// The largest principal value of a symmetric matrix's leading `dim`
/// block, and its unit direction (its sign fixed: the first non-zero
/// component positive, so that the same stress gives the same crack).
pub fn principal(dim: usize, m: &Matrix3<Real>) -> (Real, Vector) {
    let (value, direction) = if dim == 2 {
        let block = m.fixed_view::<2, 2>(0, 0).into_owned();
        let eigen = SymmetricEigen::new(block);
        let k = eigen.eigenvalues.imax();
        let v = eigen.eigenvectors.column(k);
        (eigen.eigenvalues[k], Vector::new(v[0], v[1], 0.0))
    } else {
        let eigen = SymmetricEigen::new(*m);
        let k = eigen.eigenvalues.imax();
        (
            eigen.eigenvalues[k],
            eigen.eigenvectors.column(k).into_owned(),
        )
    };
    let sign = direction
        .iter()
        .find(|c| c.abs() > 1e-12)
        .map_or(1.0, |c| c.signum());
    (value, direction * sign)
}

/// Cauchy stress `F S F^T / det F` of a stress state (the second
/// Piola–Kirchhoff stress itself where `F` is inverted).
pub fn cauchy(state: &StressState) -> Matrix3<Real> {
    if state.det > 0.0 {
        state.f * state.s * state.f.transpose() / state.det
    } else {
        state.s
    }
}

impl Fracture {
    /// No crack yet in a solid of `particles` particles and `edges`
    /// topology edges.
    pub fn new(params: FractureParams, particles: usize, edges: usize) -> Self {
        Self {
            params,
            cracks: Vec::new(),
            extra: vec![0.0; edges],
            fragments: vec![0; particles],
            fragment_count: 1,
            search: SearchCache::default(),
        }
    }

    /// The parameters.
    pub fn params(&self) -> &FractureParams {
        &self.params
    }

    /// The cracks, in the order they started.
    pub fn cracks(&self) -> &[Crack] {
        &self.cracks
    }

    /// Each particle's fragment.
    pub fn fragments(&self) -> &[u32] {
        &self.fragments
    }

    /// How many fragments the solid is in.
    pub fn fragment_count(&self) -> u32 {
        self.fragment_count
    }

    /// Per topology edge, the term cracks added to its distance.
    pub fn extra(&self) -> &[Real] {
        &self.extra
    }

    /// Crack vertices held.
    pub fn vertex_count(&self) -> usize {
        self.cracks.iter().map(|c| c.vertices().len()).sum()
    }
}

impl Body {
    /// The fracture state, when the solid fractures.
    pub fn fracture(&self) -> Option<&Fracture> {
        self.fracture.as_ref()
    }

    /// Every crack's two faces deformed with the material on each side,
    /// with unit vertex normals, for a frame; `None` before any crack.
    pub fn crack_surface(&self) -> Option<(crate::geometry::TriMesh, Vec<Vector>)> {
        let fracture = self.fracture.as_ref()?;
        surface::crack_faces(
            fracture,
            &self.rest,
            &self.positions,
            self.params.spacing,
            self.params.support,
        )
    }

    /// Eq. 71 at every particle: the transparency-weighted count of its
    /// neighbours, which cracks lower (the plain count without them).
    pub fn undersampling(&self) -> Vec<Real> {
        let t = &self.topology;
        let kernel = MlsParams::new(self.params.order, self.params.support).weight;
        let inv_h = 1.0 / self.params.support;
        let extra = self.fracture.as_ref().map(|f| f.extra.as_slice());
        let edges = t.gradients.neighbour_indices();
        (0..self.len())
            .map(|i| {
                let pairs = t
                    .gradients
                    .range(i)
                    .filter(|&e| edges[e] as usize != i)
                    .map(|e| (t.rest_offset[e].norm() * inv_h, extra.map_or(0.0, |x| x[e])));
                undersampling(kernel, pairs)
            })
            .collect()
    }

    /// The cracks as a snapshot keeps them, when the solid fractures.
    pub fn fracture_snapshot(&self) -> Option<FractureSnapshot> {
        self.fracture.as_ref().map(|f| FractureSnapshot {
            cracks: f.cracks.clone(),
            extra: f.extra.clone(),
            fragments: f.fragments.clone(),
        })
    }

    /// Checks a snapshot's cracks against this body: present exactly when
    /// the solid fractures, one term per pair (none negative or NaN), of
    /// the solid's dimension, within the crack count and geometry bounds.
    pub(super) fn check_fracture(
        &self,
        state: Option<&FractureSnapshot>,
    ) -> Result<(), SnapshotError> {
        let (fracture, state) = match (&self.fracture, state) {
            (None, None) => return Ok(()),
            (Some(f), Some(s)) => (f, s),
            (f, s) => {
                return Err(SnapshotError::Length {
                    what: "fracture states",
                    expected: usize::from(f.is_some()),
                    got: usize::from(s.is_some()),
                });
            }
        };
        let edges = self.topology.owner.len();
        if state.extra.len() != edges {
            return Err(SnapshotError::Length {
                what: "crack terms (one per neighbour pair)",
                expected: edges,
                got: state.extra.len(),
            });
        }
        if let Some(index) = state.extra.iter().position(|x| x.is_nan() || *x < 0.0) {
            return Err(SnapshotError::Invalid {
                what: "crack term",
                index,
                value: state.extra[index],
            });
        }
        check_length("fragment labels", state.fragments.len(), self.len())?;
        if let Some(index) = state
            .fragments
            .iter()
            .position(|&k| k as usize >= self.len())
        {
            return Err(SnapshotError::Invalid {
                what: "fragment label",
                index,
                value: Real::from(state.fragments[index]),
            });
        }
        let max = fracture.params.max_cracks as usize;
        if state.cracks.len() > max {
            return Err(SnapshotError::Length {
                what: "cracks",
                expected: max,
                got: state.cracks.len(),
            });
        }
        if let Some(index) = state.cracks.iter().position(|c| c.dim() != self.params.dim) {
            return Err(SnapshotError::Invalid {
                what: "crack dimension",
                index,
                value: state.cracks[index].dim() as Real,
            });
        }
        let vertices: usize = state.cracks.iter().map(|c| c.vertices().len()).sum();
        let limit = VERTICES_PER_PARTICLE * self.len() + 1024;
        if vertices > limit {
            return Err(SnapshotError::Length {
                what: "crack vertices",
                expected: limit,
                got: vertices,
            });
        }
        Ok(())
    }

    /// Puts back a snapshot's cracks, pair terms and fragments (checked
    /// by [`Self::check_fracture`]), reweighing the pairs that differ.
    pub(super) fn restore_fracture(&mut self, state: &FractureSnapshot) {
        let Some(now) = self.fracture.as_ref() else {
            return;
        };
        let saved = Fracture {
            params: now.params,
            cracks: state.cracks.clone(),
            extra: state.extra.clone(),
            fragments: state.fragments.clone(),
            fragment_count: state.fragments.iter().max().map_or(0, |&k| k + 1),
            search: SearchCache::default(),
        };
        self.put_back_cracks(&saved);
    }

    /// Labels the fragments of a solid no crack has cut yet.
    pub(super) fn label_fragments(&mut self) {
        let n = self.len();
        let Some(mut fracture) = self.fracture.take() else {
            return;
        };
        (fracture.fragments, fracture.fragment_count) =
            fragments::label(n, |i| self.connected_neighbours(i, &fracture.extra));
        self.fracture = Some(fracture);
    }

    /// The neighbours `i` still interacts with under the terms `extra`.
    fn connected_neighbours<'a>(
        &'a self,
        i: usize,
        extra: &'a [Real],
    ) -> impl Iterator<Item = usize> + 'a {
        let t = &self.topology;
        let kernel = MlsParams::new(self.params.order, self.params.support).weight;
        let inv_h = 1.0 / self.params.support;
        let edges = t.gradients.neighbour_indices();
        t.gradients
            .range(i)
            .filter(move |&e| edges[e] as usize != i)
            .filter(move |&e| {
                transparent_weight(kernel, t.rest_offset[e].norm() * inv_h, extra[e]).is_some()
            })
            .map(move |e| edges[e] as usize)
    }

    /// Returns the cracks to `saved` (this body's, from before the
    /// current ones grew), reweighing the particles whose pairs differ:
    /// the weights are a function of the per-edge terms, so the shape
    /// functions return bit for bit.
    pub(super) fn put_back_cracks(&mut self, saved: &Fracture) {
        let Some(now) = self.fracture.as_ref() else {
            return;
        };
        if now == saved {
            return;
        }
        let changed: Vec<usize> = (0..self.len())
            .filter(|&i| {
                self.topology
                    .gradients
                    .range(i)
                    .any(|e| now.extra[e] != saved.extra[e])
            })
            .collect();
        self.fracture = Some(saved.clone());
        if changed.is_empty() {
            return;
        }
        let p = self.params;
        let mls = Mls::new(p.dim, MlsParams::new(p.order, p.support))
            .expect("the solid's MLS parameters were valid when it was built");
        let mut scratch = Reweigh::default();
        for i in changed {
            self.topology
                .reweigh(i, &self.rest, &mls, &saved.extra, &mut scratch);
        }
    }

    /// Steps 1 to 4 of the module's update with `states`, the stress
    /// states of the step's last force evaluation.
    ///
    /// # Errors
    /// [`FractureError::Geometry`] when the cracks would outgrow their
    /// bound; nothing changed then.
    pub(super) fn fracture_step(
        &mut self,
        states: &[StressState],
    ) -> Result<FractureStep, FractureError> {
        let Some(mut fracture) = self.fracture.take() else {
            return Ok(FractureStep::default());
        };
        let mut search = std::mem::take(&mut fracture.search);
        let result = self.update_cracks(&mut fracture, &mut search, states);
        fracture.search = search;
        self.fracture = Some(fracture);
        result
    }

    fn update_cracks(
        &mut self,
        fracture: &mut Fracture,
        search: &mut SearchCache,
        states: &[StressState],
    ) -> Result<FractureStep, FractureError> {
        let p = self.params;
        let (dim, spacing, h) = (p.dim, p.spacing, p.support);
        let n = self.len();
        if states.len() != n {
            return Ok(FractureStep::default());
        }
        let params = fracture.params;
        // How far a pair's weight can feel a front: past `kappa spacing`
        // behind it the added term reaches 1 and the weight is zero.
        let reach = match params.discontinuity {
            crate::solid::fracture::Discontinuity::Visibility => 0.0,
            crate::solid::fracture::Discontinuity::Transparency { kappa } => kappa * spacing,
        };
        let step = params.advance * spacing;
        let radius = h + reach + step + spacing;
        let search = search.get(radius, &self.rest);
        let rest = &self.rest;
        let nearest = |at: &Vector| -> Option<usize> {
            let mut best: Option<(Real, usize)> = None;
            search.for_each_candidate(at, |j| {
                let d = (rest[j as usize] - at).norm();
                if d <= spacing && best.is_none_or(|(b, k)| d < b || (d == b && (j as usize) < k)) {
                    best = Some((d, j as usize));
                }
            });
            best.map(|(_, j)| j)
        };
        let measure = |i: usize| -> (Real, Vector) {
            let (sigma, direction) = principal(dim, &cauchy(&states[i]));
            match params.threshold {
                Threshold::Stress { stress } => (sigma / stress, direction),
                Threshold::PlasticStrain { plastic_strain } => {
                    let strain = self.plastic.as_ref().map_or(0.0, |e| e[i].norm());
                    (strain / plastic_strain, direction)
                }
            }
        };

        // 1. Running fronts.
        let mut touched: Vec<Vector> = Vec::new();
        let mut out = FractureStep::default();
        for c in 0..fracture.cracks.len() {
            let front = fracture.cracks[c].front().to_vec();
            let mut moves = vec![None; front.len()];
            for (k, node) in front.iter().enumerate() {
                if !node.active {
                    continue;
                }
                let Some(at) = nearest(&node.at) else {
                    // Out of the body: the pairs near it lose their front.
                    fracture.cracks[c].stop(k);
                    touched.push(node.at);
                    continue;
                };
                let (ratio, normal) = measure(at);
                if ratio < 1.0 {
                    continue;
                }
                let mut heading = node.heading - normal * node.heading.dot(&normal);
                if dim == 2 {
                    heading.z = 0.0;
                }
                let heading = if heading.norm() > 1e-9 {
                    heading.normalize()
                } else {
                    node.heading
                };
                let mut to = node.at + heading * step;
                // Joining: a front that meets another crack stops on it.
                let met = fracture
                    .cracks
                    .iter()
                    .enumerate()
                    .filter(|(other, _)| *other != c)
                    .filter_map(|(_, other)| other.crossing(&node.at, &to))
                    .map(|x| x.at)
                    .min_by(|a, b| (a - node.at).norm().total_cmp(&(b - node.at).norm()));
                if let Some(hit) = met {
                    to = hit;
                }
                touched.push(node.at);
                touched.push(to);
                moves[k] = Some((to, heading));
                if met.is_some() {
                    fracture.cracks[c].stop(k);
                }
                out.advanced += 1;
            }
            if moves.iter().any(Option::is_some) {
                fracture.cracks[c].advance(&moves, 1.5 * spacing);
            }
        }

        let scanning = Instant::now();
        // 2. New cracks, the most loaded particle first. The largest
        // principal stress is at most the stress's Frobenius norm, so
        // only particles past the threshold in that norm are decomposed.
        let plastic = self.plastic.as_deref();
        let mut candidates: Vec<(Real, usize, Vector)> = (0..n)
            .into_par_iter()
            .filter(|&i| match params.threshold {
                Threshold::Stress { stress } => cauchy(&states[i]).norm() >= stress,
                Threshold::PlasticStrain { plastic_strain } => {
                    plastic.is_some_and(|e| e[i].norm() >= plastic_strain)
                }
            })
            .filter_map(|i| {
                let (ratio, direction) = measure(i);
                (ratio >= 1.0).then_some((ratio, i, direction))
            })
            .collect();
        candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        for (_, i, normal) in candidates {
            if fracture.cracks.len() >= params.max_cracks as usize {
                break;
            }
            let x = rest[i];
            if fracture
                .cracks
                .iter()
                .any(|c| c.distance_to_vertices(&x) < h)
            {
                continue;
            }
            let crack = Crack::start(dim, x + normal * (0.5 * spacing), normal, spacing, h);
            touched.extend(crack.front().iter().map(|f| f.at));
            touched.push(x);
            fracture.cracks.push(crack);
            out.started += 1;
        }
        out.scan = scanning.elapsed();
        let vertices = fracture.vertex_count();
        let limit = VERTICES_PER_PARTICLE * n + 1024;
        if vertices > limit {
            return Err(FractureError::Geometry {
                vertices,
                limit,
                particles: n,
            });
        }
        if touched.is_empty() {
            return Ok(out);
        }

        let refitting = Instant::now();
        // 3. The pairs near what moved: their terms, and the particles
        // whose shape functions change with them.
        let mut near = Vec::new();
        for point in &touched {
            search.for_each_candidate(point, |j| {
                if (rest[j as usize] - point).norm() <= radius {
                    near.push(j as usize);
                }
            });
        }
        near.sort_unstable();
        near.dedup();
        let kernel = MlsParams::new(p.order, h).weight;
        let inv_h = 1.0 / h;
        let mut refit = Vec::new();
        let mut cut = Vec::new();
        {
            let t = &self.topology;
            let edges = t.gradients.neighbour_indices();
            for &i in &near {
                for e in t.gradients.range(i) {
                    let j = edges[e] as usize;
                    if j == i {
                        continue;
                    }
                    // One direction for both edges of the pair, so both
                    // get the same term.
                    let (a, b) = if i < j {
                        (rest[i], rest[j])
                    } else {
                        (rest[j], rest[i])
                    };
                    let added: Real = fracture
                        .cracks
                        .iter()
                        .filter_map(|c| c.crossing(&a, &b))
                        .map(|x| opacity(params.discontinuity, x.to_front, spacing))
                        .sum();
                    if added > fracture.extra[e] {
                        let q = t.rest_offset[e].norm() * inv_h;
                        if transparent_weight(kernel, q, fracture.extra[e]).is_some()
                            && transparent_weight(kernel, q, added).is_none()
                        {
                            cut.push((i.min(j), i.max(j)));
                        }
                        fracture.extra[e] = added;
                        refit.extend([i, j]);
                        // The reverse edge, which `j` owns.
                        if let Some(back) = t.gradients.range(j).find(|&f| edges[f] as usize == i) {
                            fracture.extra[back] = fracture.extra[back].max(added);
                        }
                    }
                }
            }
        }
        refit.sort_unstable();
        refit.dedup();
        let mls = Mls::new(dim, MlsParams::new(p.order, h))
            .expect("the solid's MLS parameters were valid when it was built");
        let shares = |body: &Body| -> Real {
            let model = body.model();
            refit
                .iter()
                .map(|&i| model.particle_energy(i, &body.positions))
                .sum()
        };
        let before = shares(self);
        let mut scratch = Reweigh::default();
        for &i in &refit {
            self.topology
                .reweigh(i, &self.rest, &mls, &fracture.extra, &mut scratch);
        }
        out.energy_change = shares(self) - before;
        out.refitted = refit.len() as u32;

        // 4. Fragments: only a pair cut through can split one, and only
        // if no other chain of pairs still joins its ends.
        cut.sort_unstable();
        cut.dedup();
        for (a, b) in cut {
            fragments::split(
                a,
                b,
                |i| self.connected_neighbours(i, &fracture.extra),
                &mut fracture.fragments,
                &mut fracture.fragment_count,
            );
        }
        out.refit = refitting.elapsed();
        Ok(out)
    }
}
