//! High-resolution surfaces embedded in an MLS elastic solid (Adams–Wicke
//! tutorial, Section 7.2). A render mesh far finer than the particles
//! follows the deformation field the particles define: everything that
//! depends only on the material (rest) configuration is computed once, so
//! an update is one weighted sum over each vertex's particles.
//!
//! - [`EmbeddingMethod::ShapeFunctions`], Alternative 1 (Adams et al.
//!   2008): the MLS shape functions `phi_i(x)` of each vertex `x` (Eq. 27)
//!   and their gradients (Eq. 32) are stored, and `x' = x + sum_i phi_i
//!   u_i` (Eq. 67).
//! - [`EmbeddingMethod::Gradients`], Alternative 2 (Müller et al. 2004,
//!   Eq. 68): the displacement gradients the solver already has at the
//!   particles extrapolate each particle's displacement to the vertex,
//!   `u(x) = sum_j w~_j (u_j + grad u_j (x - x_j))`, with `w~_j` the
//!   normalised poly6 weights of `|x - x_j| / h`. Nothing but the weights
//!   is stored, and the result is first-order accurate.
//!
//! **Normals.** The tutorial updates a normal as `n' = n + grad u n`, i.e.
//! it maps `n` by the deformation gradient `F = I + grad u` like a
//! tangent. That is right for rotations only: a stretch along a tilted
//! normal tilts it the wrong way. A normal maps by the cofactor,
//! `n' ~ cof(F) n = det(F) F^-T n`, which follows every affine deformation
//! exactly, and that is what both methods use. Alternative 1 keeps the
//! tutorial's trick of precomputed scalars by applying it to two unit
//! tangents `t1 x t2 = n` instead of to `n`: with `s_ik = grad phi_i(x) .
//! t_k` stored, `F t_k = t_k + sum_i s_ik u_i` costs scalar-vector products
//! only, and `n' ~ (F t1) x (F t2) = cof(F) (t1 x t2)`. Alternative 2 forms
//! `F = I + sum_j w~_j grad u_j` and applies its cofactor to `n`.
//!
//! **Layout and cost.** Per-vertex data keeps the mesh's vertex order and
//! per-pair data lies flat (CSR), so an update streams both once, in
//! order; particles are listed by ascending index, so the gathers move
//! forward through the particle arrays, which for some ten thousand
//! particles stay in cache (a randomly shuffled vertex order measured no
//! slower). The particle-side terms (displacements, and for Alternative 2
//! each particle's extrapolation to a common centre) are formed once per
//! update in the caller's [`DeformedSurface`], so a pair reads one record.
//! Alternative 1 streams 28 bytes per pair (an index and three `f64`
//! weights) and is bound by memory bandwidth; its weights stay in double
//! precision because rounded ones would no longer reproduce an affine
//! deformation exactly. Alternative 2 streams 6 to 12 bytes per pair (`f32`
//! weights, exact all the same, for couples of vertices that share one
//! index list) and is bound by its twelve multiply-adds per pair.

use crate::approx::{Kernel, KernelKind, Mls, MlsError, MlsParams, Order, ShapeFunctions};
use crate::geometry::{MeshError, TriMesh};
use crate::math::{Real, Vector};
use crate::neighbors::{CandidateSearch, KdTree, NeighborList};
use nalgebra::Matrix3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Vertices per parallel work item: large enough that the scheduling cost
/// vanishes next to the work, small enough to balance two to dozens of
/// cores on meshes of some ten thousand vertices. Even, so that chunks
/// start on one of Alternative 2's couples of vertices.
const CHUNK: usize = 1024;
const _: () = assert!(CHUNK.is_multiple_of(2));

/// Particles per parallel work item of the per-update particle pass.
const PARTICLE_CHUNK: usize = 4096;

