//! Snapshots (`snapshot.proto`): a world's state both ways. Vectors travel
//! as flat `x y z` arrays of doubles, so every value crosses bit for bit.
//! What arrives is only shaped here (lengths multiple of 3, required
//! messages present); the engine checks the values against the world it
//! restores them into.

use crate::error::{Result, WireError, required};
use crate::scene::{to_vec3, vec3};
use meshless_engine::efg::ModalState;
use meshless_engine::fluid::FluidSnapshot;
use meshless_engine::math::{Real, Vector};
use meshless_engine::rigid::{BodyState, Rotation};
use meshless_engine::shell::ShellState;
use meshless_engine::solid::fracture::{Crack, FrontNode};
use meshless_engine::solid::{FractureSnapshot, SolidSnapshot};
use meshless_engine::{Clock, SystemState, WorldState};
use meshless_proto::v1;
use nalgebra::{Matrix3, Quaternion};

/// `state` as its message.
pub fn world_state_to_proto(state: &WorldState) -> v1::WorldSnapshot {
    v1::WorldSnapshot {
        step: state.clock.step,
        time: state.clock.time,
        systems: state.systems.iter().map(system_to_proto).collect(),
    }
}

fn system_to_proto(system: &SystemState) -> v1::SystemSnapshot {
    let kind = match system {
        SystemState::Fluid {
            fluid,
            removals,
            insertions,
            energy_start,
            ..
        } => v1::system_snapshot::Kind::Fluid(v1::FluidSnapshot {
            ids: fluid.ids.clone(),
            positions: flatten(&fluid.positions),
            velocities: flatten(&fluid.velocities),
            densities: fluid.densities.clone(),
            pressures: fluid.pressures.clone(),
            max_acceleration: fluid.max_acceleration,
            substeps_since_reorder: fluid.substeps_since_reorder,
            warm_start: fluid.warm_start.clone(),
            bodies: fluid.bodies.iter().map(body_to_proto).collect(),
            removals: removals.clone(),
            energy_start: energy_start.map(|(e, _)| e),
            energy_scale: energy_start.map(|(_, s)| s),
            next_id: Some(fluid.next_id),
            insert_positions: flatten(&insertions.iter().map(|p| p.0).collect::<Vec<_>>()),
            insert_velocities: flatten(&insertions.iter().map(|p| p.1).collect::<Vec<_>>()),
        }),
        SystemState::Solid {
            solid,
            energy_start,
            ..
        } => v1::system_snapshot::Kind::Solid(v1::SolidSnapshot {
            fracture: solid.fracture.as_ref().map(fracture_to_proto),
            positions: flatten(&solid.positions),
            velocities: flatten(&solid.velocities),
            plastic: solid
                .plastic
                .iter()
                .flatten()
                // Row by row.
                .flat_map(|m| m.transpose().iter().copied().collect::<Vec<_>>())
                .collect(),
            rest: solid
                .reference
                .as_ref()
                .map(|(rest, _)| flatten(rest))
                .unwrap_or_default(),
            volumes: solid
                .reference
                .as_ref()
                .map(|(_, v)| v.clone())
                .unwrap_or_default(),
            escalated: solid.escalated,
            radii: solid.radii.clone().unwrap_or_default(),
            energy_start: energy_start.map(|(e, _)| e),
            energy_scale: energy_start.map(|(_, s)| s),
        }),
        SystemState::Modal { state, .. } => v1::system_snapshot::Kind::Modal(v1::ModalSnapshot {
            amplitudes: state.amplitudes.clone(),
            velocities: state.velocities.clone(),
        }),
        SystemState::Shell { state, .. } => v1::system_snapshot::Kind::Shell(v1::ShellSnapshot {
            displacements: flatten(&state.displacement),
            velocities: flatten(&state.velocity),
            accelerations: flatten(&state.acceleration),
            time: state.time,
        }),
    };
    v1::SystemSnapshot {
        index: u32::try_from(system.index()).unwrap_or(u32::MAX),
        kind: Some(kind),
    }
}

fn body_to_proto(body: &BodyState) -> v1::RigidBodySnapshot {
    let q = body.orientation.quaternion();
    v1::RigidBodySnapshot {
        position: Some(to_vec3(body.position.into())),
        orientation: vec![q.w, q.i, q.j, q.k],
        velocity: Some(to_vec3(body.velocity.into())),
        angular_velocity: Some(to_vec3(body.angular_velocity.into())),
        time: body.time,
    }
}

