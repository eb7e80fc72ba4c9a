//! The octree discretisation of an implicit solid (Guo–Qin, Section
//! 4.1.1): a 2:1-balanced octree adapted to the surface, its terminal
//! octants classified interior (I), exterior (E), interior boundary (IB)
//! or exterior boundary (EB), one node per I, IB and EB octant, and the
//! cubic supports of the nodes with the O(1) lookup of those covering a
//! point.
//!
//! **Construction.** The root is a cube of side `cell * 2^depth` whose
//! lower corner is half a cell below the surface's, `depth` the least
//! that covers the surface, so that octants at the surface have side
//! `cell` and the faces of a box whose sides are multiples of `cell` run
//! through octant centres: nodes then sit on those faces. Had the faces
//! run along octant boundaries instead, a point on one would be covered
//! by a single layer of nodes in the normal direction (the weight of Eq.
//! 13 vanishes at the edge of a support of `alpha = 3`), and no linear
//! basis could be fitted there — the embedded surface and the clamped
//! faces are exactly such points. An octant is split
//! while it is coarser than `cell` and the surface may cross it
//! (`|d(centre)| < ` half its diagonal), or while it is more than
//! `interior_levels` levels coarser than `cell`. Then the tree is balanced
//! so that no leaf has a face or edge neighbour more than one level
//! coarser or finer (the paper's "one level adjusted octree"): this bounds
//! how far a support reaches into its neighbours and keeps every point
//! under enough supports (the patch covering condition, Eq. 8).
//!
//! **Classification** reads the signed distance at the eight corners and
//! the centre: all inside (`<= 0`) is I, all outside is E, a mix is a
//! boundary octant, IB when its centre is inside and EB when outside.
//! The EB node is the projection of the centre onto the surface, so that
//! every node lies in the solid.
//!
//! **Lookup.** Octants are keyed by level and integer coordinates in a
//! hash map, so a neighbour at any level is one probe away (the role of
//! the paper's face-neighbour links, without pointers to keep
//! consistent). For each leaf the nodes whose supports overlap it are
//! listed once, by descending the tree through the octants each support
//! overlaps; a point then finds its leaf in `depth` probes and its
//! covering supports among that leaf's list: O(1) for a bounded depth.

use super::ImplicitSurface;
use crate::cancel::Cancel;
use crate::math::{Brief, Real, Vector};
use std::collections::HashMap;

/// Deepest octree accepted: 2^16 octants along an axis, far past what
/// memory allows for a volume, and a bound on every coordinate.
pub const MAX_DEPTH: u32 = 16;

/// Most terminal octants a build may create, counted as it goes so that a
/// too fine request fails before it exhausts memory.
pub const MAX_OCTANTS: usize = 4_000_000;

/// Octants (or nodes) handled between two reads of the cancel flag: a
/// few milliseconds of work at most.
const CHECK_EVERY: usize = 1024;

/// How an octree is cut.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OctreeParams {
    /// Side of the terminal octants at the surface (length unit of the
    /// surface).
    pub cell: Real,
    /// How many levels coarser than `cell` an interior octant may stay:
    /// 0 cuts the whole solid at `cell` (uniform), more saves nodes deep
    /// inside.
    pub interior_levels: u32,
    /// Side of a node's cubic support over the side of its octant
    /// (Section 4.1.1; 3 covers every point of a uniform region by 27
    /// supports, more than the 4 a linear basis needs).
    pub alpha: Real,
}

/// The class of a terminal octant (Section 4.1.1, Fig. 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OctantKind {
    /// Wholly inside the solid.
    Interior,
    /// Wholly outside: no node, no quadrature.
    Exterior,
    /// Crossed by the surface, centre inside.
    InteriorBoundary,
    /// Crossed by the surface, centre outside: its node is projected onto
    /// the surface.
    ExteriorBoundary,
}

