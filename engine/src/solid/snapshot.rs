//! An elastic solid's state as a snapshot keeps it: positions,
//! velocities, plastic strains, a reference shape that plastic flow
//! re-based, and the one solver decision a step carries over (whether
//! `auto` switched to Cholesky). The integrators' buffers are scratch and
//! stay out.

use super::body::Body;
use super::elastic::ElasticSolid;
use super::fracture::FractureSnapshot;
use super::integrate::Integrator;
use super::topology::Topology;
use crate::math::{Real, Vector};
use crate::snapshot::{SnapshotError, check_finite, check_length, check_vectors};
use nalgebra::Matrix3;
use std::collections::HashMap;

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
    /// The cracks of a fracturing solid; `None` for one that cannot crack.
    pub fracture: Option<FractureSnapshot>,
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
            fracture: body.fracture_snapshot(),
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
        if let Some(fracture) = &state.fracture {
            body.restore_fracture(fracture);
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
    body.check_fracture(state.fracture.as_ref())?;
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
    check_crowding(rest, params.support, body.topology.owner.len())?;
    Topology::build(rest, params.dim, params.order, params.support)
        .map(Some)
        .map_err(|_| SnapshotError::Invalid {
            what: "reference shape (no MLS fit)",
            index: 0,
            value: 0.0,
        })
}

/// How many times the neighbour pairs of the shape a solid was built
/// with a re-based reference shape may bound, by [`pair_bound`]: plastic
/// flow crowds a shape by a few times at most, while one forged onto a
/// point (its checksum recomputed) holds n^2 pairs, so that building its
/// neighbourhoods would take memory and time without bound.
const MAX_PAIR_GROWTH: u64 = 64;

/// Refuses a reference shape whose neighbour pairs could exceed
/// [`MAX_PAIR_GROWTH`] times `built_pairs` (the built shape's, at least
/// one per particle), before any neighbourhood is searched.
fn check_crowding(rest: &[Vector], support: Real, built_pairs: usize) -> Result<(), SnapshotError> {
    let limit = MAX_PAIR_GROWTH.saturating_mul(built_pairs.max(rest.len()) as u64);
    let bound = pair_bound(rest, support);
    if bound > limit {
        return Err(SnapshotError::Crowded { bound, limit });
    }
    Ok(())
}

/// An upper bound on the pairs of `points` closer than `support`: each
/// point pairs at most with the points of its own and the neighbouring
/// cells of side `support`. Linear in the points (a hash of the cells).
fn pair_bound(points: &[Vector], support: Real) -> u64 {
    let mut cells: HashMap<[i64; 3], u64> = HashMap::with_capacity(points.len());
    let cell_of = |p: &Vector| p.map(|x| (x / support).floor() as i64);
    for p in points {
        let c = cell_of(p);
        *cells.entry([c.x, c.y, c.z]).or_default() += 1;
    }
    let mut bound = 0u64;
    for (cell, &count) in &cells {
        let mut near = 0u64;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let key = [cell[0] + dx, cell[1] + dy, cell[2] + dz];
                    near += cells.get(&key).copied().unwrap_or(0);
                }
            }
        }
        bound = bound.saturating_add(count.saturating_mul(near));
    }
    bound
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
