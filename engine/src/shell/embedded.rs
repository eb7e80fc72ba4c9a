//! Points carried by a shell: an input mesh's vertices (or a point
//! cloud's points) placed in the parametric domain and moved by the node
//! shape functions, as the modal solids carry their skins. A point keeps
//! its own rest position and adds the shell's displacement there, so an
//! undeformed shell shows its input exactly (the nodes' surface is a fit
//! of it); its normal is the deformed middle surface's.

use super::error::ShellError;
use super::model::{ShellModel, ShellSurface, Stencil};
use crate::geometry::atlas::{Atlas, Transfer};
use crate::geometry::conformal::ConformalChart;
use crate::geometry::quadtree::Point2;
use crate::math::{Real, Vector, bounds};
use rayon::prelude::*;
use wide::f32x4;

/// A mesh's chart is a shell's surface: its points are the mesh's,
/// interpolated in the triangle under a parametric point.
impl ShellSurface for ConformalChart {
    fn position(&self, u: Point2) -> Vector {
        self.surface_point(u)
    }
}

/// An atlas is a shell's surface across its seams: each chart's points
/// are the mesh's, and a node near a seam reaches into the neighbouring
/// chart through the atlas's transfers.
impl ShellSurface for Atlas {
    fn position(&self, u: Point2) -> Vector {
        self.surface_point(u)
    }

    fn transfers(&self, u: Point2) -> Vec<Transfer> {
        Atlas::transfers(self, u)
    }
}

/// Points embedded in a shell: each point's nodes and its shape
/// functions' values and first derivatives there, flat.
///
/// The update runs in single precision, apart from each point's own rest
/// position: it reads the weights of tens of thousands of points every
/// frame, so their bytes are its cost (a sixth of the stencils' rows in
/// all: those also hold second derivatives, in double precision), and
/// frames carry single-precision positions anyway (the rounding moves a
/// point by about 1e-7 of its displacement). The tangents are summed over
/// the nodes' positions about the shell's centre, which the derivatives'
/// partition of nullity (`sum_I N_I,a = 0`) leaves unchanged, so a shell
/// far from the origin keeps its normals' precision.
#[derive(Debug, Clone)]
pub struct Embedded {
    /// Point `i`'s entries are `starts[i]..starts[i + 1]`.
    starts: Vec<u32>,
    entries: Vec<Entry>,
    rest: Vec<Vector>,
    /// The centre of the nodes' reference box, which the tangents are
    /// summed about.
    centre: Vector,
}

/// A node of a point's stencil and its `N`, `N_,1`, `N_,2` there.
#[derive(Debug, Clone, Copy)]
struct Entry {
    node: u32,
    weights: [f32; 3],
}

impl Embedded {
    /// How many points.
    pub fn len(&self) -> usize {
        self.rest.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.rest.is_empty()
    }

    /// The points moved by nodal displacements `displacement`, and the
    /// deformed middle surface's unit normals at them (zero where the
    /// surface has folded flat), for the nodes' reference positions
    /// `reference`: one pass over the weights, in parallel.
    pub fn surface(
        &self,
        reference: &[Vector],
        displacement: &[Vector],
    ) -> (Vec<Vector>, Vec<Vector>) {
        let mut positions = vec![Vector::zeros(); self.rest.len()];
        let mut normals = vec![Vector::zeros(); self.rest.len()];
        // Per node, its displacement and its deformed position about the
        // centre side by side, each in four lanes (the last zero): one
        // entry's work is three four-wide multiplies and adds on one
        // 32-byte load. Multiplies and adds apart, not fused, so that
        // every target rounds alike.
        let nodes: Vec<[f32x4; 2]> = reference
            .iter()
            .zip(displacement)
            .map(|(x, u)| [lanes(*u), lanes(x + u - self.centre)])
            .collect();
        positions
            .par_chunks_mut(POINTS_PER_TASK)
            .zip(normals.par_chunks_mut(POINTS_PER_TASK))
            .enumerate()
            .for_each(|(task, (positions, normals))| {
                let first = task * POINTS_PER_TASK;
                for (k, (position, normal)) in
                    positions.iter_mut().zip(normals.iter_mut()).enumerate()
                {
                    let i = first + k;
                    let entries =
                        &self.entries[self.starts[i] as usize..self.starts[i + 1] as usize];
                    let (mut d, mut t1, mut t2) = (f32x4::ZERO, f32x4::ZERO, f32x4::ZERO);
                    for e in entries {
                        let [u, x] = nodes[e.node as usize];
                        let [n, n1, n2] = e.weights;
                        d += f32x4::splat(n) * u;
                        t1 += f32x4::splat(n1) * x;
                        t2 += f32x4::splat(n2) * x;
                    }
                    *position = self.rest[i] + double(d);
                    *normal = double(t1).cross(&double(t2));
                }
                // Normalised in a pass of their own: without the
                // weights' loop between them, the square roots and
                // divisions of neighbouring points overlap instead of
                // each waiting on its point's sums.
                for normal in normals {
                    let length = normal.norm();
                    *normal *= if length > 0.0 { length.recip() } else { 0.0 };
                }
            });
        (positions, normals)
    }
}

/// Points per parallel task of the surface update: enough that a task's
/// work (tens of microseconds) dwarfs handing it out.
const POINTS_PER_TASK: usize = 2048;

/// The first three lanes of `v` in double precision.
fn double(v: f32x4) -> Vector {
    let [x, y, z, _] = v.to_array();
    Vector::new(x.into(), y.into(), z.into())
}

/// `v` in single precision, the fourth lane zero.
fn lanes(v: Vector) -> f32x4 {
    f32x4::new([v.x as f32, v.y as f32, v.z as f32, 0.0])
}

impl ShellModel {
    /// Embeds the points at parametric positions `at` whose rest
    /// positions are `rest`.
    ///
    /// # Errors
    /// [`ShellError::Parameter`] when the lengths differ; a point off the
    /// chart or under too few supports, as [`ShellModel::stencil`].
    pub fn embed(&self, at: &[Point2], rest: &[Vector]) -> Result<Embedded, ShellError> {
        if at.len() != rest.len() {
            return Err(ShellError::Parameter {
                what: "embedded points",
                got: rest.len() as Real,
                range: "one rest position per parametric position",
            });
        }
        let stencils: Vec<Stencil> = at
            .par_iter()
            .map(|&u| self.stencil(u))
            .collect::<Result<_, _>>()?;
        let mut starts = Vec::with_capacity(stencils.len() + 1);
        let mut entries = Vec::new();
        starts.push(0);
        for s in &stencils {
            entries.extend(s.nodes.iter().zip(&s.rows).map(|(&node, r)| Entry {
                node,
                weights: [r[0] as f32, r[1] as f32, r[2] as f32],
            }));
            starts.push(
                u32::try_from(entries.len()).map_err(|_| ShellError::TooLarge {
                    nodes: self.node_count(),
                })?,
            );
        }
        Ok(Embedded {
            starts,
            entries,
            rest: rest.to_vec(),
            centre: {
                let (lo, hi) = bounds(self.reference());
                0.5 * (lo + hi)
            },
        })
    }
}