/// How the vertices follow the particles (tutorial Section 7.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EmbeddingMethod {
    /// Alternative 1 (Adams et al. 2008): the MLS approximation of the
    /// displacement at each vertex, from stored shape functions. Exact for
    /// every field the basis reproduces; stores three weights per pair.
    ShapeFunctions,
    /// Alternative 2 (Müller et al. 2004, Eq. 68): each particle's
    /// displacement extrapolated with its displacement gradient, averaged
    /// with normalised weights. Exact for affine deformations when the
    /// gradients are; stores one weight per pair and needs the solver's
    /// gradients at every update.
    Gradients,
}

/// Why a surface cannot be embedded or updated. Each message says what to
/// change.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EmbedError {
    /// The solid is not 3D: an embedded surface is a triangle mesh and
    /// follows only a 3D solid; embed the mesh in a 3D solid.
    #[error(
        "embedded surfaces are triangle meshes in 3D, but the solid is {dim}D; \
         embed the mesh in a 3D solid"
    )]
    Dimension {
        /// The solid's dimension as given.
        dim: usize,
    },

    /// The support radius (checked as the MLS parameter it is).
    #[error("embedded surface: {0}")]
    Parameter(#[from] MlsError),

    /// A particle's rest position has a NaN or infinite coordinate; give
    /// every particle finite x, y, z.
    #[error(
        "particle {particle} has a non-finite rest position; every particle needs finite x, y, z"
    )]
    NonFiniteParticle {
        /// Index of the first such particle.
        particle: usize,
    },

    /// The surface mesh is invalid (a non-finite vertex, or a triangle
    /// naming a missing vertex); fix the mesh.
    #[error("surface mesh: {0}")]
    Mesh(#[from] MeshError),

    /// A surface vertex has no particle within the support radius `h` (or
    /// none that the coupling test accepts), so nothing would move it;
    /// enlarge `h` or move the mesh inside the particles.
    #[error(
        "surface vertex {vertex} at {position:?}: none of the {particles} particles lies \
         within h = {h}; enlarge h or move the mesh inside the particles"
    )]
    NoSupport {
        /// Index of the first unsupported vertex in the mesh.
        vertex: usize,
        /// Its rest position, m.
        position: [Real; 3],
        /// The support radius searched, m.
        h: Real,
        /// How many particles the solid has.
        particles: usize,
    },

    /// Alternative 1's MLS fit at a vertex failed for a reason other than
    /// missing support; the MLS error says what to change.
    #[error("surface vertex {vertex}: {source}")]
    Mls {
        /// Index of the vertex whose fit failed.
        vertex: usize,
        /// Why the fit failed.
        #[source]
        source: MlsError,
    },

    /// [`EmbeddedSurface::update`] got `positions` or `grad_u` with a length
    /// other than the particle count the surface was embedded among; pass
    /// one entry per particle of that solid.
    #[error(
        "{what} has {got} entries but the surface was embedded among {expected} particles; \
         pass one entry per particle of that solid"
    )]
    LengthMismatch {
        /// The argument at fault: `positions` or `grad_u`.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The particle count the surface was embedded among.
        expected: usize,
    },
}

/// Alternative 1, per vertex: its rest position and unit tangents, `t1 x
/// t2` the undeformed unit normal (zero for a vertex without one).
#[derive(Debug, Clone, Copy)]
struct ShapeVertex {
    x: Vector,
    t: [Vector; 2],
}

/// Alternative 2, per vertex: its rest position, undeformed unit normal
/// (or zero), and the sum of its stored (rounded) weights.
#[derive(Debug, Clone, Copy)]
struct GradientVertex {
    x: Vector,
    n: Vector,
    total: Real,
}

/// Alternative 1's tables: per vertex its particles (flat, CSR) and per
/// pair `[phi_i, grad phi_i . t1, grad phi_i . t2]`.
#[derive(Debug, Clone)]
struct ShapeTables {
    vertices: Vec<ShapeVertex>,
    /// `offsets[v]..offsets[v + 1]` indexes `neighbours` and `pairs`.
    offsets: Vec<u32>,
    neighbours: Vec<u32>,
    pairs: Vec<[Real; 3]>,
}

