//! Each fragment's own closed surface, once a solid has cracked in pieces
//! (tutorial Section 7.3, Figure 12: the surface "follows the fragments and
//! gets new faces on the crack surfaces").
//!
//! Cutting the embedded triangle mesh along the cracks and capping every
//! cut with the crack's faces would need a robust mesh boolean per step;
//! instead each fragment's surface is the zero level set of a field on a
//! regular grid in reference coordinates, extracted by marching cubes,
//! which is closed by construction wherever the field is positive on the
//! grid's border. The field of fragment `f` at a node `X` is
//! `max(d_body(X), c_f(X))`: `d_body` the signed distance to the solid's
//! reference surface (negative inside), and `c_f` negative where the
//! material that `X` sees belongs to `f`, positive elsewhere. The material
//! a node sees is its nearest particle within the support that no crack
//! hides from it (the visibility criterion, as the crack faces use), so two
//! neighbouring nodes on either side of a crack belong to the fragments on
//! either side. Where they differ, `|c|` at each is its distance along the
//! grid edge to the crack (`Crack::crossing`), so the level set passes
//! through the crack itself, not midway between the nodes; away from a
//! crack `|c|` is one cell.
//!
//! Vertices then move with their own fragment: the Shepard mean of the
//! displacements of that fragment's particles within the support that see
//! a point a quarter spacing inside the vertex through no crack (a vertex
//! of a crack face lies on the crack itself), so a fragment's surface
//! never follows the material across a crack, and two fragments that fly
//! apart leave two closed surfaces. Where a crack's edge stops short of
//! the body's surface, a few vertices of a fragment lie across the crack
//! from its particles and see none of them: each moves with the nearest
//! particle of its fragment, seen or not (left in place, they drew a
//! tongue of surface back to where the bar had been). The grid cell is
//! `surface_cell` spacings (half a spacing unless the scene says):
//! finer than the particles that carry the motion, and as fine as a
//! subdivided embedded surface (which the solid keeps while it is in one
//! piece) only at a cost growing as the cell's inverse cube.

use super::Fracture;
use crate::approx::KernelKind;
use crate::geometry::{MeshSdf, TriMesh, vertex_normals};
use crate::math::{Real, Vector};
use crate::neighbors::{CandidateSearch, KdTree};
use crate::surface::{NodeGrid, extract};
use rayon::prelude::*;
use std::hash::{DefaultHasher, Hash, Hasher};
use std::sync::Mutex;

/// No fragment: a node that sees no particle.
const NONE: u32 = u32::MAX;

/// The most grid nodes a fragment surface takes; past it the cell grows
/// until the grid fits, so a huge solid's surface costs bounded memory.
const MAX_NODES: usize = 8_000_000;

/// Each fragment's closed surface, deformed, one mesh with every fragment's
/// component, and unit vertex normals; `None` while the solid is in one
/// piece (it keeps its embedded surface then). The reference surface and
/// each vertex's weights are kept in `fracture`'s cache until the cracks,
/// the fragments or the particles change, so a frame between such changes
/// costs one weighted sum per vertex.
pub(in crate::solid) fn fragment_surfaces(
    fracture: &Fracture,
    outline: &MeshSdf,
    rest: &[Vector],
    positions: &[Vector],
    spacing: Real,
    support: Real,
) -> Option<(TriMesh, Vec<Vector>)> {
    if fracture.fragment_count < 2 || fracture.fragments.len() != rest.len() {
        return None;
    }
    let key = fingerprint(fracture, outline, rest.len());
    let mut cache = fracture.skin.0.lock().unwrap_or_else(|e| e.into_inner());
    if cache.as_ref().is_none_or(|skin| skin.key != key) {
        *cache = Some(Skin::build(fracture, outline, rest, spacing, support, key));
    }
    let skin = cache.as_ref()?;
    let vertices: Vec<Vector> = skin
        .reference
        .par_iter()
        .enumerate()
        .map(|(v, x)| {
            let range = skin.offsets[v] as usize..skin.offsets[v + 1] as usize;
            x + skin.particles[range.clone()]
                .iter()
                .zip(&skin.weights[range])
                .map(|(&j, &w)| (positions[j as usize] - rest[j as usize]) * w)
                .sum::<Vector>()
        })
        .collect();
    let normals = vertex_normals(&skin.triangles, &vertices);
    Some((
        TriMesh {
            vertices,
            triangles: skin.triangles.clone(),
        },
        normals,
    ))
}

/// What identifies a reference skin: the fragments, the cracks' geometry,
/// the particle count and the outline's box.
fn fingerprint(fracture: &Fracture, outline: &MeshSdf, particles: usize) -> u64 {
    let mut h = DefaultHasher::new();
    (particles, fracture.fragment_count, &fracture.fragments).hash(&mut h);
    let (lo, hi) = outline.bounds();
    for x in [lo, hi] {
        x.iter().for_each(|c| c.to_bits().hash(&mut h));
    }
    for crack in &fracture.cracks {
        crack.triangles().hash(&mut h);
        for x in crack.vertices() {
            x.iter().for_each(|c| c.to_bits().hash(&mut h));
        }
    }
    h.finish()
}

