//! The surface of an oriented point cloud as a triangle mesh: the zero set
//! of the cloud's implicit moving-least-squares field
//! ([`PointSurface`], Shen et al. 2004, Kolluri 2008) meshed by marching
//! cubes on a regular grid. What a thin shell is cut into charts over when
//! its input is a scan rather than a mesh (Guo–Qin 4.2 take points with
//! normals as their input).
//!
//! Why through a surface and not by charting the points directly: the
//! atlas, the conformal maps, the seams and every shell test already stand
//! on triangle meshes, so a cloud gets all of them by one step that is
//! tested on its own. The mesh is only the parametric domain's carrier:
//! the shell streams the cloud's own points, embedded in the node shape
//! functions through the triangle under each, so the surface a user sees
//! is the input, not the mesh.
//!
//! **Open clouds.** The field goes on past an open cloud's rim (as the
//! plane of the nearest sample), so its zero set does too: triangles with
//! a corner farther than [`RIM_SPACINGS`] sample spacings from every
//! sample are taken off. The rim then lies within that distance beyond the
//! outermost samples, and a gap in the cloud wider than about twice it
//! opens a hole.
//!
//! **Clean-up.** A grid value within [`SNAP`] cells of zero is moved there
//! (keeping its sign), so no crossing falls on a grid node and no triangle
//! collapses to a point; a vertex whose triangles form several fans after
//! trimming is split, one copy per fan, so the mesh is a manifold; pieces
//! smaller than [`MIN_PIECE`] of the largest (sign errors from noisy
//! normals far from the samples) are dropped, and a cloud of several
//! comparable pieces is refused.

use super::field::NodeGrid;
use super::marching_cubes;
use crate::cancel::Cancel;
use crate::geometry::ImplicitSurface;
use crate::geometry::{
    PointCloudError, PointSurface, PointSurfaceParams, TriMesh, sorted_half_edges,
};
use crate::math::{Real, Vector, bounds};
use rayon::prelude::*;
use std::collections::HashMap;

/// Most grid nodes the field is evaluated on (4 Mi: each evaluation visits
/// some 40 samples, a few seconds in all on two cores).
pub const MAX_NODES: usize = 1 << 22;

/// How far past the samples, in median sample spacings, the zero set is
/// kept.
pub const RIM_SPACINGS: Real = 2.0;

/// Grid values closer to zero than this many cells are moved to it.
pub const SNAP: Real = 0.01;

/// Pieces with fewer triangles than this part of the largest are dropped;
/// larger ones make the cloud several surfaces.
pub const MIN_PIECE: Real = 0.1;

/// Why a cloud's surface could not be meshed. Each message says what to
/// change.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReconstructError {
    /// The cloud itself was refused.
    #[error(transparent)]
    Cloud(#[from] PointCloudError),
    /// The grid cell is not a positive length.
    #[error("the reconstruction's grid cell is {0} m; use a finite length > 0")]
    Cell(Real),
    /// The cloud's box needs too many grid nodes at this cell.
    #[error(
        "meshing the cloud at a cell of {cell:.3e} m needs {nodes:.3e} grid nodes, above the \
         {limit} allowed; coarsen the resolution"
    )]
    TooManyNodes {
        /// Nodes the grid would need.
        nodes: Real,
        /// The cell asked for.
        cell: Real,
        /// [`MAX_NODES`].
        limit: usize,
    },
    /// The field has no zero crossing near the samples.
    #[error(
        "the cloud's field has no surface near its points; check that the normals point \
         outward and the points lie on one surface"
    )]
    Empty,
    /// The zero set falls apart into comparable pieces.
    #[error(
        "the cloud's surface is {pieces} separate pieces; a shell is one connected surface: \
         give each piece its own shell, or sample the gaps between them"
    )]
    Pieces {
        /// Pieces of at least [`MIN_PIECE`] of the largest.
        pieces: usize,
    },
    /// The work was cancelled.
    #[error("cancelled")]
    Cancelled,
}

/// A cloud's surface, meshed.
#[derive(Debug, Clone)]
pub struct Reconstruction {
    /// The mesh, oriented along the cloud's normals.
    pub mesh: TriMesh,
    /// The cloud's median sample spacing, m.
    pub spacing: Real,
    /// The grid cell it was meshed on, m.
    pub cell: Real,
    /// Triangles of the small pieces dropped.
    pub dropped: usize,
}