/// Alternative 2's tables, by couples of consecutive vertices `(2b, 2b +
/// 1)`: the union of their particles and, per entry, both vertices'
/// normalised weights `w~_j` (zero where the particle lies outside one's
/// support). Consecutive vertices of a mesh are usually neighbours and
/// share most particles, so each 12-number particle record is gathered
/// once for two vertices, which about halves the work of the loop (it is
/// bound by its multiply-adds, not by memory); a couple that lies apart
/// costs only zero-weight multiply-adds. The weights are single precision,
/// and each vertex divides by the sum of its rounded weights, so they still
/// sum to one and an affine deformation stays exact: every term of Eq. 68
/// then equals `u(x)`.
#[derive(Debug, Clone)]
struct GradientTables {
    vertices: Vec<GradientVertex>,
    /// `offsets[b]..offsets[b + 1]` indexes `neighbours` and `pairs` for
    /// couple `b`.
    offsets: Vec<u32>,
    neighbours: Vec<u32>,
    pairs: Vec<[f32; 2]>,
}

/// What each method stores.
#[derive(Debug, Clone)]
enum Tables {
    Shape(ShapeTables),
    Gradients(GradientTables),
}

/// A triangle mesh embedded in a particle solid, with everything an update
/// needs precomputed in material coordinates.
#[derive(Debug, Clone)]
pub struct EmbeddedSurface {
    method: EmbeddingMethod,
    h: Real,
    /// Particle rest positions, to form displacements at each update.
    rest: Vec<Vector>,
    /// Mean rest position: Alternative 2 extrapolates every particle to it
    /// once per update, so a vertex needs one matrix-vector product.
    centre: Vector,
    triangles: Vec<[u32; 3]>,
    tables: Tables,
    /// (vertex, particle) pairs within `h`.
    pairs: usize,
    /// Vertices where the MLS fit dropped below the requested order.
    reduced: usize,
}

/// The deformed surface, written by [`EmbeddedSurface::update`]. Reuse one
/// across updates: its buffers then never reallocate.
#[derive(Debug, Clone, Default)]
pub struct DeformedSurface {
    /// Deformed vertex positions, in the mesh's vertex order.
    pub vertices: Vec<Vector>,
    /// Deformed unit normals (zero where the undeformed vertex had none,
    /// or where the deformation collapses the surface).
    pub normals: Vec<Vector>,
    /// Alternative 1's particle displacements `u_i` of the last update.
    displacements: Vec<Vector>,
    /// Alternative 2's per-particle affine maps of the last update,
    /// `[v_j, grad u_j row by row]` (see [`EmbeddedSurface::update`]), one
    /// contiguous record per particle so a pair gathers one cache line run.
    extrapolations: Vec<[Real; 12]>,
}

impl DeformedSurface {
    /// An empty surface, for [`EmbeddedSurface::update`] to fill; the same
    /// as `Default`.
    pub fn new() -> Self {
        Self::default()
    }

    /// The deformed mesh, with `triangles` from
    /// [`EmbeddedSurface::triangles`], for export or measurement.
    pub fn to_mesh(&self, triangles: &[[u32; 3]]) -> TriMesh {
        TriMesh {
            vertices: self.vertices.clone(),
            triangles: triangles.to_vec(),
        }
    }
}