/// The fragments' surfaces in reference coordinates, and each vertex's
/// particles with their normalised weights (CSR).
struct Skin {
    key: u64,
    reference: Vec<Vector>,
    triangles: Vec<[u32; 3]>,
    offsets: Vec<u32>,
    particles: Vec<u32>,
    weights: Vec<Real>,
}

/// The last reference skin of a fracturing solid: a cache, not state, so
/// it takes no part in comparisons and snapshots, and a clone starts
/// empty.
#[derive(Default)]
pub(in crate::solid) struct SkinCache(Mutex<Option<Skin>>);

impl Clone for SkinCache {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl PartialEq for SkinCache {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl std::fmt::Debug for SkinCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SkinCache")
    }
}

impl Skin {
    fn build(
        fracture: &Fracture,
        outline: &MeshSdf,
        rest: &[Vector],
        spacing: Real,
        support: Real,
        key: u64,
    ) -> Skin {
        let search = fracture.search.or_built(support, rest);
        let search = &*search;
        let grid = Grid::around(outline, fracture.params.surface_cell * spacing);
        let labels: Vec<u32> = (0..grid.len())
            .into_par_iter()
            .map(|n| {
                nearest(
                    fracture,
                    search,
                    rest,
                    &grid.position(n),
                    support,
                    None,
                    true,
                )
                .map_or(NONE, |j| fracture.fragments[j])
            })
            .collect();
        let body: Vec<Real> = (0..grid.len())
            .into_par_iter()
            .map(|n| outline.distance(&grid.position(n)))
            .collect();
        // Distance along the grid to the crack between differently
        // labelled neighbours; one cell elsewhere.
        let reach: Vec<Real> = (0..grid.len())
            .into_par_iter()
            .map(|n| {
                let x = grid.position(n);
                grid.neighbours(n)
                    .filter(|&m| labels[m] != labels[n])
                    .filter_map(|m| {
                        let y = grid.position(m);
                        fracture
                            .cracks
                            .iter()
                            .filter_map(|c| c.crossing(&x, &y))
                            .map(|c| (c.at - x).norm())
                            .min_by(Real::total_cmp)
                            // Differently labelled with no crack between
                            // (a node that sees nothing): midway.
                            .or(Some(0.5 * grid.cell))
                    })
                    .fold(grid.cell, Real::min)
            })
            .collect();

        // Each fragment's field on the box of nodes it labels, a node of
        // margin around it (outside, every other node is outside the
        // fragment anyway): the work follows the nodes, not the nodes
        // times the fragments, so a solid in thousands of pieces costs
        // about what one in two does.
        let mut boxes = vec![([usize::MAX; 3], [0; 3]); fracture.fragment_count as usize];
        for (n, &f) in labels.iter().enumerate() {
            if let Some((lo, hi)) = boxes.get_mut(f as usize) {
                let at = grid.index(n);
                for a in 0..3 {
                    lo[a] = lo[a].min(at[a].saturating_sub(1));
                    hi[a] = hi[a].max((at[a] + 1).min(grid.dims[a] - 1));
                }
            }
        }
        let mut mesh = TriMesh::default();
        let mut owner = Vec::new();
        for (f, (lo, hi)) in (0..fracture.fragment_count).zip(boxes) {
            if lo[0] > hi[0] {
                // A fragment no node sees: too small for the grid.
                continue;
            }
            let dims = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
            let mut values = Vec::with_capacity(dims.iter().product());
            for k in lo[2]..=hi[2] {
                for j in lo[1]..=hi[1] {
                    for i in lo[0]..=hi[0] {
                        let n = grid.node([i, j, k]);
                        let c = if labels[n] == f { -reach[n] } else { reach[n] };
                        // `extract` takes corners above the iso value as
                        // inside.
                        values.push(-(body[n].max(c)) as f32);
                    }
                }
            }
            let origin = grid.position(grid.node(lo));
            let part = extract(
                &NodeGrid {
                    origin,
                    cell: grid.cell,
                    dims,
                    values,
                },
                0.0,
            );
            let first = mesh.vertices.len() as u32;
            owner.extend(std::iter::repeat_n(f, part.vertices.len()));
            mesh.vertices.extend(part.vertices);
            mesh.triangles
                .extend(part.triangles.iter().map(|t| t.map(|v| v + first)));
        }
        // A vertex on a crack face lies on the crack, where visibility is a
        // coin toss: each moves as the material a quarter spacing inside it.
        let inward = vertex_normals(&mesh.triangles, &mesh.vertices);
        let weights: Vec<Vec<(u32, Real)>> = (mesh.vertices.par_iter().zip(inward.par_iter()))
            .zip(owner.par_iter())
            .map(|((x, n), &f)| {
                let probe = x - n * (0.25 * spacing);
                let shepard = shepard(fracture, search, rest, &probe, support, f);
                if shepard.is_empty() {
                    // Seen by none of its piece within the support (the
                    // Shepard weights are positive wherever one is): the
                    // nearest of them, seen or not (module documentation).
                    nearest(fracture, search, rest, &probe, support, Some(f), false)
                        .map(|j| vec![(j as u32, 1.0)])
                        .unwrap_or_default()
                } else {
                    shepard
                }
            })
            .collect();
        let mut offsets = Vec::with_capacity(weights.len() + 1);
        offsets.push(0);
        let (mut particles, mut values) = (Vec::new(), Vec::new());
        for list in weights {
            for (j, w) in list {
                particles.push(j);
                values.push(w);
            }
            offsets.push(particles.len() as u32);
        }
        Skin {
            key,
            reference: mesh.vertices,
            triangles: mesh.triangles,
            offsets,
            particles,
            weights: values,
        }
    }
}

