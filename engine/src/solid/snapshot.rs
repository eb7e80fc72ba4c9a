//! An elastic solid's state as a snapshot keeps it: positions,
//! velocities, plastic strains, a reference shape that plastic flow
//! re-based, and the one solver decision a step carries over (whether
//! `auto` switched to Cholesky). The integrators' buffers are scratch and
//! stay out.

use super::body::Body;
use super::elastic::ElasticSolid;
use super::fracture::{FractureSnapshot, SearchCache, lengthened};
use super::integrate::Integrator;
use super::topology::Topology;
use crate::approx::mls::{Mls, MlsParams};
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
    /// Each particle's support radius once resampling split some (the
    /// particles past those the solid was built with are the new ones;
    /// `reference` then holds every particle's reference position and
    /// volume); `None` for a solid that holds the particles it was built
    /// with.
    pub radii: Option<Vec<Real>>,
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
            reference: (rebases || body.radii.is_some())
                .then(|| (body.rest.clone(), body.volumes.clone())),
            escalated: self.integrator.escalated(),
            fracture: body.fracture_snapshot(),
            radii: body.radii.clone(),
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
        let resized = resize(&self.body, state)?;
        let topology = check(resized.as_ref().unwrap_or(&self.body), state)?;
        if let Some(resized) = resized {
            self.body = resized;
            self.integrator = Integrator::new(&self.body.params.integrator);
        }
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

/// The body with the particles of a resampled `state` (or with those it
/// was built with, for a state taken before any split, where `body` has
/// split since): reference shape, volumes, masses, radii, anchors and
/// neighbourhoods, its cracks to be put back by the caller. `None` where
/// `state` holds as many particles as `body` with the same radii rule.
///
/// # Errors
/// [`SnapshotError`] for a count past the solid's capacity or under the
/// particles it was built with, radii or a reference shape out of range,
/// or a shape whose pairs could not be bounded; `body` is unchanged.
fn resize(body: &Body, state: &SolidSnapshot) -> Result<Option<Body>, SnapshotError> {
    let params = &body.params;
    let n = state.positions.len();
    let (rest, volumes, radii) = match (&state.radii, &body.radii) {
        (None, None) => return Ok(None),
        (None, Some(_)) => {
            let built = body.built;
            let volume = params.particle_volume();
            (body.rest[..built].to_vec(), vec![volume; built], None)
        }
        (Some(radii), _) => {
            if n < body.built || n > body.capacity {
                return Err(SnapshotError::Length {
                    what: "particles of a resampled solid (at least those built, at most its capacity)",
                    expected: body.capacity,
                    got: n,
                });
            }
            let Some((rest, volumes)) = &state.reference else {
                return Err(SnapshotError::Length {
                    what: "reference positions of a resampled solid",
                    expected: n,
                    got: 0,
                });
            };
            check_length("support radii", radii.len(), n)?;
            if let Some(index) = radii
                .iter()
                .position(|&r| !(r > 0.0 && r <= params.support))
            {
                return Err(SnapshotError::Invalid {
                    what: "support radius (positive, at most the solid's)",
                    index,
                    value: radii[index],
                });
            }
            check_vectors("reference positions", rest, n)?;
            check_volumes(volumes, n)?;
            check_crowding(rest, params.support, body.topology.owner.len())?;
            (rest.clone(), volumes.clone(), Some(radii.clone()))
        }
    };
    let mut grown = body.clone();
    let count = rest.len();
    grown.masses = volumes.iter().map(|v| v * params.density).collect();
    grown.fixed.resize(count, false);
    let mls = Mls::new(params.dim, MlsParams::new(params.order, params.support))
        .expect("the solid's MLS parameters were valid when it was built");
    let (topology, extra) = match &radii {
        Some(radii) => Topology::build_with_radii(
            &rest,
            radii,
            (params.dim, params.order, params.support),
            |_, _| 0.0,
            lengthened(&mls),
        ),
        None => Topology::build(&rest, params.dim, params.order, params.support).map(|t| {
            let edges = t.owner.len();
            (t, vec![0.0; edges])
        }),
    }
    .expect("the solid's MLS parameters were valid when it was built");
    if let Some(fracture) = &mut grown.fracture {
        fracture.extra = extra;
        fracture.fragments = vec![0; count];
        fracture.search = SearchCache::default();
    }
    grown.topology = topology;
    grown.rest = rest;
    grown.volumes = volumes;
    grown.radii = radii;
    grown.positions.resize(count, Vector::zeros());
    grown.velocities.resize(count, Vector::zeros());
    if let Some(plastic) = &mut grown.plastic {
        plastic.resize(count, Matrix3::zeros());
    }
    Ok(Some(grown))
}

/// Reference volumes: `n` of them, each positive and finite.
fn check_volumes(volumes: &[Real], n: usize) -> Result<(), SnapshotError> {
    check_length("reference volumes", volumes.len(), n)?;
    if let Some(index) = volumes.iter().position(|&v| !(v > 0.0 && v.is_finite())) {
        return Err(SnapshotError::Invalid {
            what: "reference volumes",
            index,
            value: volumes[index],
        });
    }
    Ok(())
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
    check_volumes(volumes, n)?;
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