impl EmbeddedSurface {
    /// Precomputes, in material coordinates, how `mesh` follows particles
    /// whose reference positions are `rest`: for each vertex, the particles
    /// within the support radius `h` and their weights. `dim` is the
    /// solid's dimension (3; 2D solids have no triangle surface). `order`
    /// is the MLS basis order of Alternative 1 (linear reproduces affine
    /// deformations and their normals exactly); Alternative 2 ignores it.
    /// Runs in parallel; the result does not depend on the thread count.
    ///
    /// # Errors
    /// [`EmbedError::Dimension`] unless `dim` is 3;
    /// [`EmbedError::Parameter`] for a non-positive or non-finite `h`;
    /// [`EmbedError::NonFiniteParticle`]; [`EmbedError::Mesh`] when a
    /// triangle names a missing vertex or a vertex is not finite;
    /// [`EmbedError::NoSupport`] naming the first vertex with no particle
    /// within `h`.
    pub fn new(
        mesh: &TriMesh,
        rest: &[Vector],
        dim: usize,
        h: Real,
        order: Order,
        method: EmbeddingMethod,
    ) -> Result<Self, EmbedError> {
        Self::new_coupled(mesh, rest, dim, h, order, method, &|_, _| true)
    }

    /// [`Self::new`] where a vertex at `v` couples to a particle at `x`
    /// within `h` only if `couples(v, x)`: the shape optimiser couples by
    /// distance inside the shape, so a finger's surface ignores the
    /// particles of the finger beside it.
    ///
    /// # Errors
    /// As [`Self::new`]; [`EmbedError::NoSupport`] also when a vertex
    /// couples to no particle.
    pub fn new_coupled(
        mesh: &TriMesh,
        rest: &[Vector],
        dim: usize,
        h: Real,
        order: Order,
        method: EmbeddingMethod,
        couples: &(dyn Fn(&Vector, &Vector) -> bool + Sync),
    ) -> Result<Self, EmbedError> {
        if dim != 3 {
            return Err(EmbedError::Dimension { dim });
        }
        let mls = Mls::new(dim, MlsParams::new(order, h))?;
        if let Some(particle) = rest.iter().position(|x| x.iter().any(|c| !c.is_finite())) {
            return Err(EmbedError::NonFiniteParticle { particle });
        }
        mesh.validate()?;

        let mut tree = KdTree::new(h);
        tree.rebuild(rest);
        let mut list = NeighborList::default();
        list.build_between(&tree, &mesh.vertices, rest, h, None);
        let mut offsets = Vec::with_capacity(mesh.vertices.len() + 1);
        offsets.push(0u32);
        let mut neighbours = Vec::with_capacity(list.pair_count());
        let coupled: Vec<Vec<u32>> = mesh
            .vertices
            .par_iter()
            .enumerate()
            .map(|(vertex, x)| {
                let mut found = list.of(vertex).to_vec();
                found.retain(|&j| couples(x, &rest[j as usize]));
                found
            })
            .collect();
        for ((vertex, x), found) in mesh.vertices.iter().enumerate().zip(&coupled) {
            if found.is_empty() {
                return Err(EmbedError::NoSupport {
                    vertex,
                    position: [x[0], x[1], x[2]],
                    h,
                    particles: rest.len(),
                });
            }
            let start = neighbours.len();
            neighbours.extend_from_slice(found);
            neighbours[start..].sort_unstable();
            offsets.push(neighbours.len() as u32);
        }

        let normals = mesh.vertex_normals();
        let centre = if rest.is_empty() {
            Vector::zeros()
        } else {
            rest.iter().sum::<Vector>() / rest.len() as Real
        };
        let pairs = neighbours.len();
        let mut reduced = 0;
        let tables = match method {
            EmbeddingMethod::ShapeFunctions => {
                let (pairs, lowered) =
                    shape_pairs(&mls, &mesh.vertices, &normals, rest, &offsets, &neighbours)?;
                reduced = lowered;
                let vertices = mesh
                    .vertices
                    .iter()
                    .zip(&normals)
                    .map(|(&x, n)| ShapeVertex { x, t: tangents(n) })
                    .collect();
                Tables::Shape(ShapeTables {
                    vertices,
                    offsets,
                    neighbours,
                    pairs,
                })
            }
            EmbeddingMethod::Gradients => Tables::Gradients(gradient_tables(
                &mesh.vertices,
                &normals,
                rest,
                h,
                &offsets,
                &neighbours,
            )),
        };
        Ok(Self {
            method,
            h,
            rest: rest.to_vec(),
            centre,
            triangles: mesh.triangles.clone(),
            tables,
            pairs,
            reduced,
        })
    }

