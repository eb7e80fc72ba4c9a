//! What a step does to a fracturing solid's cracks (tutorial Section
//! 7.3; the model is `fracture/`'s module documentation): fronts run,
//! cracks start, the pairs near what moved are reweighed and the
//! fragments kept; and the cracks as snapshots, frames and undone steps
//! see them. The body's side of fracture, as `plasticity.rs` is of
//! plastic flow.

use super::body::Body;
use super::fracture::{
    Crack, CrackIndex, Discontinuity, Fracture, FractureError, FractureParamsError,
    FractureSnapshot, FractureStep, FrontNode, Notch, SearchCache, SkinCache, Threshold,
    VERTICES_PER_PARTICLE, cauchy, check_room, crack_faces, fragment_surfaces, label,
    largest_principal, lengthened, opacity, principal, split, stress_bound, transparent_weight,
    undersampling,
};
use super::material::StressState;
use super::topology::Reweigh;
use crate::approx::mls::{Mls, MlsParams};
use crate::math::{Real, Vector};
use crate::neighbors::CandidateSearch;
use crate::snapshot::{SnapshotError, check_length};
use rayon::prelude::*;
use std::time::Instant;

impl Body {
    /// The fracture state, when the solid fractures.
    pub fn fracture(&self) -> Option<&Fracture> {
        self.fracture.as_ref()
    }

    /// Every crack's two faces deformed with the material on each side,
    /// with unit vertex normals, for a frame; `None` before any crack.
    pub fn crack_surface(&self) -> Option<(crate::geometry::TriMesh, Vec<Vector>)> {
        let fracture = self.fracture.as_ref()?;
        crack_faces(
            fracture,
            &self.rest,
            &self.positions,
            self.params.spacing,
            self.params.support,
        )
    }