/// The nodes of a regular grid around the solid's reference surface,
/// x fastest, with a cell of margin past it on every side.
struct Grid {
    origin: Vector,
    cell: Real,
    dims: [usize; 3],
}

impl Grid {
    fn around(outline: &MeshSdf, cell: Real) -> Grid {
        let (lo, hi) = outline.bounds();
        let mut cell = cell;
        loop {
            let dims = [0, 1, 2].map(|k| ((hi[k] - lo[k]) / cell).ceil() as usize + 3);
            if dims.iter().product::<usize>() <= MAX_NODES {
                let origin = lo - Vector::repeat(cell);
                return Grid { origin, cell, dims };
            }
            cell *= 1.25;
        }
    }

    fn len(&self) -> usize {
        self.dims.iter().product()
    }

    /// Node `n`'s indices along the three axes.
    fn index(&self, n: usize) -> [usize; 3] {
        let [nx, ny, _] = self.dims;
        [n % nx, (n / nx) % ny, n / (nx * ny)]
    }

    /// The node at indices `at`.
    fn node(&self, at: [usize; 3]) -> usize {
        let [nx, ny, _] = self.dims;
        at[0] + nx * (at[1] + ny * at[2])
    }

    fn position(&self, n: usize) -> Vector {
        let [i, j, k] = self.index(n);
        self.origin + Vector::new(i as Real, j as Real, k as Real) * self.cell
    }

    /// The up to six nodes one cell from node `n`.
    fn neighbours(&self, n: usize) -> impl Iterator<Item = usize> + '_ {
        let [nx, ny, _] = self.dims;
        let stride = [1, nx, nx * ny];
        let at = self.index(n);
        let size = self.dims;
        (0..3).flat_map(move |a| {
            let down = (at[a] > 0).then(|| n - stride[a]);
            let up = (at[a] + 1 < size[a]).then(|| n + stride[a]);
            down.into_iter().chain(up)
        })
    }
}

/// Whether no crack cuts the segment from `a` to `b`.
fn visible(fracture: &Fracture, a: &Vector, b: &Vector) -> bool {
    fracture.cracks.iter().all(|c| c.crossing(a, b).is_none())
}

/// The particle nearest `x` within `support` (of fragment `only`, when
/// given) that, where `seen`, sees it through no crack.
fn nearest(
    fracture: &Fracture,
    search: &KdTree,
    rest: &[Vector],
    x: &Vector,
    support: Real,
    only: Option<u32>,
    seen: bool,
) -> Option<usize> {
    let mut near: Vec<(Real, usize)> = Vec::new();
    search.for_each_candidate(x, |j| {
        let j = j as usize;
        let d = (rest[j] - x).norm();
        if d < support && only.is_none_or(|f| fracture.fragments[j] == f) {
            near.push((d, j));
        }
    });
    near.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    near.into_iter()
        .map(|(_, j)| j)
        .find(|&j| !seen || visible(fracture, x, &rest[j]))
}

/// The Shepard weights at `x` of fragment `f`'s particles within `support`
/// that see it through no crack, normalised; empty when none does.
fn shepard(
    fracture: &Fracture,
    search: &KdTree,
    rest: &[Vector],
    x: &Vector,
    support: Real,
    f: u32,
) -> Vec<(u32, Real)> {
    let mut near = Vec::new();
    search.for_each_candidate(x, |j| {
        let q = (rest[j as usize] - x).norm() / support;
        let ju = j as usize;
        if q < 1.0 && fracture.fragments[ju] == f && visible(fracture, x, &rest[ju]) {
            near.push((j, KernelKind::Poly6.profile(q)[0]));
        }
    });
    let total: Real = near.iter().map(|(_, w)| w).sum();
    if total > 0.0 {
        near.iter_mut().for_each(|(_, w)| *w /= total);
        near
    } else {
        Vec::new()
    }
}