    /// Writes the deformed vertices and unit normals into `out`, from the
    /// particles' current `positions` and, for Alternative 2, their
    /// displacement gradients `grad_u` (entry `(a, b) = du_a / dx_b`, the
    /// form [`crate::approx::LagrangianGradients::vector_gradients`]
    /// writes); Alternative 1 ignores `grad_u`, so `&[]` will do. Runs in
    /// parallel; allocates only while `out` grows to this surface's size.
    ///
    /// # Errors
    /// [`EmbedError::LengthMismatch`] when `positions`, or for Alternative
    /// 2 `grad_u`, does not have one entry per particle; `out` is then left
    /// as it was.
    pub fn update(
        &self,
        positions: &[Vector],
        grad_u: &[Matrix3<Real>],
        out: &mut DeformedSurface,
    ) -> Result<(), EmbedError> {
        let expected = self.rest.len();
        let mismatch = |what, got| EmbedError::LengthMismatch {
            what,
            got,
            expected,
        };
        if positions.len() != expected {
            return Err(mismatch("positions", positions.len()));
        }
        if self.method == EmbeddingMethod::Gradients && grad_u.len() != expected {
            return Err(mismatch("grad_u", grad_u.len()));
        }
        let count = self.vertex_count();
        out.vertices.resize(count, Vector::zeros());
        out.normals.resize(count, Vector::zeros());
        match &self.tables {
            Tables::Shape(tables) => {
                out.displacements.resize(expected, Vector::zeros());
                out.displacements
                    .par_chunks_mut(PARTICLE_CHUNK)
                    .zip(positions.par_chunks(PARTICLE_CHUNK))
                    .zip(self.rest.par_chunks(PARTICLE_CHUNK))
                    .for_each(|((u, x), rest)| {
                        for ((u, x), rest) in u.iter_mut().zip(x).zip(rest) {
                            *u = x - rest;
                        }
                    });
                let u = &out.displacements;
                for_each_chunk(&mut out.vertices, &mut out.normals, |first, xs, ns| {
                    for (k, (x, n)) in xs.iter_mut().zip(ns).enumerate() {
                        let v = first + k;
                        let range = tables.offsets[v] as usize..tables.offsets[v + 1] as usize;
                        // sums[b][a] = sum_i s_ib u_ia, with s_i = [phi_i,
                        // grad phi_i . t1, grad phi_i . t2].
                        let mut sums = [[0.0; 3]; 3];
                        for (&j, s) in tables.neighbours[range.clone()]
                            .iter()
                            .zip(&tables.pairs[range])
                        {
                            let uj = &u[j as usize];
                            for (sum, &sb) in sums.iter_mut().zip(s) {
                                for a in 0..3 {
                                    sum[a] += sb * uj[a];
                                }
                            }
                        }
                        let d = &tables.vertices[v];
                        let [dx, f1, f2] = sums.map(Vector::from);
                        (*x, *n) = (d.x + dx, unit(&(d.t[0] + f1).cross(&(d.t[1] + f2))));
                    }
                });
            }
            Tables::Gradients(tables) => {
                // v_j = u_j + grad u_j (c - X_j): particle j's extrapolation
                // to the centre, so that u(x) = sum_j w~_j v_j + G (x - c)
                // with G = sum_j w~_j grad u_j (Eq. 68 regrouped): twelve
                // multiply-adds per pair.
                let centre = self.centre;
                out.extrapolations.resize(expected, [0.0; 12]);
                out.extrapolations
                    .par_chunks_mut(PARTICLE_CHUNK)
                    .zip(positions.par_chunks(PARTICLE_CHUNK))
                    .zip(self.rest.par_chunks(PARTICLE_CHUNK))
                    .zip(grad_u.par_chunks(PARTICLE_CHUNK))
                    .for_each(|(((e, x), rest), g)| {
                        for (((e, x), rest), g) in e.iter_mut().zip(x).zip(rest).zip(g) {
                            let v = (x - rest) + g * (centre - rest);
                            e[..3].copy_from_slice(v.as_slice());
                            e[3..].copy_from_slice(g.transpose().as_slice());
                        }
                    });
                let terms = &out.extrapolations;
                for_each_chunk(&mut out.vertices, &mut out.normals, |first, xs, ns| {
                    // CHUNK is even, so chunks start on a couple.
                    for (k, (xs, ns)) in xs.chunks_mut(2).zip(ns.chunks_mut(2)).enumerate() {
                        let b = first / 2 + k;
                        let range = tables.offsets[b] as usize..tables.offsets[b + 1] as usize;
                        let (mut s0, mut s1) = ([0.0; 12], [0.0; 12]);
                        for (&j, w) in tables.neighbours[range.clone()]
                            .iter()
                            .zip(&tables.pairs[range])
                        {
                            let (w0, w1) = (Real::from(w[0]), Real::from(w[1]));
                            let t = &terms[j as usize];
                            for (s, t) in s0.iter_mut().zip(t) {
                                *s += w0 * t;
                            }
                            for (s, t) in s1.iter_mut().zip(t) {
                                *s += w1 * t;
                            }
                        }
                        let sums = [s0, s1];
                        for (i, (x, n)) in xs.iter_mut().zip(ns).enumerate() {
                            (*x, *n) = tables.vertices[2 * b + i].deform(&sums[i], &centre);
                        }
                    }
                });
            }
        }
        Ok(())
    }