/// Meshes the surface of the cloud `points` with outward `normals` on a
/// grid of `cell`, raised to the cloud's sample spacing where it is finer
/// (a finer grid meshes the field's wiggles between samples, nothing the
/// cloud holds); see the module's documentation. Checks `cancel` once per
/// plane of nodes.
///
/// # Errors
/// [`ReconstructError`]: a cloud the field refuses, a cell that is not a
/// positive length or needs more than [`MAX_NODES`] nodes, no surface,
/// several pieces, cancellation.
pub fn reconstruct(
    points: &[Vector],
    normals: &[Vector],
    cell: Real,
    cancel: &Cancel,
) -> Result<Reconstruction, ReconstructError> {
    let surface = PointSurface::new(points, normals, PointSurfaceParams::default())?;
    if !(cell.is_finite() && cell > 0.0) {
        return Err(ReconstructError::Cell(cell));
    }
    let spacing = surface.spacing();
    let cell = cell.max(spacing);
    let (lo, hi) = bounds(points);
    let pad = 2.0 * cell;
    let per_axis = (hi - lo)
        .add_scalar(2.0 * pad)
        .map(|e| (e / cell).ceil() + 1.0);
    let nodes = per_axis.product();
    // NaN (an overflowing box) is refused too.
    if nodes.is_nan() || nodes > MAX_NODES as Real {
        return Err(ReconstructError::TooManyNodes {
            nodes,
            cell,
            limit: MAX_NODES,
        });
    }
    let dims = [0, 1, 2].map(|a| per_axis[a] as usize);
    let origin = lo.add_scalar(-pad);
    let grid = field_on_grid(&surface, origin, cell, dims, cancel)?;
    let mesh = marching_cubes::extract(&grid, 0.0);
    let reach = RIM_SPACINGS * spacing;
    // A triangle is kept when all its corners are near the samples (not
    // its centroid alone, which let a rim vertex lie a grid cell further
    // out).
    let near: Vec<bool> = mesh
        .vertices
        .par_iter()
        .map(|v| surface.distance_to_samples(v).is_some_and(|d| d <= reach))
        .collect();
    let kept: Vec<[u32; 3]> = mesh
        .triangles
        .iter()
        .filter(|tri| tri.iter().all(|&v| near[v as usize]))
        .copied()
        .collect();
    let mesh = split_pinched_vertices(TriMesh {
        vertices: mesh.vertices,
        triangles: kept,
    });
    let (mesh, dropped) = largest_piece(mesh)?;
    Ok(Reconstruction {
        mesh,
        spacing,
        cell,
        dropped,
    })
}

/// The field on the grid's nodes, negated so the inside is positive as
/// marching cubes takes it, and kept [`SNAP`] cells off zero.
fn field_on_grid(
    surface: &PointSurface,
    origin: Vector,
    cell: Real,
    dims: [usize; 3],
    cancel: &Cancel,
) -> Result<NodeGrid, ReconstructError> {
    let [nx, ny, _] = dims;
    let snap = (SNAP * cell) as f32;
    let mut grid = NodeGrid {
        origin,
        cell,
        dims,
        values: vec![0.0; dims.iter().product()],
    };
    let at =
        |i: usize, j: usize, k: usize| origin + Vector::new(i as Real, j as Real, k as Real) * cell;
    grid.values
        .par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(k, plane)| {
            if cancel.is_cancelled() {
                return;
            }
            for (n, value) in plane.iter_mut().enumerate() {
                let f = surface.signed_distance(&at(n % nx, n / nx, k));
                // A NaN (no sample near enough to measure) is outside.
                let v = if f.is_nan() { -cell } else { -f } as f32;
                *value = if v.abs() >= snap {
                    v
                } else if v < 0.0 {
                    -snap
                } else {
                    snap
                };
            }
        });
    if cancel.is_cancelled() {
        return Err(ReconstructError::Cancelled);
    }
    Ok(grid)
}

