//! The surface a modal solid carries into frames (Guo–Qin, Section 5.3:
//! the input surface embedded in the nodes' shape functions): a triangle
//! mesh, whose normals are recomputed from the deformed triangles, or
//! oriented points (surfels), whose rest normals turn by the interpolated
//! rotation vector.
//!
//! Everything that does not change per frame (the shape-function rows of
//! each vertex, the triangles around each vertex) is built once, so a
//! frame is three parallel passes: the displaced positions, the
//! triangles' cross products, the vertex normals.
//!
//! The rows' values are kept as f32: the frame ships vertices as f32
//! (`proto/meshless/v1/frame.proto`), and a weight rounded to f32 moves a
//! vertex by about `6e-8 |u|`, below that rounding of its position
//! whenever the displacement is smaller than the position. It halves the
//! bytes the hottest loop streams (and drops the gradients a skin never
//! reads).

use super::ShapeTable;
use super::shape::weighted_sums;
use crate::geometry::VertexRings;
use crate::math::{Real, Vector};
use crate::modal::ModalSystem;
use nalgebra::Rotation3;
use rayon::prelude::*;

/// The surface a modal solid carries into frames: a triangle mesh, or
/// oriented points (surfels) with no triangles.
#[derive(Debug, Clone, PartialEq)]
pub struct SkinInput {
    /// Rest positions, world frame.
    pub vertices: Vec<Vector>,
    /// Triangles (empty for a point cloud).
    pub triangles: Vec<[u32; 3]>,
    /// Unit rest normals, one per vertex.
    pub normals: Vec<Vector>,
}

/// Buffers a deformed skin is written into, reused from frame to frame.
#[derive(Debug, Clone, Default)]
pub struct SkinBuffers {
    /// Vertex positions.
    pub positions: Vec<Vector>,
    /// Unit normal per vertex.
    pub normals: Vec<Vector>,
    /// The triangles' cross products (scratch).
    faces: Vec<[f32; 3]>,
    /// The nodes' rotation vectors, for a point cloud's normals (scratch).
    rotations: Vec<Vector>,
}

/// A surface embedded in the nodes' shape functions.
#[derive(Debug)]
pub(super) struct Skin {
    input: SkinInput,
    /// CSR rows: `offsets`, `nodes` and f32 `values`, one row per vertex.
    offsets: Vec<u32>,
    nodes: Vec<u32>,
    values: Vec<f32>,
    /// Each vertex's triangles (empty for a point cloud).
    rings: VertexRings,
}

impl Skin {
    /// `input` with its shape-function rows `table` (one per vertex).
    pub(super) fn new(input: SkinInput, table: &ShapeTable) -> Self {
        let rings = VertexRings::new(&input.triangles, input.vertices.len());
        let mut offsets = Vec::with_capacity(table.len() + 1);
        offsets.push(0);
        let (mut nodes, mut values) = (Vec::new(), Vec::new());
        for i in 0..table.len() {
            let row = table.row(i);
            nodes.extend_from_slice(row.nodes);
            values.extend(row.values.iter().map(|&v| v as f32));
            offsets.push(nodes.len() as u32);
        }
        Self {
            input,
            offsets,
            nodes,
            values,
            rings,
        }
    }

    /// The bytes of its tables: an index and an f32 value per
    /// shape-function entry; per vertex its rest position and normal and
    /// two offsets (rows, ring); per triangle its corners twice (the
    /// input's and the rings' copy) and three ring entries.
    pub(super) fn bytes(&self) -> usize {
        let real = std::mem::size_of::<Real>();
        self.nodes.len() * 8
            + self.input.vertices.len() * (6 * real + 8)
            + 9 * 4 * self.input.triangles.len()
    }

    /// Its triangles (empty for a point cloud).
    pub(super) fn triangles(&self) -> &[[u32; 3]] {
        &self.input.triangles
    }

    /// The positions and unit normals of the skin at the state of
    /// `system` into `out`.
    pub(super) fn deform_into(&self, system: &ModalSystem, out: &mut SkinBuffers) {
        let rest = &self.input.vertices;
        self.sums(system.displacements(), &mut out.positions, |i| rest[i]);
        if self.input.triangles.is_empty() {
            out.rotations.clear();
            out.rotations
                .extend((0..system.basis().node_count()).map(|i| system.rotation_vector(i)));
            self.sums(&out.rotations, &mut out.normals, |_| Vector::zeros());
            out.normals
                .par_iter_mut()
                .zip(&self.input.normals)
                .for_each(|(w, n)| *w = Rotation3::new(*w) * n);
        } else {
            self.rings
                .normals_into(&out.positions, &mut out.faces, &mut out.normals);
        }
    }

    /// The positions and unit normals of the skin at the nodal
    /// displacements `u` of the full nonlinear state: a mesh's normals from
    /// its deformed triangles, a point cloud's rest normals `n` taken to
    /// `F^-T n` (normalised; `cloud` holds the vertices' shape functions
    /// with their gradients, for `F`).
    pub(super) fn deform_full_into(
        &self,
        u: &[Vector],
        cloud: Option<&ShapeTable>,
        out: &mut SkinBuffers,
    ) {
        let rest = &self.input.vertices;
        self.sums(u, &mut out.positions, |i| rest[i]);
        if self.input.triangles.is_empty() {
            out.normals.clear();
            out.normals.extend_from_slice(&self.input.normals);
            if let Some(table) = cloud {
                out.normals.par_iter_mut().enumerate().for_each(|(i, n)| {
                    let f = super::nonlinear::gradient_at(&table.row(i), u);
                    if let Some(inverse) = f.try_inverse() {
                        *n = (inverse.transpose() * *n).try_normalize(0.0).unwrap_or(*n);
                    }
                });
            }
        } else {
            self.rings
                .normals_into(&out.positions, &mut out.faces, &mut out.normals);
        }
    }

    /// `base(i) + sum_I phi_I(x_i) u_I` for every vertex.
    fn sums(&self, u: &[Vector], out: &mut Vec<Vector>, base: impl Fn(usize) -> Vector + Sync) {
        weighted_sums(&self.offsets, &self.nodes, &self.values, u, out, base);
    }
}

/// The skin as deformed at the current state.
#[derive(Debug, Clone, PartialEq)]
pub struct DeformedSkin<'a> {
    /// Vertex positions.
    pub positions: Vec<Vector>,
    /// Triangles (empty for a point cloud).
    pub triangles: &'a [[u32; 3]],
    /// Unit normal per vertex.
    pub normals: Vec<Vector>,
}
