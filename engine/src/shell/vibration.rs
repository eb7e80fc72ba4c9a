//! Free vibration about the reference: the lowest modes of
//! `K x = omega^2 M x` with the linearised stiffness, the supports'
//! penalties and the consistent mass (Guo–Qin Eq. 16-17: `rho t` over the
//! parametric domain with the area element), by the shift-and-invert
//! Krylov–Schur eigensolver the modal solids use (`linalg/eigen.rs`).

use super::assembly::{Assembly, GrabBlocks, Support};
use super::error::ShellError;
use super::model::ShellModel;
use crate::cancel::Cancel;
use crate::linalg::eigen::{EigenParams, Mass, lowest_modes};
use crate::math::{Real, Vector};

/// The lowest free-vibration modes of a shell.
#[derive(Debug, Clone, PartialEq)]
pub struct ShellModes {
    /// Angular frequencies `omega`, ascending (zero for a free rigid
    /// motion).
    pub frequencies: Vec<Real>,
    /// Each mode's nodal coefficients, mass-normalised.
    pub shapes: Vec<Vec<Vector>>,
}

impl ShellModel {
    /// The `count` lowest modes of the shell held by `supports` (penalty
    /// scale `penalty`, as the static route's).
    ///
    /// # Errors
    /// [`ShellError`]: a zero density (no mass), a support off the chart,
    /// the eigensolver's refusals, cancellation.
    pub fn vibration_modes(
        &self,
        supports: &[Support],
        count: usize,
        penalty: Real,
        cancel: &Cancel,
    ) -> Result<ShellModes, ShellError> {
        if self.material().density <= 0.0 {
            return Err(ShellError::Parameter {
                what: "density",
                got: self.material().density,
                range: "a value > 0 (free vibration needs mass)",
            });
        }
        let mut assembly = Assembly::new(self, supports, &[], penalty, GrabBlocks::InPattern)?;
        assembly.forces(self, &vec![Vector::zeros(); self.node_count()])?;
        let (mut stiffness, mut mass) = (Vec::new(), Vec::new());
        let assembly = &assembly;
        assembly.pattern.assemble(&mut stiffness, |node, column| {
            assembly.column(self, node, column, 1.0, 0.0)
        });
        assembly.pattern.assemble(&mut mass, |node, column| {
            assembly.column(self, node, column, 0.0, 1.0)
        });
        let params = EigenParams {
            count,
            ..EigenParams::default()
        };
        let modes = lowest_modes(
            &assembly.pattern,
            &stiffness,
            Mass::Consistent(&mass),
            &params,
            cancel,
        )?;
        let n = assembly.pattern.size();
        Ok(ShellModes {
            frequencies: modes
                .eigenvalues
                .iter()
                .map(|l| l.max(0.0).sqrt())
                .collect(),
            shapes: modes
                .vectors
                .chunks_exact(n)
                .map(|x| {
                    x.chunks_exact(3)
                        .map(|c| Vector::new(c[0], c[1], c[2]))
                        .collect()
                })
                .collect(),
        })
    }
}