/// The state a message holds, shaped but not yet checked against a
/// world (see [`meshless_engine::World::restored`]).
///
/// # Errors
/// [`WireError`] naming the field of a missing message, an array that is
/// not whole vectors, or a system without a kind.
pub fn world_state_from_proto(message: v1::WorldSnapshot) -> Result<WorldState> {
    let v1::WorldSnapshot {
        step,
        time,
        systems,
    } = message;
    let systems = systems
        .into_iter()
        .enumerate()
        .map(|(k, s)| system_from_proto(s, &format!("world.systems[{k}]")))
        .collect::<Result<_>>()?;
    Ok(WorldState {
        clock: Clock { step, time },
        systems,
    })
}

fn system_from_proto(message: v1::SystemSnapshot, field: &str) -> Result<SystemState> {
    let v1::SystemSnapshot { index, kind } = message;
    let index = index as usize;
    Ok(match required(kind, &format!("{field}.kind"))? {
        v1::system_snapshot::Kind::Fluid(f) => {
            let v1::FluidSnapshot {
                ids,
                positions,
                velocities,
                densities,
                pressures,
                max_acceleration,
                substeps_since_reorder,
                warm_start,
                bodies,
                removals,
                energy_start,
                energy_scale,
                next_id,
                insert_positions,
                insert_velocities,
            } = f;
            let field = format!("{field}.fluid");
            let energy_start = energy_pair(energy_start, energy_scale, &field)?;
            SystemState::Fluid {
                index,
                fluid: FluidSnapshot {
                    next_id: next_id.unwrap_or(ids.len().try_into().unwrap_or(u32::MAX)),
                    ids,
                    positions: vectors(positions, &format!("{field}.positions"))?,
                    velocities: vectors(velocities, &format!("{field}.velocities"))?,
                    densities,
                    pressures,
                    max_acceleration,
                    substeps_since_reorder,
                    warm_start,
                    bodies: bodies
                        .into_iter()
                        .enumerate()
                        .map(|(k, b)| body_from_proto(b, &format!("{field}.bodies[{k}]")))
                        .collect::<Result<_>>()?,
                },
                removals,
                insertions: {
                    let x = vectors(insert_positions, &format!("{field}.insert_positions"))?;
                    let v = vectors(insert_velocities, &format!("{field}.insert_velocities"))?;
                    if x.len() != v.len() {
                        return Err(WireError::new(
                            format!("{field}.insert_velocities"),
                            format!(
                                "holds {} vectors; give one per new particle ({})",
                                v.len(),
                                x.len()
                            ),
                        ));
                    }
                    x.into_iter().zip(v).collect()
                },
                energy_start,
            }
        }
        v1::system_snapshot::Kind::Modal(m) => {
            let v1::ModalSnapshot {
                amplitudes,
                velocities,
            } = m;
            SystemState::Modal {
                index,
                state: ModalState {
                    amplitudes,
                    velocities,
                },
            }
        }
        v1::system_snapshot::Kind::Shell(s) => {
            let v1::ShellSnapshot {
                displacements,
                velocities,
                accelerations,
                time,
            } = s;
            let field = format!("{field}.shell");
            SystemState::Shell {
                index,
                state: ShellState {
                    displacement: vectors(displacements, &format!("{field}.displacements"))?,
                    velocity: vectors(velocities, &format!("{field}.velocities"))?,
                    acceleration: vectors(accelerations, &format!("{field}.accelerations"))?,
                    time,
                },
            }
        }
        v1::system_snapshot::Kind::Solid(s) => {
            let v1::SolidSnapshot {
                positions,
                velocities,
                plastic,
                rest,
                volumes,
                escalated,
                energy_start,
                energy_scale,
                fracture,
                radii,
            } = s;
            let field = format!("{field}.solid");
            let energy_start = energy_pair(energy_start, energy_scale, &field)?;
            let plastic = if plastic.is_empty() {
                None
            } else {
                if !plastic.len().is_multiple_of(9) {
                    return Err(WireError::new(
                        format!("{field}.plastic"),
                        format!("holds {} values: 9 per particle expected", plastic.len()),
                    ));
                }
                Some(
                    plastic
                        .chunks_exact(9)
                        .map(Matrix3::from_row_slice)
                        .collect(),
                )
            };
            let reference = if rest.is_empty() && volumes.is_empty() {
                None
            } else {
                Some((vectors(rest, &format!("{field}.rest"))?, volumes))
            };
            SystemState::Solid {
                index,
                solid: SolidSnapshot {
                    positions: vectors(positions, &format!("{field}.positions"))?,
                    velocities: vectors(velocities, &format!("{field}.velocities"))?,
                    plastic,
                    reference,
                    escalated,
                    fracture: fracture
                        .map(|f| fracture_from_proto(f, &format!("{field}.fracture")))
                        .transpose()?,
                    radii: (!radii.is_empty()).then_some(radii),
                },
                energy_start,
            }
        }
    })
}