/// A terminal octant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Octant {
    /// Depth below the root (0 is the root).
    pub level: u32,
    /// Integer coordinates at that level.
    pub coords: [u32; 3],
    /// Its class.
    pub kind: OctantKind,
    /// Lower corner.
    pub min: Vector,
    /// Side length.
    pub size: Real,
}

impl Octant {
    /// The octant's centre.
    pub fn centre(&self) -> Vector {
        self.min + Vector::repeat(0.5 * self.size)
    }
}

/// A simulation node: where its shape function is centred and how far
/// its support reaches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Node {
    /// Rest position.
    pub position: Vector,
    /// Half the side of its cubic support, `alpha * size / 2`.
    pub half_width: Real,
    /// The leaf it was placed in.
    pub octant: u32,
}

/// Why an octree could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OctreeError {
    /// A parameter is out of range.
    #[error("octree `{field}` is {value}; {message}")]
    InvalidParameter {
        /// The parameter.
        field: &'static str,
        /// Its value, briefly.
        value: String,
        /// What to use instead.
        message: &'static str,
    },
    /// The surface's bounds are empty or not finite.
    #[error("the surface's bounding box is empty or not finite; check the input surface")]
    BadBounds,
    /// `cell` is so small against the surface that the tree would be
    /// deeper than [`MAX_DEPTH`] or hold more than [`MAX_OCTANTS`] leaves.
    #[error(
        "an octree with cells of {cell} over a surface {extent} across needs {what}; \
         use a larger cell (a smaller depth)"
    )]
    TooFine {
        /// The requested cell size.
        cell: Brief,
        /// The surface's largest extent.
        extent: Brief,
        /// What it would need.
        what: String,
    },
    /// No octant lies inside the surface.
    #[error(
        "no octant of side {cell} lies inside the surface: the solid is thinner than a cell; \
         use a smaller cell (a larger depth)"
    )]
    Empty {
        /// The cell size.
        cell: Brief,
    },
    /// The build was cancelled.
    #[error("the octree build was cancelled")]
    Cancelled,
}

/// Key of an octant: level and coordinates packed in 64 bits (5 + 3 x 19).
fn key(level: u32, c: [u32; 3]) -> u64 {
    (u64::from(level) << 57) | (u64::from(c[0]) << 38) | (u64::from(c[1]) << 19) | u64::from(c[2])
}

/// What the map holds at an octant's key.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Slot {
    /// Split: its children are in the map.
    Inner,
    /// A terminal octant: index into `leaves`.
    Leaf(u32),
}

/// A balanced, classified octree over an implicit solid with its nodes
/// and supports.
#[derive(Debug, Clone)]
pub struct Octree {
    origin: Vector,
    root: Real,
    depth: u32,
    alpha: Real,
    slots: HashMap<u64, Slot>,
    leaves: Vec<Octant>,
    nodes: Vec<Node>,
    /// Per leaf, the nodes whose supports overlap it (CSR).
    candidate_offsets: Vec<u32>,
    candidates: Vec<u32>,
}

