//! The fixed connectivity of an elastic solid in material coordinates
//! (Lagrangian kernels, tutorial Section 7.1): neighbours, MLS gradient
//! weights, the normalised pair weights of the hourglass and damping
//! terms, and the reverse adjacency that lets forces be gathered in
//! parallel instead of scattered under locks.
//!
//! Built once from the reference positions, and again only when a
//! plastic solid re-bases its reference shape or a fracturing one
//! resamples (`solid/resampling.rs`), which gives particles radii of
//! their own.

use crate::approx::mls::{
    GradientKind, GradientWeights, LagrangianGradients, Mls, MlsError, Order,
};
use crate::approx::{Kernel, KernelKind};
use crate::math::{Real, Vector};
use crate::neighbors::{CandidateSearch, KdTree, NeighborList};

/// The largest condition number of the moment matrix a particle that
/// cracks cut keeps its gradient at, in `dim` dimensions: past it its
/// remaining neighbours (a sliver of a fragment, a few particles in a
/// line) resolve no gradient, and the estimate would turn the particle
/// inside out; it then drops to the constant order (no energy of its
/// own, elastic or hourglass) and moves as debris with whatever pairs
/// still hold it. A full lattice support has condition numbers of order
/// 10. In 3D a tenth of the 2D bound: at 1e3 the particles a tearing 3D
/// ductile bar left beside its cracks kept gradients fitted over
/// lopsided neighbourhoods, carried elastic energies a thousand times the
/// bar's mean, and blew it up within steps (`scenes/ductile_spin_3d.toml`
/// holds at 1e2); the 2D solids are validated at 1e3.
pub fn max_refit_condition(dim: usize) -> Real {
    if dim == 3 { 1e2 } else { 1e3 }
}

/// Directed edges `e = (i -> j)` for every `j` within `h` of `i` (itself
/// included, with zero weights), in CSR order of `i`.
#[derive(Debug, Clone, Default)]
pub struct Topology {
    pub gradients: LagrangianGradients,
    /// Owner `i` of each edge.
    pub owner: Vec<u32>,
    /// `X_j - X_i` of each edge, reference frame.
    pub rest_offset: Vec<Vector>,
    /// `w_ij / sum_k w_ik` (poly6 profile, self excluded).
    pub pair_weight: Vec<Real>,
    /// `sum_j g_ij` per particle.
    pub sum_g: Vec<Vector>,
    /// For each particle `k`, the edges `(i -> k)` that end at it.
    pub reverse_offsets: Vec<u32>,
    pub reverse_edges: Vec<u32>,
    /// `1 / h_ij` of each edge, `h_ij = (h_i + h_j) / 2` the pair's mean
    /// support radius (tutorial Section 3.1), once particles carry radii
    /// of their own (a resampled solid); `None` while every particle has
    /// the solid's support radius, so that a solid that never resamples
    /// computes what it did before radii existed, bit for bit.
    pub edge_inv_support: Option<Vec<Real>>,
}

impl Topology {
    /// The topology of particles at `rest` with an MLS gradient of `order`
    /// over support `h` in `dim` dimensions.
    ///
    /// # Errors
    /// [`MlsError`] for invalid MLS parameters.
    pub fn build(rest: &[Vector], dim: usize, order: Order, h: Real) -> Result<Self, MlsError> {
        let mls = Mls::new(dim, crate::approx::mls::MlsParams::new(order, h))?;
        let mut search = KdTree::new(h);
        search.rebuild(rest);
        let mut list = NeighborList::default();
        list.build(&search, rest, h);
        let gradients = LagrangianGradients::build(&mls, GradientKind::Direct, rest, &list)?;
        let weight = Kernel::new(KernelKind::Poly6, dim, h);
        Ok(Self::connect(gradients, rest, |_, r| weight.value(r), None))
    }