fn fracture_to_proto(state: &FractureSnapshot) -> v1::FractureState {
    v1::FractureState {
        cracks: state
            .cracks
            .iter()
            .map(|c| v1::CrackState {
                vertices: flatten(c.vertices()),
                triangles: c.triangles().iter().flatten().copied().collect(),
                front: c
                    .front()
                    .iter()
                    .map(|f| {
                        let [tip_a, tip_b] = f.tips();
                        v1::CrackFrontNode {
                            at: Some(to_vec3([f.at.x, f.at.y, f.at.z])),
                            heading: Some(to_vec3([f.heading.x, f.heading.y, f.heading.z])),
                            tip_a,
                            tip_b,
                            active: f.active,
                        }
                    })
                    .collect(),
            })
            .collect(),
        extra: state.extra.clone(),
        fragments: state.fragments.clone(),
    }
}

/// A fracture state, shaped: each crack's indices in range and values
/// finite (the engine checks it against the solid).
fn fracture_from_proto(state: v1::FractureState, field: &str) -> Result<FractureSnapshot> {
    let v1::FractureState {
        cracks,
        extra,
        fragments,
    } = state;
    let cracks = cracks
        .into_iter()
        .enumerate()
        .map(|(k, c)| {
            let at = format!("{field}.cracks[{k}]");
            let v1::CrackState {
                vertices,
                triangles,
                front,
            } = c;
            let vertices = vectors(vertices, &format!("{at}.vertices"))?;
            if !triangles.len().is_multiple_of(3) {
                return Err(WireError::new(
                    format!("{at}.triangles"),
                    format!("holds {} indices: 3 per triangle expected", triangles.len()),
                ));
            }
            let triangles = triangles
                .chunks_exact(3)
                .map(|t| [t[0], t[1], t[2]])
                .collect();
            let front = front
                .into_iter()
                .enumerate()
                .map(|(j, f)| {
                    let node = format!("{at}.front[{j}]");
                    let v1::CrackFrontNode {
                        at: position,
                        heading,
                        tip_a,
                        tip_b,
                        active,
                    } = f;
                    let position = Vector::from(vec3(required(position, &format!("{node}.at"))?));
                    let heading =
                        Vector::from(vec3(required(heading, &format!("{node}.heading"))?));
                    Ok(FrontNode::new(position, heading, [tip_a, tip_b], active))
                })
                .collect::<Result<Vec<_>>>()?;
            Crack::from_parts(vertices, triangles, front).map_err(|e| WireError::new(at, e))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(FractureSnapshot {
        cracks,
        extra,
        fragments,
    })
}

/// An energy watch's start `(E_0, scale)` from its two optional fields,
/// which come together.
fn energy_pair(
    start: Option<Real>,
    scale: Option<Real>,
    field: &str,
) -> Result<Option<(Real, Real)>> {
    match (start, scale) {
        (Some(e), Some(s)) => Ok(Some((e, s))),
        (None, None) => Ok(None),
        _ => Err(WireError::new(
            format!("{field}.energy_start"),
            "energy_start and energy_scale come together",
        )),
    }
}

fn body_from_proto(message: v1::RigidBodySnapshot, field: &str) -> Result<BodyState> {
    let v1::RigidBodySnapshot {
        position,
        orientation,
        velocity,
        angular_velocity,
        time,
    } = message;
    let &[w, i, j, k] = orientation.as_slice() else {
        return Err(WireError::new(
            format!("{field}.orientation"),
            format!(
                "holds {} values: a quaternion w x y z expected",
                orientation.len()
            ),
        ));
    };
    let vector = |v: Option<v1::Vec3>, name: &str| -> Result<Vector> {
        Ok(vec3(required(v, &format!("{field}.{name}"))?).into())
    };
    Ok(BodyState {
        position: vector(position, "position")?,
        // Kept as stored, bit for bit; the engine refuses one that is not
        // unit.
        orientation: Rotation::new_unchecked(Quaternion::new(w, i, j, k)),
        velocity: vector(velocity, "velocity")?,
        angular_velocity: vector(angular_velocity, "angular_velocity")?,
        time,
    })
}

/// Vectors as the protocol's flat arrays: `x y z` per vector.
pub fn flatten(values: &[Vector]) -> Vec<Real> {
    values.iter().flat_map(|v| [v.x, v.y, v.z]).collect()
}

/// A flat `x y z` array as vectors.
///
/// # Errors
/// [`WireError`] naming `field` when the length is no multiple of 3.
pub fn vectors(values: Vec<Real>, field: &str) -> Result<Vec<Vector>> {
    if !values.len().is_multiple_of(3) {
        return Err(WireError::new(
            field,
            format!("holds {} values: 3 per vector expected", values.len()),
        ));
    }
    Ok(values
        .chunks_exact(3)
        .map(|c| Vector::new(c[0], c[1], c[2]))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use meshless_engine::{BuildOptions, Scene};

    /// A 2D tank with a floating box and a plastic beam, stepped: every
    /// kind of state a message carries.
    fn stepped_world() -> meshless_engine::World {
        let scene = Scene::from_toml_str(
            r#"
            dimension = 2
            [domain]
            min = [0.0, 0.0, 0.0]
            max = [1.0, 1.0, 0.0]
            [time]
            dt = 0.004
            [[systems]]
            kind = "fluid"
            solver = "dfsph"
            spacing = 0.04
            [[systems.blocks]]
            region = { min = [0.0, 0.0, 0.0], max = [0.5, 0.3, 0.0] }
            [[systems]]
            kind = "rigid_body"
            shape = { type = "box", half_extents = [0.06, 0.06, 0.06] }
            position = [0.7, 0.5, 0.0]
            orientation = [0.0, 0.0, 0.3]
            motion = "dynamic"
            density = 500.0
            [[systems]]
            kind = "solid"
            shape = { type = "box", half_extents = [0.2, 0.04, 0.05] }
            position = [0.5, 0.8, 0.0]
            spacing = 0.02
            young = 1e5
            plasticity = { yield = 0.001, creep = 0.5, max = 1.0, rebase = 0.01 }
            "#,
        )
        .expect("parses");
        let mut world = scene.build(&BuildOptions::default()).expect("builds");
        for _ in 0..3 {
            world.step().expect("stable");
        }
        world
    }

    #[test]
    fn a_world_state_round_trips_bit_for_bit() {
        let state = stepped_world().state();
        let back = world_state_from_proto(world_state_to_proto(&state)).expect("converts");
        assert_eq!(back, state);
    }

    #[test]
    fn misshapen_messages_name_their_field() {
        let good = world_state_to_proto(&stepped_world().state());
        let refused = |change: &dyn Fn(&mut v1::WorldSnapshot)| {
            let mut message = good.clone();
            change(&mut message);
            world_state_from_proto(message).expect_err("refused").field
        };
        fn fluid(m: &mut v1::WorldSnapshot) -> &mut v1::FluidSnapshot {
            match &mut m.systems[0].kind {
                Some(v1::system_snapshot::Kind::Fluid(f)) => f,
                _ => panic!("the fluid comes first"),
            }
        }
        assert_eq!(
            refused(&|m| {
                fluid(m).velocities.pop();
            }),
            "world.systems[0].fluid.velocities"
        );
        assert_eq!(
            refused(&|m| {
                fluid(m).bodies[0].orientation.pop();
            }),
            "world.systems[0].fluid.bodies[0].orientation"
        );
        assert_eq!(
            refused(&|m| fluid(m).energy_scale = None),
            "world.systems[0].fluid.energy_start"
        );
        assert_eq!(
            refused(&|m| m.systems[1].kind = None),
            "world.systems[1].kind"
        );
    }

    /// The shipped brittle beam stepped until its cracks run.
    fn cracked_world() -> meshless_engine::World {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/brittle_beam.toml");
        let scene = Scene::from_toml_file(&path).expect("parses");
        let mut world = scene.build(&BuildOptions::default()).expect("builds");
        while world
            .solids()
            .next()
            .and_then(|(_, s)| s.fracture())
            .is_some_and(|f| f.cracks().is_empty())
        {
            world.step().expect("stable");
        }
        world
    }

    #[test]
    fn a_cracked_solid_round_trips_and_forged_cracks_are_refused() {
        let state = cracked_world().state();
        let message = world_state_to_proto(&state);
        let back = world_state_from_proto(message.clone()).expect("converts");
        assert_eq!(back, state);
        let refused = |change: &dyn Fn(&mut v1::FractureState)| {
            let mut m = message.clone();
            let Some(v1::system_snapshot::Kind::Solid(solid)) = &mut m.systems[0].kind else {
                panic!("the beam is the only system");
            };
            change(solid.fracture.as_mut().expect("it fractures"));
            world_state_from_proto(m).expect_err("refused").to_string()
        };
        let error = refused(&|f| f.cracks[0].triangles[0] = 1_000_000);
        assert!(
            error.contains("cracks[0]") && error.contains("triangle 0"),
            "{error}"
        );
        let error = refused(&|f| f.cracks[0].vertices[0] = f64::NAN);
        assert!(error.contains("not finite"), "{error}");
        let error = refused(&|f| f.cracks[0].front[0].at = None);
        assert!(error.contains("front[0].at"), "{error}");
        let error = refused(&|f| {
            f.cracks[0].triangles.pop();
        });
        assert!(error.contains("3 per triangle"), "{error}");
    }
}