    /// The alternative the surface was embedded with.
    pub fn method(&self) -> EmbeddingMethod {
        self.method
    }

    /// Support radius the weights were computed for.
    pub fn h(&self) -> Real {
        self.h
    }

    /// Vertices of the mesh: the length of [`DeformedSurface::vertices`]
    /// after an update.
    pub fn vertex_count(&self) -> usize {
        match &self.tables {
            Tables::Shape(tables) => tables.vertices.len(),
            Tables::Gradients(tables) => tables.vertices.len(),
        }
    }

    /// Particles the surface follows.
    pub fn particle_count(&self) -> usize {
        self.rest.len()
    }

    /// (vertex, particle) pairs within `h`: the work of one update.
    pub fn pair_count(&self) -> usize {
        self.pairs
    }

    /// Vertices where Alternative 1's MLS fit had too few or too flat a set
    /// of particles for the requested order and fell back to a lower one
    /// (those vertices then do not reproduce fields of the requested
    /// order); always 0 for Alternative 2.
    pub fn reduced_vertices(&self) -> usize {
        self.reduced
    }

    /// The mesh's triangles, indexing [`DeformedSurface::vertices`].
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }
}

impl GradientVertex {
    /// Position and unit normal from `sums = sum_j w_j [v_j, grad u_j row by
    /// row]` over the vertex's rounded weights `w_j` (Eq. 68 regrouped, see
    /// [`EmbeddedSurface::update`]). Dividing by `total` normalises the
    /// weights. The cofactor is homogeneous of degree two, so `cof(total I +
    /// sum_j w_j grad u_j) n` has the direction of `cof(I + sum_j w~_j grad
    /// u_j) n` and needs no division.
    #[inline]
    fn deform(&self, sums: &[Real; 12], centre: &Vector) -> (Vector, Vector) {
        let g = Matrix3::from_row_slice(&sums[3..]);
        let shift = Vector::from_column_slice(&sums[..3]) + g * (self.x - centre);
        let f = Matrix3::from_diagonal_element(self.total) + g;
        (
            self.x + shift * (1.0 / self.total),
            unit(&cofactor_times(&f, &self.n)),
        )
    }
}