impl Octree {
    /// Cuts, balances and classifies the octree of `surface`, places its
    /// nodes and lists its supports. Checks `cancel` as it goes.
    ///
    /// # Errors
    /// [`OctreeError`] for bad parameters, a surface without extent, a
    /// tree too fine for the bounds above, a solid with no node, or
    /// cancellation.
    pub fn build(
        surface: &dyn ImplicitSurface,
        params: &OctreeParams,
        cancel: &Cancel,
    ) -> Result<Self, OctreeError> {
        if !(params.cell.is_finite() && params.cell > 0.0) {
            return Err(OctreeError::InvalidParameter {
                field: "cell",
                value: Brief(params.cell).to_string(),
                message: "the cell size must be positive and finite",
            });
        }
        if !(params.alpha.is_finite() && (1.0..=8.0).contains(&params.alpha)) {
            return Err(OctreeError::InvalidParameter {
                field: "alpha",
                value: Brief(params.alpha).to_string(),
                message: "the support must span 1 to 8 octants; 3 covers every point by 27 supports",
            });
        }
        let (min, max) = surface.bounds();
        let extent = (max - min).max();
        if !(min.iter().chain(max.iter()).all(|v| v.is_finite()) && extent > 0.0) {
            return Err(OctreeError::BadBounds);
        }
        let too_fine = |what: String| OctreeError::TooFine {
            cell: Brief(params.cell),
            extent: Brief(extent),
            what,
        };
        // The least depth whose root covers the extent and the half
        // cells on either side.
        let levels = (extent / params.cell + 1.0).log2().ceil().max(0.0);
        if levels > MAX_DEPTH as Real {
            return Err(too_fine(format!("depth {levels}, more than {MAX_DEPTH}")));
        }
        let depth = levels as u32;
        if params.interior_levels > depth {
            return Err(OctreeError::InvalidParameter {
                field: "interior_levels",
                value: params.interior_levels.to_string(),
                message: "it cannot exceed the depth of the tree; 0 cuts the solid uniformly",
            });
        }
        let mut tree = Self {
            origin: min - Vector::repeat(0.5 * params.cell),
            root: params.cell * (1u64 << depth) as Real,
            depth,
            alpha: params.alpha,
            slots: HashMap::new(),
            leaves: Vec::new(),
            nodes: Vec::new(),
            candidate_offsets: Vec::new(),
            candidates: Vec::new(),
        };
        let coarsest = depth - params.interior_levels;
        tree.refine(surface, coarsest, cancel, &too_fine)?;
        tree.balance(surface, cancel, &too_fine)?;
        tree.place_nodes(surface);
        if tree.nodes.is_empty() {
            return Err(OctreeError::Empty {
                cell: Brief(params.cell),
            });
        }
        tree.list_candidates(cancel)?;
        Ok(tree)
    }

    /// Side of an octant at `level`.
    fn size(&self, level: u32) -> Real {
        self.root / (1u64 << level) as Real
    }

    fn octant(&self, surface: &dyn ImplicitSurface, level: u32, coords: [u32; 3]) -> Octant {
        let size = self.size(level);
        let min = self.origin
            + Vector::new(coords[0] as Real, coords[1] as Real, coords[2] as Real) * size;
        let mut octant = Octant {
            level,
            coords,
            kind: OctantKind::Exterior,
            min,
            size,
        };
        octant.kind = classify(surface, &octant);
        octant
    }

    /// Top-down subdivision from the root (Section 4.1.1).
    fn refine(
        &mut self,
        surface: &dyn ImplicitSurface,
        coarsest: u32,
        cancel: &Cancel,
        too_fine: &dyn Fn(String) -> OctreeError,
    ) -> Result<(), OctreeError> {
        let mut stack = vec![(0u32, [0u32; 3])];
        // Counted octants, not the stack's length: a depth-first stack
        // stays short, so its length rarely meets a multiple.
        let mut visited = 0usize;
        while let Some((level, coords)) = stack.pop() {
            visited += 1;
            if visited.is_multiple_of(CHECK_EVERY) {
                cancel.check().map_err(|_| OctreeError::Cancelled)?;
            }
            let size = self.size(level);
            let min = self.origin
                + Vector::new(coords[0] as Real, coords[1] as Real, coords[2] as Real) * size;
            let centre = min + Vector::repeat(0.5 * size);
            let d = surface.signed_distance(&centre);
            let half_diagonal = 0.5 * 3f64.sqrt() * size;
            let near_surface = d.abs() < half_diagonal;
            let split =
                level < self.depth && (level < coarsest && d < half_diagonal || near_surface);
            if split {
                self.slots.insert(key(level, coords), Slot::Inner);
                for child in children(coords) {
                    stack.push((level + 1, child));
                }
            } else {
                self.add_leaf(self.octant(surface, level, coords), too_fine)?;
            }
        }
        Ok(())
    }

