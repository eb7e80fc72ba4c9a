//! A shell's quantities per node, for frames that list the nodes as
//! particles: each node's share of the mass and of the strain energy.
//! A quadrature point's share goes to the nodes of its stencil in
//! proportion to their shape functions, which sum to one (the MLS
//! partition of unity), so the shares sum to the shell's totals.

use super::error::ShellError;
use super::kirchhoff::energy;
use super::model::ShellModel;
use crate::math::{Real, Vector};

impl ShellModel {
    /// Each node's lumped mass: the row sums of the consistent mass,
    /// `m_I = sum_g rho t N_I(g) w_g`, which add up to the shell's mass.
    pub fn lumped_masses(&self) -> Vec<Real> {
        let areal = self.material().density * self.material().thickness;
        self.distribute(|_| Some(areal))
            .unwrap_or_else(|_| vec![0.0; self.node_count()])
    }

    /// Each node's share of the membrane and bending energy at nodal
    /// displacements `u` (the supports' springs not included); they add
    /// up to the shell's strain energy.
    ///
    /// # Errors
    /// [`ShellError::Folded`] where the deformed surface folds flat.
    pub fn nodal_energies(&self, u: &[Vector]) -> Result<Vec<Real>, ShellError> {
        let x: Vec<Vector> = self.reference().iter().zip(u).map(|(a, b)| a + b).collect();
        let thickness = self.material().thickness;
        self.distribute(|p| energy(&p.reference, thickness, &p.stencil.local(&x)))
    }

    /// `sum_g density(g) N_I(g) w_g` per node, the density per unit
    /// reference area given at each quadrature point (`None`: folded).
    fn distribute(
        &self,
        density: impl Fn(&super::model::SurfacePoint) -> Option<Real>,
    ) -> Result<Vec<Real>, ShellError> {
        let mut out = vec![0.0; self.node_count()];
        for p in self.points() {
            let value =
                density(p).ok_or(ShellError::Folded { at: p.at })? * p.weight * p.reference.area;
            for (&k, row) in p.stencil.nodes.iter().zip(&p.stencil.rows) {
                out[k as usize] += row[0] * value;
            }
        }
        Ok(out)
    }
}