/// Calls `chunk(first, positions, normals)` for consecutive chunks of
/// [`CHUNK`] vertices in parallel, `first` the index of the chunk's first
/// vertex.
fn for_each_chunk(
    positions: &mut [Vector],
    normals: &mut [Vector],
    chunk: impl Fn(usize, &mut [Vector], &mut [Vector]) + Sync,
) {
    positions
        .par_chunks_mut(CHUNK)
        .zip(normals.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(c, (xs, ns))| chunk(c * CHUNK, xs, ns));
}

/// Alternative 2's tables from each vertex's particles (`offsets`,
/// `neighbours`, ascending within a vertex): normalised poly6 weights,
/// rounded to single precision, merged by couples of vertices.
fn gradient_tables(
    points: &[Vector],
    normals: &[Vector],
    rest: &[Vector],
    h: Real,
    offsets: &[u32],
    neighbours: &[u32],
) -> GradientTables {
    let kernel = Kernel::new_3d(KernelKind::Poly6, h);
    let mut weights = Vec::with_capacity(neighbours.len());
    let mut vertices = Vec::with_capacity(points.len());
    for ((v, &x), &n) in points.iter().enumerate().zip(normals) {
        let js = &neighbours[offsets[v] as usize..offsets[v + 1] as usize];
        let start = weights.len();
        weights.extend(
            js.iter()
                .map(|&j| kernel.value_sq((x - rest[j as usize]).norm_squared())),
        );
        // Normalised before rounding, so that they are of order one
        // whatever h is. Every listed particle is closer than h, so the
        // weights are positive, but at q -> 1 they may round to zero: if
        // all do, the particles share equally.
        let total: Real = weights[start..].iter().sum();
        let scale = if total > 0.0 { 1.0 / total } else { 0.0 };
        for w in &mut weights[start..] {
            *w = Real::from((*w * scale) as f32);
        }
        let mut rounded: Real = weights[start..].iter().sum();
        if rounded <= 0.0 {
            weights[start..].fill(1.0);
            rounded = js.len() as Real;
        }
        vertices.push(GradientVertex {
            x,
            n,
            total: rounded,
        });
    }
    // Merge each couple's sorted particle lists.
    let mut tables = GradientTables {
        vertices,
        offsets: vec![0],
        neighbours: Vec::with_capacity(neighbours.len()),
        pairs: Vec::with_capacity(neighbours.len()),
    };
    let of = |v: usize| {
        let range = offsets[v] as usize..offsets[v + 1] as usize;
        (&neighbours[range.clone()], &weights[range])
    };
    for first in (0..points.len()).step_by(2) {
        let (a, wa) = of(first);
        let (b, wb) = if first + 1 < points.len() {
            of(first + 1)
        } else {
            (&[][..], &[][..])
        };
        let (mut i, mut k) = (0, 0);
        loop {
            let (j, pair) = match (a.get(i), b.get(k)) {
                (None, None) => break,
                (Some(&ja), Some(&jb)) if ja == jb => {
                    i += 1;
                    k += 1;
                    (ja, [wa[i - 1], wb[k - 1]])
                }
                (Some(&ja), Some(&jb)) if ja < jb => {
                    i += 1;
                    (ja, [wa[i - 1], 0.0])
                }
                (Some(&ja), None) => {
                    i += 1;
                    (ja, [wa[i - 1], 0.0])
                }
                (_, Some(&jb)) => {
                    k += 1;
                    (jb, [0.0, wb[k - 1]])
                }
            };
            tables.neighbours.push(j);
            // Exact: the weights were rounded to f32 above.
            tables.pairs.push(pair.map(|w| w as f32));
        }
        tables.offsets.push(tables.neighbours.len() as u32);
    }
    tables
}