    fn add_leaf(
        &mut self,
        octant: Octant,
        too_fine: &dyn Fn(String) -> OctreeError,
    ) -> Result<(), OctreeError> {
        if self.leaves.len() >= MAX_OCTANTS {
            return Err(too_fine(format!("more than {MAX_OCTANTS} octants")));
        }
        let index = self.leaves.len() as u32;
        self.slots
            .insert(key(octant.level, octant.coords), Slot::Leaf(index));
        self.leaves.push(octant);
        Ok(())
    }

    /// The leaf holding the cell `(level, coords)`, at that level or
    /// coarser, if any.
    fn leaf_covering(&self, level: u32, coords: [u32; 3]) -> Option<u32> {
        (0..=level).rev().find_map(|l| {
            let shift = level - l;
            match self.slots.get(&key(l, coords.map(|c| c >> shift)))? {
                Slot::Leaf(i) => Some(*i),
                Slot::Inner => None,
            }
        })
    }

    /// Splits leaves until no two non-exterior leaves that share a face
    /// or an edge differ by more than one level.
    fn balance(
        &mut self,
        surface: &dyn ImplicitSurface,
        cancel: &Cancel,
        too_fine: &dyn Fn(String) -> OctreeError,
    ) -> Result<(), OctreeError> {
        let mut queue: Vec<u32> = (0..self.leaves.len() as u32).collect();
        let cells = 1i64 << self.depth;
        let mut visited = 0usize;
        while let Some(i) = queue.pop() {
            visited += 1;
            if visited.is_multiple_of(CHECK_EVERY) {
                cancel.check().map_err(|_| OctreeError::Cancelled)?;
            }
            let leaf = self.leaves[i as usize];
            // A leaf already split (its slot now inner) has no say.
            if leaf.kind == OctantKind::Exterior
                || self.slots.get(&key(leaf.level, leaf.coords)) != Some(&Slot::Leaf(i))
                || leaf.level < 2
            {
                continue;
            }
            let span = 1i64 << (self.depth - leaf.level);
            for offset in FACE_AND_EDGE_OFFSETS {
                let c: [i64; 3] = std::array::from_fn(|k| i64::from(leaf.coords[k]) + offset[k]);
                if c.iter().any(|&v| v < 0 || v * span >= cells) {
                    continue;
                }
                let c = c.map(|v| v as u32);
                let Some(j) = self.leaf_covering(leaf.level, c) else {
                    continue;
                };
                let neighbour = self.leaves[j as usize];
                if neighbour.level + 1 < leaf.level && neighbour.kind != OctantKind::Exterior {
                    let split = self.split(surface, j, too_fine)?;
                    queue.extend(split);
                    queue.push(i);
                }
            }
        }
        // Drop the leaves that were split.
        let mut kept = Vec::with_capacity(self.leaves.len());
        for (i, leaf) in self.leaves.iter().enumerate() {
            if self.slots.get(&key(leaf.level, leaf.coords)) == Some(&Slot::Leaf(i as u32)) {
                kept.push(*leaf);
            }
        }
        self.leaves = kept;
        for (i, leaf) in self.leaves.iter().enumerate() {
            self.slots
                .insert(key(leaf.level, leaf.coords), Slot::Leaf(i as u32));
        }
        Ok(())
    }

    /// Splits leaf `i` into its eight children; returns their indices.
    fn split(
        &mut self,
        surface: &dyn ImplicitSurface,
        i: u32,
        too_fine: &dyn Fn(String) -> OctreeError,
    ) -> Result<Vec<u32>, OctreeError> {
        let leaf = self.leaves[i as usize];
        self.slots.insert(key(leaf.level, leaf.coords), Slot::Inner);
        let mut added = Vec::with_capacity(8);
        for child in children(leaf.coords) {
            added.push(self.leaves.len() as u32);
            self.add_leaf(self.octant(surface, leaf.level + 1, child), too_fine)?;
        }
        Ok(added)
    }

