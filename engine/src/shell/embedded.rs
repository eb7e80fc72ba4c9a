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

/// Points embedded in a shell.
#[derive(Debug, Clone)]
pub struct Embedded {
    stencils: Vec<Stencil>,
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

    /// The points moved by nodal displacements `displacement`.
    pub fn positions(&self, displacement: &[Vector]) -> Vec<Vector> {
        self.stencils
            .par_iter()
            .zip(&self.rest)
            .map(|(s, p)| p + s.value(displacement))
            .collect()
    }

    /// The deformed middle surface's unit normals at the points, for
    /// nodal positions `nodes` (reference plus displacement); zero where
    /// the surface has folded flat.
    pub fn normals(&self, nodes: &[Vector]) -> Vec<Vector> {
        self.stencils
            .par_iter()
            .map(|s| {
                let q = s.local(nodes);
                q[0].cross(&q[1])
                    .try_normalize(0.0)
                    .unwrap_or_else(Vector::zeros)
            })
            .collect()
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
        let stencils = at
            .par_iter()
            .map(|&u| self.stencil(u))
            .collect::<Result<_, _>>()?;
        Ok(Embedded {
            stencils,
            rest: rest.to_vec(),
        })
    }
}