/// Alternative 1's pairs and how many vertices fell below the requested
/// order.
type ShapePairs = (Vec<[Real; 3]>, usize);

/// Alternative 1's pairs, `[phi_i, grad phi_i . t1, grad phi_i . t2]`,
/// vertex after vertex, and the number of vertices whose fit fell below
/// the requested order. Parallel over chunks of vertices; the first
/// failing vertex (in index order) is reported.
fn shape_pairs(
    mls: &Mls,
    points: &[Vector],
    normals: &[Vector],
    rest: &[Vector],
    offsets: &[u32],
    neighbours: &[u32],
) -> Result<ShapePairs, EmbedError> {
    let requested = mls.params().order;
    let chunks: Vec<Result<ShapePairs, EmbedError>> = (0..points.len().div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let (first, last) = (c * CHUNK, ((c + 1) * CHUNK).min(points.len()));
            let mut pairs = Vec::with_capacity((offsets[last] - offsets[first]) as usize);
            let mut reduced = 0;
            let mut nodes = Vec::new();
            let mut shape = ShapeFunctions::new();
            for v in first..last {
                let js = &neighbours[offsets[v] as usize..offsets[v + 1] as usize];
                nodes.clear();
                nodes.extend(js.iter().map(|&j| rest[j as usize]));
                let x = points[v];
                let fit = mls
                    .shape_functions(&x, &nodes, &mut shape)
                    .map_err(|source| {
                        match source {
                            // A particle at distance h up to rounding: listed,
                            // yet outside the weight's support.
                            MlsError::NoSupport { h, .. } => EmbedError::NoSupport {
                                vertex: v,
                                position: [x[0], x[1], x[2]],
                                h,
                                particles: rest.len(),
                            },
                            source => EmbedError::Mls { vertex: v, source },
                        }
                    })?;
                if fit.order < requested {
                    reduced += 1;
                }
                let [t1, t2] = tangents(&normals[v]);
                pairs.extend(
                    shape
                        .values()
                        .iter()
                        .zip(shape.gradients())
                        .map(|(&phi, g)| [phi, g.dot(&t1), g.dot(&t2)]),
                );
            }
            Ok((pairs, reduced))
        })
        .collect();
    let mut pairs = Vec::with_capacity(neighbours.len());
    let mut reduced = 0;
    for chunk in chunks {
        let (chunk, lowered) = chunk?;
        pairs.extend_from_slice(&chunk);
        reduced += lowered;
    }
    Ok((pairs, reduced))
}

/// Unit tangents `t1, t2` with `t1 x t2 = n` for a unit `n`, without a
/// branch on the direction (Duff et al. 2017, "Building an orthonormal
/// basis, revisited"); zeros for a zero `n`.
fn tangents(n: &Vector) -> [Vector; 2] {
    if *n == Vector::zeros() {
        return [Vector::zeros(); 2];
    }
    let sign = 1.0_f64.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    [
        Vector::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vector::new(b, sign + n.y * n.y * a, -n.y),
    ]
}

/// `cof(F) n = det(F) F^-T n`, how a deformation gradient maps a normal:
/// with the columns `f_k` of `F`, `cof(F) = [f2 x f3, f3 x f1, f1 x f2]`,
/// which needs no inverse and stays defined for a singular `F`.
fn cofactor_times(f: &Matrix3<Real>, n: &Vector) -> Vector {
    let (f1, f2, f3) = (f.column(0), f.column(1), f.column(2));
    n.x * f2.cross(&f3) + n.y * f3.cross(&f1) + n.z * f1.cross(&f2)
}

/// `v / |v|`, or zero where `v` has no direction (zero or not finite).
fn unit(v: &Vector) -> Vector {
    let norm_squared = v.norm_squared();
    if norm_squared > 0.0 && norm_squared.is_finite() {
        v * (1.0 / norm_squared.sqrt())
    } else {
        Vector::zeros()
    }
}