    fn place_nodes(&mut self, surface: &dyn ImplicitSurface) {
        for (i, leaf) in self.leaves.iter().enumerate() {
            let position = match leaf.kind {
                OctantKind::Exterior => continue,
                OctantKind::Interior | OctantKind::InteriorBoundary => leaf.centre(),
                OctantKind::ExteriorBoundary => surface.project(&leaf.centre()),
            };
            self.nodes.push(Node {
                position,
                half_width: 0.5 * self.alpha * leaf.size,
                octant: i as u32,
            });
        }
    }

    /// For each leaf, the nodes whose supports overlap it, found by
    /// descending from the root through the octants each support box
    /// overlaps.
    fn list_candidates(&mut self, cancel: &Cancel) -> Result<(), OctreeError> {
        let mut per_leaf: Vec<Vec<u32>> = vec![Vec::new(); self.leaves.len()];
        let mut stack = Vec::new();
        for (n, node) in self.nodes.iter().enumerate() {
            if n.is_multiple_of(CHECK_EVERY) {
                cancel.check().map_err(|_| OctreeError::Cancelled)?;
            }
            let lo = node.position - Vector::repeat(node.half_width);
            let hi = node.position + Vector::repeat(node.half_width);
            stack.clear();
            stack.push((0u32, [0u32; 3]));
            while let Some((level, coords)) = stack.pop() {
                let size = self.size(level);
                let min = self.origin
                    + Vector::new(coords[0] as Real, coords[1] as Real, coords[2] as Real) * size;
                let overlaps = (0..3).all(|k| min[k] < hi[k] && min[k] + size > lo[k]);
                if !overlaps {
                    continue;
                }
                match self.slots.get(&key(level, coords)) {
                    Some(Slot::Leaf(i))
                        if self.leaves[*i as usize].kind != OctantKind::Exterior =>
                    {
                        per_leaf[*i as usize].push(n as u32);
                    }
                    Some(Slot::Inner) => {
                        stack.extend(children(coords).map(|c| (level + 1, c)));
                    }
                    Some(Slot::Leaf(_)) | None => {}
                }
            }
        }
        self.candidate_offsets = Vec::with_capacity(per_leaf.len() + 1);
        self.candidate_offsets.push(0);
        for list in per_leaf {
            self.candidates.extend(list);
            self.candidate_offsets.push(self.candidates.len() as u32);
        }
        Ok(())
    }

    /// The terminal octants, exterior ones included.
    pub fn leaves(&self) -> &[Octant] {
        &self.leaves
    }

    /// The nodes, in leaf order.
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    /// Support side over octant side.
    pub fn alpha(&self) -> Real {
        self.alpha
    }

    /// The leaf holding `p`, or `None` outside the root cube. A point on a
    /// face, edge or corner shared by several leaves lies in each of them;
    /// it is given a non-exterior one where there is one, because only
    /// those list candidate supports: a point of the solid on the face
    /// between an interior octant and an exterior one is covered from the
    /// interior side, and would read as covered by nothing from the
    /// exterior side. Off shared faces, the one leaf holding it.
    pub fn leaf_at(&self, p: &Vector) -> Option<u32> {
        let cells = 1u32 << self.depth;
        // Per axis, the finest cell holding `p` and, on a face between two
        // of them, the one below as well.
        let mut options = [[0u32; 2]; 3];
        for k in 0..3 {
            let t = (p[k] - self.origin[k]) / self.root * cells as Real;
            if !(t >= 0.0 && t <= cells as Real) {
                return None;
            }
            let c = (t as u32).min(cells - 1);
            options[k] = [c, if c > 0 && c as Real == t { c - 1 } else { c }];
        }
        let mut exterior = None;
        for pick in 0..8usize {
            // Each choice of a lower cell once: skip the repeats of axes
            // with only one.
            if (0..3).any(|k| pick >> k & 1 == 1 && options[k][0] == options[k][1]) {
                continue;
            }
            let coords: [u32; 3] = std::array::from_fn(|k| options[k][pick >> k & 1]);
            let Some(leaf) = self.leaf_covering(self.depth, coords) else {
                continue;
            };
            if self.leaves[leaf as usize].kind != OctantKind::Exterior {
                return Some(leaf);
            }
            exterior.get_or_insert(leaf);
        }
        exterior
    }

