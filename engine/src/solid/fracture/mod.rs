//! Fracture of MLS solids (tutorial Section 7.3, after Pauly et al. 2005):
//! cracks that start where the material fails, run along the stress
//! field, and cut the interactions of the particles on either side, so
//! that a body splits into fragments.
//!
//! After every step the solid
//!
//! 1. advances each running crack front normal to the largest principal
//!    stress where that stress still passes the threshold (with a
//!    toughness, the stress a critical distance ahead of the front: the
//!    point method, `Threshold::Toughness`), stopping a front node that
//!    leaves the body or meets another crack (joining), and splitting
//!    one whose stress passes `branching` times the threshold
//!    (branching);
//! 2. starts a crack at each particle past the threshold (largest
//!    first) that no crack is near yet, its plane normal to the
//!    particle's principal direction;
//! 3. recomputes the weights of the pairs the moved fronts can have
//!    changed (Eq. 70, `transparency.rs`), and refits the gradient
//!    weights of only the particles whose pairs changed: the cost of a
//!    running crack is proportional to the particles near its front, not
//!    to the body;
//! 4. splits off a fragment wherever a pair cut through was the last
//!    link between two parts (`fragments.rs`).
//!
//! Weights only ever fall (a crack does not heal), as in Pauly et al.
//!
//! The update itself is the body's (`solid/cracking.rs`, beside
//! `solid/plasticity.rs`); this module is what it works with:
//!
//! - `params.rs`: thresholds, criterion, knobs, and the notches a solid
//!   is built with;
//! - `crack.rs`: crack surfaces as triangulated fronts;
//! - `transparency.rs`: Eq. 70 and the under-sampling measure Eq. 71;
//! - `fragments.rs`: connected fragments;
//! - `index.rs`: a grid over the cracks, for the pairs' crossing tests;
//! - `surface.rs`: the crack faces a frame shows, each carried by its own
//!   side's material.

mod crack;
mod fragment_surface;
mod fragments;
mod index;
mod params;
mod surface;
mod transparency;

#[cfg(test)]
pub(in crate::solid) mod tests;

pub use crack::{Crack, Crossing, FrontNode};
pub(in crate::solid) use fragment_surface::{SkinCache, fragment_surfaces};
pub(in crate::solid) use fragments::{label, split};
pub(in crate::solid) use index::CrackIndex;
pub use params::{
    CrackCriterion, Discontinuity, FractureParams, FractureParamsError, Notch, Resampling,
    Threshold, check_room,
};
pub(in crate::solid) use surface::crack_faces;
pub use transparency::{opacity, transparent_weight, undersampling};

use super::material::StressState;
use crate::approx::mls::Mls;
use crate::math::{Real, Vector};
use crate::neighbors::{CandidateSearch, KdTree};
use nalgebra::{Matrix3, SymmetricEigen};
use std::borrow::Cow;
use std::time::Duration;

/// Crack vertices a solid may hold per particle (beyond a fixed
/// allowance): a bound on the geometry's memory that a running crack
/// cannot pass silently.
pub const VERTICES_PER_PARTICLE: usize = 32;

/// A fracturing solid's cracks and what they did to its pairs: its state,
/// which snapshots keep.
#[derive(Debug, Clone, PartialEq)]
pub struct Fracture {
    pub(in crate::solid) params: FractureParams,
    pub(in crate::solid) cracks: Vec<Crack>,
    /// Per topology edge, the term the cracks added to its normalised
    /// distance (0 where none crossed; infinite where a crack removed it).
    pub(in crate::solid) extra: Vec<Real>,
    /// Fragment of each particle: the body's connected parts as built,
    /// then each part a crack cuts off numbered next.
    pub(in crate::solid) fragments: Vec<u32>,
    pub(in crate::solid) fragment_count: u32,
    /// The neighbour search over the reference shape, kept between
    /// updates (the shape never moves: a fracturing solid does not
    /// re-base), so a step's cost follows the particles near the fronts.
    pub(in crate::solid) search: SearchCache,
    /// The fragments' reference surface, kept between frames.
    pub(in crate::solid) skin: SkinCache,
}

/// A kd-tree over the reference shape and the radius it answers, built
/// at the first update: a cache, not state, so it takes no part in
/// comparisons and snapshots.
#[derive(Clone, Default)]
pub(in crate::solid) struct SearchCache(Option<(Real, KdTree)>);