    /// The topology of particles at `rest` with support radii `radii`
    /// (tutorial Section 3.1: a pair interacts within its mean radius
    /// `h_ij = (h_i + h_j) / 2`, found by a search at the largest radius),
    /// every pair's weights cut by the cracks' terms `extra(i, j)` (Eq.
    /// 70; 0 where none crosses). `h` is the solid's support radius, the
    /// basis scale; particles whose remaining neighbours resolve no
    /// gradient drop to the constant order as [`Self::reweigh`] drops
    /// them.
    ///
    /// # Errors
    /// [`MlsError`] for invalid MLS parameters. Returns the topology and
    /// each edge's term.
    pub fn build_with_radii(
        rest: &[Vector],
        radii: &[Real],
        (dim, order, h): (usize, Order, Real),
        extra: impl Fn(usize, usize) -> Real,
        weight: impl Fn(Real, Real) -> Option<Real>,
    ) -> Result<(Self, Vec<Real>), MlsError> {
        let mls = Mls::new(dim, crate::approx::mls::MlsParams::new(order, h))?;
        let largest = radii.iter().copied().fold(0.0, Real::max);
        let mut search = KdTree::new(largest);
        search.rebuild(rest);
        let mut list = NeighborList::default();
        list.build(&search, rest, largest);
        list.retain(|i, j| {
            let mean = 0.5 * (radii[i] + radii[j as usize]);
            (rest[j as usize] - rest[i]).norm_squared() < mean * mean
        });
        let gradients = LagrangianGradients::build(&mls, GradientKind::Direct, rest, &list)?;
        let edges = gradients.neighbour_indices();
        let mut inv_support = vec![0.0; edges.len()];
        let mut terms = vec![0.0; edges.len()];
        for i in 0..rest.len() {
            for e in gradients.range(i) {
                let j = edges[e] as usize;
                inv_support[e] = 2.0 / (radii[i] + radii[j]);
                terms[e] = extra(i, j);
            }
        }
        let supports = inv_support.clone();
        let mut topology = Self::connect(
            gradients,
            rest,
            |e, r| Kernel::new(KernelKind::Poly6, dim, 1.0 / supports[e]).value(r),
            Some(inv_support),
        );
        let mut scratch = Reweigh::default();
        for i in 0..rest.len() {
            topology.reweigh(i, rest, &mls, &terms, &weight, &mut scratch);
        }
        Ok((topology, terms))
    }

    /// Owners, offsets, normalised pair weights (`pair(e, r)` before
    /// normalising), `sum_g` and the reverse adjacency of `gradients`.
    fn connect(
        gradients: LagrangianGradients,
        rest: &[Vector],
        pair: impl Fn(usize, Real) -> Real,
        edge_inv_support: Option<Vec<Real>>,
    ) -> Self {
        let n = rest.len();
        let edges = gradients.neighbour_indices();
        let mut owner = vec![0u32; edges.len()];
        let mut rest_offset = vec![Vector::zeros(); edges.len()];
        let mut pair_weight = vec![0.0; edges.len()];
        let mut sum_g = vec![Vector::zeros(); n];
        let g = gradients.all_weights();
        for i in 0..n {
            let range = gradients.range(i);
            let mut total = 0.0;
            for e in range.clone() {
                let j = edges[e] as usize;
                owner[e] = i as u32;
                rest_offset[e] = rest[j] - rest[i];
                sum_g[i] += g[e];
                if j != i {
                    pair_weight[e] = pair(e, rest_offset[e].norm());
                    total += pair_weight[e];
                }
            }
            if total > 0.0 {
                for w in &mut pair_weight[range] {
                    *w /= total;
                }
            }
        }

        let mut reverse_offsets = vec![0u32; n + 1];
        for &j in edges {
            reverse_offsets[j as usize + 1] += 1;
        }
        for k in 0..n {
            reverse_offsets[k + 1] += reverse_offsets[k];
        }
        let mut fill = reverse_offsets.clone();
        let mut reverse_edges = vec![0u32; edges.len()];
        for (e, &j) in edges.iter().enumerate() {
            reverse_edges[fill[j as usize] as usize] = e as u32;
            fill[j as usize] += 1;
        }
        Self {
            gradients,
            owner,
            rest_offset,
            pair_weight,
            sum_g,
            reverse_offsets,
            reverse_edges,
            edge_inv_support,
        }
    }