/// Gives each fan of triangles around a vertex its own copy of it, so
/// that two pieces touching at a point (as trimming may leave) stop
/// sharing it; drops vertices no triangle uses.
fn split_pinched_vertices(mesh: TriMesh) -> TriMesh {
    // Corners `3 t + k`, joined when they share an edge out of their
    // vertex: the fans are the classes.
    let corners = 3 * mesh.triangles.len();
    let mut parent: Vec<usize> = (0..corners).collect();
    fn root(parent: &mut [usize], mut c: usize) -> usize {
        while parent[c] != c {
            parent[c] = parent[parent[c]];
            c = parent[c];
        }
        c
    }
    let mut first_at: HashMap<(u32, u32), usize> = HashMap::new();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            let corner = 3 * t + k;
            for other in [tri[(k + 1) % 3], tri[(k + 2) % 3]] {
                let first = *first_at.entry((tri[k], other)).or_insert(corner);
                let (a, b) = (root(&mut parent, first), root(&mut parent, corner));
                parent[a.max(b)] = a.min(b);
            }
        }
    }
    let mut vertex_of_fan: HashMap<usize, u32> = HashMap::new();
    let mut vertices = Vec::new();
    let mut triangles = mesh.triangles;
    for (t, tri) in triangles.iter_mut().enumerate() {
        for (k, v) in tri.iter_mut().enumerate() {
            let fan = root(&mut parent, 3 * t + k);
            *v = *vertex_of_fan.entry(fan).or_insert_with(|| {
                vertices.push(mesh.vertices[*v as usize]);
                (vertices.len() - 1) as u32
            });
        }
    }
    TriMesh {
        vertices,
        triangles,
    }
}

/// The largest edge-connected piece, with the triangles of the dropped
/// ones; refuses several pieces of comparable size.
fn largest_piece(mesh: TriMesh) -> Result<(TriMesh, usize), ReconstructError> {
    let count = mesh.triangles.len();
    if count == 0 {
        return Err(ReconstructError::Empty);
    }
    // Triangles joined across the edges they share.
    let mut neighbours = vec![Vec::new(); count];
    for uses in sorted_half_edges(&mesh).chunk_by(|a, b| a.key == b.key) {
        for h in uses {
            for i in uses {
                if h.triangle != i.triangle {
                    neighbours[h.triangle as usize].push(i.triangle);
                }
            }
        }
    }
    let mut piece = vec![u32::MAX; count];
    let mut sizes = Vec::new();
    for start in 0..count {
        if piece[start] != u32::MAX {
            continue;
        }
        let label = sizes.len() as u32;
        piece[start] = label;
        let mut stack = vec![start];
        let mut size = 0;
        while let Some(t) = stack.pop() {
            size += 1;
            for &u in &neighbours[t] {
                if piece[u as usize] == u32::MAX {
                    piece[u as usize] = label;
                    stack.push(u as usize);
                }
            }
        }
        sizes.push(size);
    }
    let (largest, &most) = sizes
        .iter()
        .enumerate()
        .max_by_key(|&(_, s)| *s)
        .unwrap_or((0, &0));
    let pieces = sizes
        .iter()
        .filter(|&&s| s as Real >= MIN_PIECE * most as Real)
        .count();
    if pieces > 1 {
        return Err(ReconstructError::Pieces { pieces });
    }
    let triangles: Vec<[u32; 3]> = mesh
        .triangles
        .iter()
        .zip(&piece)
        .filter_map(|(tri, &p)| (p as usize == largest).then_some(*tri))
        .collect();
    let dropped = count - triangles.len();
    Ok((without_unused_vertices(mesh.vertices, triangles), dropped))
}

/// The mesh of `triangles` over the `vertices` they use, renumbered.
fn without_unused_vertices(vertices: Vec<Vector>, mut triangles: Vec<[u32; 3]>) -> TriMesh {
    let mut index = vec![u32::MAX; vertices.len()];
    let mut kept = Vec::new();
    for v in triangles.iter_mut().flatten() {
        if index[*v as usize] == u32::MAX {
            index[*v as usize] = kept.len() as u32;
            kept.push(vertices[*v as usize]);
        }
        *v = index[*v as usize];
    }
    TriMesh {
        vertices: kept,
        triangles,
    }
}

#[cfg(test)]
mod tests;