    /// Each fragment's closed surface, deformed with that fragment alone,
    /// with unit vertex normals, for a frame (`fracture/fragment_surface.rs`);
    /// `outline` is the solid's reference surface. `None` while the solid
    /// is in one piece.
    pub fn fragment_surface(
        &self,
        outline: &crate::geometry::MeshSdf,
    ) -> Option<(crate::geometry::TriMesh, Vec<Vector>)> {
        fragment_surfaces(
            self.fracture.as_ref()?,
            outline,
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
                    .map(|e| (t.q(e, inv_h), extra.map_or(0.0, |x| x[e])));
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
            skin: SkinCache::default(),
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
            label(n, |i| self.connected_neighbours(i, &fracture.extra));
        self.fracture = Some(fracture);
    }

    /// Cuts the solid along `notches`, the flaws it is built with: each
    /// becomes a crack (a front that runs under load like any other), the
    /// pairs it crosses are reweighed and the fragments labelled again.
    ///
    /// # Errors
    /// [`FractureParamsError::Notch`] for a notch out of range, for more
    /// cracks than `max_cracks` allows, for a geometry past the solid's
    /// bound, or on a solid that does not fracture; the body is then
    /// unchanged.
    pub fn notch(&mut self, notches: &[Notch]) -> Result<(), FractureParamsError> {
        let p = self.params;
        let fracture = self.fracture.as_ref().ok_or_else(|| {
            FractureParamsError::Notch("the solid does not fracture; add a fracture table".into())
        })?;
        for notch in notches {
            notch.validate(p.dim)?;
        }
        if notches.is_empty() {
            return Ok(());
        }
        check_room(
            notches,
            (fracture.cracks.len(), fracture.vertex_count()),
            fracture.params.max_cracks,
            (p.dim, p.spacing, self.len()),
        )?;
        let mut fracture = fracture.clone();
        fracture.cracks.extend(
            notches
                .iter()
                .map(|n| Crack::notch(p.dim, n, p.spacing, p.support)),
        );
        // Every pair is looked at once, so the fragments are labelled
        // afresh rather than split pair by pair.
        let all: Vec<usize> = (0..self.len()).collect();
        self.recut(&mut fracture, &all);
        self.fracture = Some(fracture);
        self.label_fragments();
        Ok(())
    }

    /// The neighbours `i` still interacts with under the terms `extra`.
    pub(super) fn connected_neighbours<'a>(
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
            .filter(move |&e| transparent_weight(kernel, t.q(e, inv_h), extra[e]).is_some())
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
            self.topology.reweigh(
                i,
                &self.rest,
                &mls,
                &saved.extra,
                lengthened(&mls),
                &mut scratch,
            );
        }
    }

    /// The update `fracture/`'s module documentation describes (its steps
    /// 1 to 4) with `states`, the stress states of the step's last force
    /// evaluation.
    ///
    /// # Errors
    /// [`FractureError::Geometry`] when the cracks outgrew their bound,
    /// checked once they grew: the caller puts back a state saved before
    /// the step (the world does, as for any failed step).
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
            Discontinuity::Visibility => 0.0,
            Discontinuity::Transparency { kappa } => kappa * spacing,
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
                Threshold::Stress { stress } | Threshold::Toughness { stress, .. } => {
                    (sigma / stress, direction)
                }
                Threshold::PlasticStrain { plastic_strain } => {
                    let strain = self.plastic.as_ref().map_or(0.0, |e| e[i].norm());
                    (strain / plastic_strain, direction)
                }
            }
        };
        // The point method (`Threshold::Toughness`): the stress the
        // critical distance ahead of a front, averaged over the particles
        // within a spacing and a half of that point that see it (none
        // across a crack), weighted by the kernel's profile.
        let critical = params.threshold.critical_distance();
        let ahead =
            |cracks: &[Crack], node: &FrontNode, distance: Real| -> Option<(Real, Vector)> {
                let stress = match params.threshold {
                    Threshold::Toughness { stress, .. } => stress,
                    Threshold::Stress { .. } | Threshold::PlasticStrain { .. } => return None,
                };
                let point = node.at + node.heading * distance;
                let reach = 1.5 * spacing;
                let (mut sum, mut weights) = (nalgebra::Matrix3::zeros(), 0.0);
                search.for_each_candidate(&point, |j| {
                    let x = rest[j as usize];
                    let q = (x - point).norm() / reach;
                    if q < 1.0 && cracks.iter().all(|c| c.crossing(&x, &point).is_none()) {
                        let w = (1.0 - q * q).powi(3);
                        sum += cauchy(&states[j as usize]) * w;
                        weights += w;
                    }
                });
                (weights > 0.0).then(|| {
                    let (sigma, direction) = principal(dim, &(sum / weights));
                    (sigma / stress, direction)
                })
            };

        // 1. Running fronts.
        let mut touched: Vec<Vector> = Vec::new();
        let mut branches: Vec<Crack> = Vec::new();
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
                let (ratio, normal) = critical
                    .and_then(|d| ahead(&fracture.cracks, node, d))
                    .unwrap_or_else(|| measure(at));
                if ratio < 1.0 {
                    continue;
                }
                let mut heading = node.heading - normal * node.heading.dot(&normal);
                if dim == 2 {
                    heading.z = 0.0;
                }
                let mut heading = if heading.norm() > 1e-9 {
                    heading.normalize()
                } else {
                    node.heading
                };
                // Branching: past `branching` times the threshold, and
                // clear of every other crack by twice the support (so that
                // the two arms of the last branch have parted before
                // either splits again), a new crack leaves the tip to one
                // side while this front turns to the other.
                let room = fracture.cracks.len() + branches.len() < params.max_cracks as usize;
                if room
                    && params.branching.is_some_and(|b| ratio >= b)
                    && fracture
                        .cracks
                        .iter()
                        .enumerate()
                        .filter(|(other, _)| *other != c)
                        .map(|(_, other)| other)
                        .chain(&branches)
                        .all(|other| other.distance_to_vertices(&node.at) >= 2.0 * h)
                    && let Some((branch, turned)) =
                        Crack::branch(dim, node.at, heading, normal, step, h)
                {
                    touched.extend(branch.front().iter().map(|f| f.at));
                    branches.push(branch);
                    out.branched += 1;
                    heading = turned;
                }
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
        fracture.cracks.append(&mut branches);

        let scanning = Instant::now();
        // 2. New cracks, the most loaded particle first. This is the one
        // pass over every particle, and it reads each one's whole stress
        // state: only those whose stress may pass the threshold by a
        // cheap bound (`stress_bound`) have their largest principal
        // stress taken, in closed form, and only those that start a crack
        // their direction.
        // With the most cracks there already, none can start: no scan.
        let plastic = self.plastic.as_deref();
        let full = fracture.cracks.len() >= params.max_cracks as usize;
        let mut candidates: Vec<(Real, usize)> = if full {
            Vec::new()
        } else {
            (0..n)
                .into_par_iter()
                .filter_map(|i| {
                    let ratio = match params.threshold {
                        Threshold::Stress { stress } | Threshold::Toughness { stress, .. } => {
                            if stress_bound(&states[i]) < stress {
                                return None;
                            }
                            largest_principal(dim, &cauchy(&states[i])) / stress
                        }
                        Threshold::PlasticStrain { plastic_strain } => {
                            plastic.map_or(0.0, |e| e[i].norm()) / plastic_strain
                        }
                    };
                    (ratio >= 1.0).then_some((ratio, i))
                })
                .collect()
        };
        candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        for (_, i) in candidates {
            if fracture.cracks.len() >= params.max_cracks as usize {
                break;
            }
            // Near a crack its front decides. With a toughness that is
            // as far as twice the critical distance: the front weighs the
            // stress at `r_c`, and the singular field behind that point
            // passes the strength at any load that runs it (within
            // `2 r_c` up to loads of 1.4 times the critical).
            let x = rest[i];
            let clear = h + 2.0 * critical.unwrap_or(0.0);
            if fracture
                .cracks
                .iter()
                .any(|c| c.distance_to_vertices(&x) < clear)
            {
                continue;
            }
            let (_, normal) = measure(i);
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
        let recut = self.recut(fracture, &near);
        out.refitted = recut.refitted;
        out.energy_change = recut.energy_change;
        // 4. Fragments: only a pair cut through can split one, and only
        // if no other chain of pairs still joins its ends.
        for (a, b) in recut.cut {
            split(
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

    /// Step 3 of the update for the particles `near` (sorted, distinct)
    /// what the cracks changed: each of their pairs' terms from the cracks
    /// as they are, and the shape functions of the particles whose terms
    /// grew; the pairs it cut through are for the caller's fragments.
    fn recut(&mut self, fracture: &mut Fracture, near: &[usize]) -> Recut {
        let p = self.params;
        let (dim, spacing, h) = (p.dim, p.spacing, p.support);
        let params = fracture.params;
        let rest = &self.rest;
        let kernel = MlsParams::new(p.order, h).weight;
        let inv_h = 1.0 / h;
        let mut refit = Vec::new();
        let mut cut = Vec::new();
        {
            let t = &self.topology;
            let edges = t.gradients.neighbour_indices();
            let index = CrackIndex::new(&fracture.cracks, h);
            let mut candidates = Vec::new();
            for &i in near {
                for e in t.gradients.range(i) {
                    let j = edges[e] as usize;
                    // A pair whose both ends are near is handled once,
                    // from its lower end, which sets both its edges.
                    if j == i || (j < i && near.binary_search(&j).is_ok()) {
                        continue;
                    }
                    // One direction for both edges of the pair, so both
                    // get the same term.
                    let (a, b) = if i < j {
                        (rest[i], rest[j])
                    } else {
                        (rest[j], rest[i])
                    };
                    index.near(&a, &b, &mut candidates);
                    let added: Real = candidates
                        .iter()
                        .filter_map(|&c| fracture.cracks[c as usize].crossing(&a, &b))
                        .map(|x| opacity(params.discontinuity, x.to_front, spacing))
                        .sum();
                    if added > fracture.extra[e] {
                        let q = t.q(e, inv_h);
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
            self.topology.reweigh(
                i,
                &self.rest,
                &mls,
                &fracture.extra,
                lengthened(&mls),
                &mut scratch,
            );
        }
        let energy_change = shares(self) - before;
        cut.sort_unstable();
        cut.dedup();
        Recut {
            refitted: refit.len() as u32,
            energy_change,
            cut,
        }
    }
}

/// What [`Body::recut`] changed.
struct Recut {
    /// Particles refitted.
    refitted: u32,
    /// The stored energy's change at the current positions, J.
    energy_change: Real,
    /// The pairs it cut through (lower end first, each once).
    cut: Vec<(usize, usize)>,
}
