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
use crate::math::{Real, Vector};
use rayon::prelude::*;

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
/// The weights are kept in single precision and apart from the
/// stencils' rows, which also hold second derivatives: the surface update
/// reads them every frame for tens of thousands of points, so their bytes
/// are its cost (a third of the rows' in all), and frames carry
/// single-precision positions anyway (the weights' rounding moves a point
/// by about 1e-7 of its displacement).
#[derive(Debug, Clone)]
pub struct Embedded {
    /// Point `i`'s entries are `starts[i]..starts[i + 1]`.
    starts: Vec<u32>,
    nodes: Vec<u32>,
    /// `N`, `N_,1`, `N_,2` of each entry.
    weights: Vec<[f32; 3]>,
    rest: Vec<Vector>,
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
        let placed: Vec<Vector> = reference
            .iter()
            .zip(displacement)
            .map(|(x, u)| x + u)
            .collect();
        (0..self.rest.len())
            .into_par_iter()
            .with_min_len(1024)
            .map(|i| {
                let range = self.starts[i] as usize..self.starts[i + 1] as usize;
                let (mut d, mut t1, mut t2) = (Vector::zeros(), Vector::zeros(), Vector::zeros());
                for (&k, w) in self.nodes[range.clone()].iter().zip(&self.weights[range]) {
                    let k = k as usize;
                    d += Real::from(w[0]) * displacement[k];
                    t1 += Real::from(w[1]) * placed[k];
                    t2 += Real::from(w[2]) * placed[k];
                }
                let normal = t1
                    .cross(&t2)
                    .try_normalize(0.0)
                    .unwrap_or_else(Vector::zeros);
                (self.rest[i] + d, normal)
            })
            .unzip()
    }
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
        let (mut nodes, mut weights) = (Vec::new(), Vec::new());
        starts.push(0);
        for s in &stencils {
            nodes.extend_from_slice(&s.nodes);
            weights.extend(
                s.rows
                    .iter()
                    .map(|r| [r[0] as f32, r[1] as f32, r[2] as f32]),
            );
            starts.push(
                u32::try_from(nodes.len()).map_err(|_| ShellError::TooLarge {
                    nodes: self.node_count(),
                })?,
            );
        }
        Ok(Embedded {
            starts,
            nodes,
            weights,
            rest: rest.to_vec(),
        })
    }
}