    /// The nodes whose supports may cover points of leaf `leaf`: a
    /// superset of those that do, to be filtered by the weight.
    pub fn candidates(&self, leaf: u32) -> &[u32] {
        let i = leaf as usize;
        &self.candidates[self.candidate_offsets[i] as usize..self.candidate_offsets[i + 1] as usize]
    }

    /// The bytes it holds, counted from its arrays: the leaves, the
    /// nodes, the candidate lists and the octant map (a key, a slot and
    /// hashbrown's control byte per entry, at its 7/8 load).
    pub fn bytes(&self) -> usize {
        use std::mem::size_of;
        self.leaves.len() * size_of::<Octant>()
            + self.nodes.len() * size_of::<Node>()
            + (self.candidates.len() + self.candidate_offsets.len()) * size_of::<u32>()
            + self.slots.capacity() * (size_of::<(u64, Slot)>() + 1)
    }

    /// Counts of terminal octants by class: `[I, E, IB, EB]`.
    pub fn census(&self) -> [usize; 4] {
        let mut counts = [0; 4];
        for leaf in &self.leaves {
            counts[match leaf.kind {
                OctantKind::Interior => 0,
                OctantKind::Exterior => 1,
                OctantKind::InteriorBoundary => 2,
                OctantKind::ExteriorBoundary => 3,
            }] += 1;
        }
        counts
    }
}

/// The eight children's coordinates one level down.
fn children(c: [u32; 3]) -> [[u32; 3]; 8] {
    std::array::from_fn(|i| {
        [
            2 * c[0] + (i as u32 & 1),
            2 * c[1] + ((i as u32 >> 1) & 1),
            2 * c[2] + ((i as u32 >> 2) & 1),
        ]
    })
}

/// The 6 face and 12 edge neighbours' offsets.
const FACE_AND_EDGE_OFFSETS: [[i64; 3]; 18] = [
    [-1, 0, 0],
    [1, 0, 0],
    [0, -1, 0],
    [0, 1, 0],
    [0, 0, -1],
    [0, 0, 1],
    [-1, -1, 0],
    [-1, 1, 0],
    [1, -1, 0],
    [1, 1, 0],
    [-1, 0, -1],
    [-1, 0, 1],
    [1, 0, -1],
    [1, 0, 1],
    [0, -1, -1],
    [0, -1, 1],
    [0, 1, -1],
    [0, 1, 1],
];

/// I, E, IB or EB from the signs at the corners and the centre. A point
/// within round-off of the surface counts as inside: corners and centres
/// on a face of the solid are its points.
fn classify(surface: &dyn ImplicitSurface, octant: &Octant) -> OctantKind {
    let tolerance = 1e-9 * octant.size;
    let inside_at = |p: &Vector| surface.signed_distance(p) <= tolerance;
    let centre_inside = inside_at(&octant.centre());
    let mut inside = usize::from(centre_inside);
    for i in 0..8 {
        let corner = octant.min
            + Vector::new(
                (i & 1) as Real,
                ((i >> 1) & 1) as Real,
                ((i >> 2) & 1) as Real,
            ) * octant.size;
        inside += usize::from(inside_at(&corner));
    }
    match (inside, centre_inside) {
        (9, _) => OctantKind::Interior,
        (0, _) => OctantKind::Exterior,
        (_, true) => OctantKind::InteriorBoundary,
        (_, false) => OctantKind::ExteriorBoundary,
    }
}

#[cfg(test)]
mod tests;