impl SearchCache {
    pub(in crate::solid) fn get(&mut self, radius: Real, rest: &[Vector]) -> &KdTree {
        if !self.0.as_ref().is_some_and(|(r, _)| *r == radius) {
            let mut tree = KdTree::new(radius);
            tree.rebuild(rest);
            self.0 = Some((radius, tree));
        }
        let (_, tree) = self.0.as_ref().expect("built above");
        tree
    }
}

impl SearchCache {
    /// The tree, if an update built one (its radius is at least the
    /// support radius).
    pub(in crate::solid) fn built(&self) -> Option<&KdTree> {
        self.0.as_ref().map(|(_, tree)| tree)
    }

    /// The tree the updates keep (its radius covers the support), or one
    /// of radius `support` built here, for a solid restored but not
    /// stepped since.
    pub(in crate::solid) fn or_built(&self, support: Real, rest: &[Vector]) -> Cow<'_, KdTree> {
        match self.built() {
            Some(tree) => Cow::Borrowed(tree),
            None => {
                let mut tree = KdTree::new(support);
                tree.rebuild(rest);
                Cow::Owned(tree)
            }
        }
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
    /// Per topology edge, the term the cracks added to its normalised
    /// distance (0 where none crossed, infinite where one cut the pair).
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
    /// Fronts that branched (each a crack started at its tip, not
    /// counted in `started`).
    pub branched: u32,
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

/// An upper bound of a state's largest principal Cauchy stress, a fifth
/// of the work of the stress itself and as tight for small strains: with
/// `F = I + D`, `|F S F^T / J|_2 <= |F|_2^2 |S|_2 / J <= (1 + |D|_F)^2
/// |S|_F / J` (where `J <= 0`, [`cauchy`] is `S` itself, bounded by
/// `|S|_F`).
pub fn stress_bound(state: &StressState) -> Real {
    let s = state.s.norm();
    if state.det <= 0.0 {
        return s;
    }
    let stretch = 1.0 + (state.f - Matrix3::identity()).norm();
    stretch * stretch * s / state.det
}

/// The largest principal value alone of a symmetric matrix's leading
/// `dim` block, in closed form (what the scan for new cracks asks of every
/// particle past the bound, where [`principal`]'s iterative decomposition
/// cost it tens of microseconds a step): in 2D the larger root of the
/// block's characteristic quadratic, in 3D Smith's trigonometric solution
/// of the cubic (Smith 1961, Comm. ACM 4(4), 168), exact to rounding
/// except near a repeated value, where it keeps about eight digits.
pub fn largest_principal(dim: usize, m: &Matrix3<Real>) -> Real {
    if dim == 2 {
        let (a, b, d) = (m[(0, 0)], 0.5 * (m[(0, 1)] + m[(1, 0)]), m[(1, 1)]);
        let half = 0.5 * (a - d);
        return 0.5 * (a + d) + half.hypot(b);
    }
    let sym = (m + m.transpose()) * 0.5;
    let off = sym[(0, 1)].powi(2) + sym[(0, 2)].powi(2) + sym[(1, 2)].powi(2);
    if off == 0.0 {
        return sym[(0, 0)].max(sym[(1, 1)]).max(sym[(2, 2)]);
    }
    let q = sym.trace() / 3.0;
    let diagonal: Real = (0..3).map(|k| (sym[(k, k)] - q).powi(2)).sum();
    let p = ((diagonal + 2.0 * off) / 6.0).sqrt();
    let b = (sym - Matrix3::identity() * q) / p;
    let r = (0.5 * b.determinant()).clamp(-1.0, 1.0);
    q + 2.0 * p * (r.acos() / 3.0).cos()
}

/// Eq. 70's weight profile for [`Topology::reweigh`]: the solid's MLS
/// weight at the lengthened distance.
///
/// [`Topology::reweigh`]: super::topology::Topology::reweigh
pub(in crate::solid) fn lengthened(mls: &Mls) -> impl Fn(Real, Real) -> Option<Real> + use<> {
    let kernel = mls.params().weight;
    move |q, extra| transparent_weight(kernel, q, extra)
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
            skin: SkinCache::default(),
        }
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

    /// Crack vertices held.
    pub fn vertex_count(&self) -> usize {
        self.cracks.iter().map(|c| c.vertices().len()).sum()
    }
}