    /// Edge `e`'s normalised distance `|X_j - X_i| / h_ij`, with
    /// `inv_h = 1 / h` the solid's support radius where particles carry
    /// none of their own.
    #[inline]
    pub fn q(&self, e: usize, inv_h: Real) -> Real {
        let inv = self.edge_inv_support.as_ref().map_or(inv_h, |v| v[e]);
        self.rest_offset[e].norm() * inv
    }

    /// Recomputes particle `i`'s gradient weights, pair weights and
    /// `sum_g` with the weight profile `weight(q, extra[e])` of each edge
    /// `e` at normalised distance `q` (the fracturing solids pass tutorial
    /// Eq. 70, which lengthens the distance by `extra[e]`; `None` removes
    /// the pair): what a crack that passed near `i` changes. A pair with
    /// `extra[e] == 0` gets the weights `build` gave it, bit for bit. The
    /// edges themselves stay, so the reverse adjacency and any sparsity
    /// pattern built on it hold.
    pub fn reweigh(
        &mut self,
        i: usize,
        rest: &[Vector],
        mls: &Mls,
        extra: &[Real],
        weight: impl Fn(Real, Real) -> Option<Real>,
        scratch: &mut Reweigh,
    ) {
        let range = self.gradients.range(i);
        let first = range.start;
        let h = mls.params().h;
        let inv_h = 1.0 / h;
        let dim = mls.dim();
        let inv_support = self.edge_inv_support.as_deref();
        self.gradients.refit_direct(
            mls,
            i,
            rest,
            |k, d| {
                let r = d[..dim].iter().map(|v| v * v).sum::<Real>().sqrt();
                match inv_support {
                    None => weight(r * inv_h, extra[first + k]),
                    // The kernel of the pair's own radius, `W(q) / h_ij^d`,
                    // relative to the solid's.
                    Some(inv) => {
                        let inv = inv[first + k];
                        weight(r * inv, extra[first + k]).map(|w| w * (h * inv).powi(dim as i32))
                    }
                }
            },
            &mut scratch.weights,
            &mut scratch.nodes,
        );
        if self.gradients.conditions()[i] > max_refit_condition(dim) {
            self.gradients.clear(i);
        }
        let edges = self.gradients.neighbour_indices();
        // As `build` weighs the pairs, so that a pair no crack crosses
        // gets the same bits.
        let plain = Kernel::new(KernelKind::Poly6, dim, h);
        let mut total = 0.0;
        for e in range.clone() {
            if edges[e] as usize == i {
                self.pair_weight[e] = 0.0;
                continue;
            }
            let r = self.rest_offset[e].norm();
            self.pair_weight[e] = match self.edge_inv_support.as_deref() {
                None if extra[e] == 0.0 => plain.value(r),
                None => weight(r * inv_h, extra[e]).map_or(0.0, |w| w * plain.value(0.0)),
                Some(inv) => {
                    let own = Kernel::new(KernelKind::Poly6, dim, 1.0 / inv[e]);
                    weight(r * inv[e], extra[e]).map_or(0.0, |w| w * own.value(0.0))
                }
            };
            total += self.pair_weight[e];
        }
        if total > 0.0 {
            for w in &mut self.pair_weight[range.clone()] {
                *w /= total;
            }
        }
        if self.gradients.orders()[i] == Order::Constant {
            // No gradient, so `F_i = I` whatever the neighbours do: an
            // hourglass term measured against it would resist rotating
            // the debris (a torque from nothing). The particle keeps no
            // energy of its own.
            self.pair_weight[range.clone()].fill(0.0);
        }
        let g = self.gradients.all_weights();
        self.sum_g[i] = range.map(|e| g[e]).sum();
    }

    /// Edges `(i -> k)` ending at particle `k`.
    pub fn incoming(&self, k: usize) -> &[u32] {
        &self.reverse_edges[self.reverse_offsets[k] as usize..self.reverse_offsets[k + 1] as usize]
    }
}

/// Scratch memory of [`Topology::reweigh`], reused between particles.
#[derive(Debug, Default)]
pub struct Reweigh {
    weights: GradientWeights,
    nodes: Vec<Vector>,
}
