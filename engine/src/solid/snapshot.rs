//! An elastic solid's state as a snapshot keeps it: positions,
//! velocities, plastic strains, a reference shape that plastic flow
//! re-based, and the one solver decision a step carries over (whether
//! `auto` switched to Cholesky). The integrators' buffers are scratch and
//! stay out.

use super::body::Body;
use super::elastic::ElasticSolid;
use super::integrate::Integrator;
use super::topology::Topology;
use crate::math::{Real, Vector};
use crate::snapshot::{SnapshotError, check_finite, check_length, check_vectors};
use nalgebra::Matrix3;

/// The evolving state of an elastic solid, per particle in scene order.
#[derive(Debug, Clone, PartialEq)]
pub struct SolidSnapshot {
    /// Positions, m.
    pub positions: Vec<Vector>,
    /// Velocities, m/s.
    pub velocities: Vec<Vector>,
    /// Plastic strains; `None` for an elastic solid.
    pub plastic: Option<Vec<Matrix3<Real>>>,
    /// The reference shape and its volumes, for a solid whose plastic
    /// flow may re-base it; `None` for the rest shape it was built with.
    pub reference: Option<(Vec<Vector>, Vec<Real>)>,
    /// Whether the implicit integrator's `auto` solver switched this body
    /// to Cholesky.
    pub escalated: bool,
}

impl ElasticSolid {
    /// The state a snapshot keeps.
    pub fn snapshot(&self) -> SolidSnapshot {
        let body = &self.body;
        let rebases = body
            .params
            .plasticity
            .is_some_and(|rule| rule.rebase.is_some());
        SolidSnapshot {
            positions: body.positions.clone(),
            velocities: body.velocities.clone(),
            plastic: body.plastic.clone(),
            reference: rebases.then(|| (body.rest.clone(), body.volumes.clone())),
            escalated: self.integrator.escalated(),
        }
    }

    /// Puts `state` back into a solid built from the scene it was taken
    /// in; a re-based reference shape gets its neighbourhoods and shape
    /// functions again.
    ///
    /// # Errors
    /// [`SnapshotError`] when the state does not fit this solid; the solid
    /// is then unchanged.
    pub fn restore_snapshot(&mut self, state: &SolidSnapshot) -> Result<(), SnapshotError> {
        let topology = check(&self.body, state)?;
        let body = &mut self.body;
        body.positions.clone_from(&state.positions);
        body.velocities.clone_from(&state.velocities);
        body.plastic.clone_from(&state.plastic);
        if let (Some((rest, volumes)), Some(topology)) = (&state.reference, topology) {
            body.rest.clone_from(rest);
            body.volumes.clone_from(volumes);
            body.topology = topology;
        }
        self.integrator.set_escalated(state.escalated);
        Ok(())
    }
}

/// Checks `state` against `body`, and builds the neighbourhoods of a
/// re-based reference shape (which a degenerate shape can fail).
fn check(body: &Body, state: &SolidSnapshot) -> Result<Option<Topology>, SnapshotError> {
    let n = body.len();
    check_vectors("positions", &state.positions, n)?;
    check_vectors("velocities", &state.velocities, n)?;
    match (&body.plastic, &state.plastic) {
        (None, None) => {}
        (Some(_), Some(plastic)) => {
            check_length("plastic strains", plastic.len(), n)?;
            let flat: Vec<Real> = plastic.iter().flat_map(|m| m.iter().copied()).collect();
            check_finite("plastic strains", &flat)?;
        }
        (expected, got) => {
            return Err(SnapshotError::Length {
                what: "plastic strains",
                expected: expected.as_ref().map_or(0, Vec::len),
                got: got.as_ref().map_or(0, Vec::len),
            });
        }
    }
    let Some((rest, volumes)) = &state.reference else {
        return Ok(None);
    };
    check_vectors("reference positions", rest, n)?;
    check_length("reference volumes", volumes.len(), n)?;
    if let Some(index) = volumes.iter().position(|&v| !(v > 0.0 && v.is_finite())) {
        return Err(SnapshotError::Invalid {
            what: "reference volumes",
            index,
            value: volumes[index],
        });
    }
    if *rest == body.rest {
        return Ok(Some(body.topology.clone()));
    }
    let params = &body.params;
    Topology::build(rest, params.dim, params.order, params.support)
        .map(Some)
        .map_err(|_| SnapshotError::Invalid {
            what: "reference shape (no MLS fit)",
            index: 0,
            value: 0.0,
        })
}

impl Integrator {
    /// Whether `auto` switched the body to Cholesky (never, for the
    /// explicit integrator).
    pub fn escalated(&self) -> bool {
        match self {
            Self::Explicit(_) => false,
            Self::Implicit(i) => i.escalated,
        }
    }

    /// Sets what [`Self::escalated`] reads; the explicit integrator has
    /// nothing to set.
    pub fn set_escalated(&mut self, escalated: bool) {
        if let Self::Implicit(i) = self {
            i.escalated = escalated;
        }
    }
}
