//! Conversions of the design messages (`design.proto`): constraints and
//! their edits, the optimiser's settings, its progress and results, and
//! the table of the enum declared there.
//!
//! A `Constraint` message carries either a constraint the optimiser
//! meets (handle, velocity, obstacle: the engine's
//! [`Constraint`]) or a runtime control of the world (a grab: the
//! engine's [`Control`]), which a session keeps apart; both share the
//! session's names, so they arrive as one [`SessionConstraint`].

use crate::enums::{WireEnum, enum_or, wire_enum};
use crate::error::WireError;
use crate::error::{Result, required};
use crate::scene::{aabb, shape_from_proto, to_aabb, to_shape, to_vec3, vec3};
use meshless_engine::design::{
    Constraint, ConstraintKind, DesignParams, Energies, Handle, MotionParams, Obstacle, Progress,
    Quadrature, Selection, SolveInfo, Target, Velocity, Waypoint,
};
use meshless_engine::efg::Grab;
use meshless_engine::math::{Vector, vector};
use meshless_engine::scene::Aabb;
use meshless_engine::world::{Control, ControlKind};
use meshless_proto::v1;

wire_enum! {
    /// Where the optimiser's energies are integrated.
    Quadrature <-> DesignQuadrature, "quadrature" {
        "particles" => Particles,
        "cells" => Cells,
    }
}

/// A vector that defaults to zero when unset.
fn vec3_or_zero(v: Option<v1::Vec3>) -> [f64; 3] {
    v.map_or([0.0; 3], vec3)
}

fn points(points: Vec<v1::Vec3>) -> Vec<[f64; 3]> {
    points.into_iter().map(vec3).collect()
}

fn to_points(points: &[[f64; 3]]) -> Vec<v1::Vec3> {
    points.iter().map(|&p| to_vec3(p)).collect()
}

/// A frame, iteration or particle count on the wire.
fn count(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// What a `Constraint` message holds, by the session's name.
#[derive(Debug, Clone, PartialEq)]
pub enum SessionConstraint {
    /// A constraint the optimiser meets.
    Design(Constraint),
    /// A runtime control of the world, with its name.
    Control(String, Control),
}

impl SessionConstraint {
    /// Its name, unique within a session.
    pub fn name(&self) -> &str {
        match self {
            Self::Design(c) => &c.name,
            Self::Control(name, _) => name,
        }
    }
}

/// An edit of a session's constraints, applied in order with the others
/// of its batch.
#[derive(Debug, Clone, PartialEq)]
pub enum SessionEdit {
    /// Adds a constraint whose name is new.
    Add(SessionConstraint),
    /// Replaces the constraint of the same name (of any kind).
    Replace(SessionConstraint),
    /// Removes the constraint of this name.
    Remove(String),
    /// Removes every constraint.
    Clear,
}

/// A session's constraint; `field` names the message for errors.
pub fn constraint_from_proto(c: v1::Constraint, field: &str) -> Result<SessionConstraint> {
    let v1::Constraint { name, kind } = c;
    let kind = match kind {
        Some(v1::constraint::Kind::Handle(v1::HandleConstraint {
            points,
            target,
            time,
        })) => ConstraintKind::Handle(Handle {
            points: selection_from_proto(points, &format!("{field}.handle.points"))?,
            target: target_from_proto(target, &format!("{field}.handle.target"))?,
            time,
        }),
        Some(v1::constraint::Kind::Velocity(v1::VelocityConstraint {
            time,
            velocity,
            points,
        })) => ConstraintKind::Velocity(Velocity {
            time,
            velocity: vec3(required(velocity, &format!("{field}.velocity.velocity"))?),
            points: points
                .map(|p| selection_from_proto(Some(p), &format!("{field}.velocity.points")))
                .transpose()?,
        }),
        Some(v1::constraint::Kind::Obstacle(v1::ObstacleConstraint {
            shape,
            orientation,
            path,
        })) => ConstraintKind::Obstacle(Obstacle {
            shape: shape_from_proto(shape, &format!("{field}.obstacle.shape"))?,
            orientation: vec3_or_zero(orientation),
            path: path
                .into_iter()
                .enumerate()
                .map(|(k, v1::Waypoint { time, position })| {
                    Ok(Waypoint {
                        time,
                        position: vec3(required(
                            position,
                            &format!("{field}.obstacle.path[{k}].position"),
                        )?),
                    })
                })
                .collect::<Result<_>>()?,
        }),
        Some(v1::constraint::Kind::Grab(v1::GrabConstraint {
            system,
            point,
            position,
            rotation,
        })) => {
            let grab = Grab {
                point: vector(vec3(required(point, &format!("{field}.grab.point"))?)),
                position: position.map(|p| vector(vec3(p))),
                rotation: rotation.map(|r| vector(vec3(r))),
            };
            let control = Control {
                system: system as usize,
                kind: ControlKind::Grab(grab),
            };
            return Ok(SessionConstraint::Control(name, control));
        }
        None => {
            return Err(WireError::new(
                format!("{field}.kind"),
                format!("constraint `{name}` has no kind; set handle, velocity, obstacle or grab"),
            ));
        }
    };
    Ok(SessionConstraint::Design(Constraint { name, kind }))
}

fn selection_from_proto(s: Option<v1::Selection>, field: &str) -> Result<Selection> {
    let v1::Selection { kind } = required(s, field)?;
    match kind {
        Some(v1::selection::Kind::Particles(v1::ParticleSelection { system, indices })) => {
            Ok(Selection::Particles {
                system: system as usize,
                indices,
            })
        }
        Some(v1::selection::Kind::Points(v1::PointSelection { points: p })) => {
            Ok(Selection::Points(points(p)))
        }
        Some(v1::selection::Kind::Region(region)) => {
            let Aabb { min, max } = aabb(Some(region), &format!("{field}.region"))?;
            Ok(Selection::Region { min, max })
        }
        None => Err(WireError::new(
            format!("{field}.kind"),
            "is required; select particles, points or a region",
        )),
    }
}

fn target_from_proto(t: Option<v1::DesignTarget>, field: &str) -> Result<Target> {
    let v1::DesignTarget { kind } = required(t, field)?;
    match kind {
        Some(v1::design_target::Kind::Positions(v1::PositionsTarget { positions })) => {
            Ok(Target::Positions(points(positions)))
        }
        Some(v1::design_target::Kind::Transform(v1::TransformTarget {
            translation,
            rotation,
            centre,
        })) => Ok(Target::Transform {
            translation: vec3_or_zero(translation),
            rotation: vec3_or_zero(rotation),
            centre: vec3_or_zero(centre),
        }),
        None => Err(WireError::new(
            format!("{field}.kind"),
            "is required; give positions or a transform",
        )),
    }
}

/// The wire form of an engine constraint.
pub fn constraint_to_proto(c: &Constraint) -> v1::Constraint {
    let Constraint { name, kind } = c;
    let kind = match kind {
        ConstraintKind::Handle(Handle {
            points,
            target,
            time,
        }) => v1::constraint::Kind::Handle(v1::HandleConstraint {
            points: Some(selection_to_proto(points)),
            target: Some(target_to_proto(target)),
            time: *time,
        }),
        ConstraintKind::Velocity(Velocity {
            time,
            velocity,
            points,
        }) => v1::constraint::Kind::Velocity(v1::VelocityConstraint {
            time: *time,
            velocity: Some(to_vec3(*velocity)),
            points: points.as_ref().map(selection_to_proto),
        }),
        ConstraintKind::Obstacle(Obstacle {
            shape,
            orientation,
            path,
        }) => v1::constraint::Kind::Obstacle(v1::ObstacleConstraint {
            shape: Some(to_shape(shape)),
            orientation: Some(to_vec3(*orientation)),
            path: path
                .iter()
                .map(|w| v1::Waypoint {
                    time: w.time,
                    position: Some(to_vec3(w.position)),
                })
                .collect(),
        }),
    };
    v1::Constraint {
        name: name.clone(),
        kind: Some(kind),
    }
}

/// The wire form of a runtime control called `name`.
pub fn control_to_proto(name: &str, control: &Control) -> v1::Constraint {
    let wire = |v: Vector| to_vec3([v.x, v.y, v.z]);
    let kind = match control.kind {
        ControlKind::Grab(g) => v1::constraint::Kind::Grab(v1::GrabConstraint {
            system: count(control.system),
            point: Some(wire(g.point)),
            position: g.position.map(wire),
            rotation: g.rotation.map(wire),
        }),
    };
    v1::Constraint {
        name: name.to_owned(),
        kind: Some(kind),
    }
}

/// The wire form of a session's constraint.
pub fn session_constraint_to_proto(c: &SessionConstraint) -> v1::Constraint {
    match c {
        SessionConstraint::Design(c) => constraint_to_proto(c),
        SessionConstraint::Control(name, control) => control_to_proto(name, control),
    }
}

fn selection_to_proto(s: &Selection) -> v1::Selection {
    let kind = match s {
        Selection::Particles { system, indices } => {
            v1::selection::Kind::Particles(v1::ParticleSelection {
                system: count(*system),
                indices: indices.clone(),
            })
        }
        Selection::Points(p) => v1::selection::Kind::Points(v1::PointSelection {
            points: to_points(p),
        }),
        Selection::Region { min, max } => v1::selection::Kind::Region(to_aabb(&Aabb {
            min: *min,
            max: *max,
        })),
    };
    v1::Selection { kind: Some(kind) }
}

fn target_to_proto(t: &Target) -> v1::DesignTarget {
    let kind = match t {
        Target::Positions(p) => v1::design_target::Kind::Positions(v1::PositionsTarget {
            positions: to_points(p),
        }),
        Target::Transform {
            translation,
            rotation,
            centre,
        } => v1::design_target::Kind::Transform(v1::TransformTarget {
            translation: Some(to_vec3(*translation)),
            rotation: Some(to_vec3(*rotation)),
            centre: Some(to_vec3(*centre)),
        }),
    };
    v1::DesignTarget { kind: Some(kind) }
}

/// A session's edit; `field` names the edit (`edits[3]`).
pub fn edit_from_proto(e: v1::ConstraintEdit, field: &str) -> Result<SessionEdit> {
    let v1::ConstraintEdit { edit } = e;
    match edit {
        Some(v1::constraint_edit::Edit::Add(c)) => Ok(SessionEdit::Add(constraint_from_proto(
            c,
            &format!("{field}.add"),
        )?)),
        Some(v1::constraint_edit::Edit::Replace(c)) => Ok(SessionEdit::Replace(
            constraint_from_proto(c, &format!("{field}.replace"))?,
        )),
        Some(v1::constraint_edit::Edit::Remove(name)) => Ok(SessionEdit::Remove(name)),
        Some(v1::constraint_edit::Edit::Clear(v1::ClearConstraints {})) => Ok(SessionEdit::Clear),
        None => Err(WireError::new(
            format!("{field}.edit"),
            "is required; set add, replace, remove or clear",
        )),
    }
}

/// The optimiser's settings; unset fields take the engine's defaults.
pub fn design_params_from_proto(s: Option<v1::DesignSettings>) -> Result<DesignParams> {
    let mut params = DesignParams::default();
    let Some(v1::DesignSettings {
        spacing,
        particles,
        support,
        quadrature,
        weights,
        solver,
    }) = s
    else {
        return Ok(params);
    };
    params.spacing = spacing.unwrap_or(params.spacing);
    params.particles = particles.unwrap_or(params.particles);
    params.support = support.unwrap_or(params.support);
    params.quadrature = enum_or(quadrature, params.quadrature, "design.quadrature")?;
    if let Some(v1::DesignWeights {
        handle,
        rigidity,
        volume,
        velocity,
        acceleration,
        obstacle,
    }) = weights
    {
        let w = &mut params.weights;
        w.handle = handle.unwrap_or(w.handle);
        w.rigidity = rigidity.unwrap_or(w.rigidity);
        w.volume = volume.unwrap_or(w.volume);
        w.velocity = velocity.unwrap_or(w.velocity);
        w.acceleration = acceleration.unwrap_or(w.acceleration);
        w.obstacle = obstacle.unwrap_or(w.obstacle);
    }
    if let Some(v1::DesignSolverSettings {
        tolerance,
        max_iterations,
        linear_tolerance,
        max_linear_iterations,
    }) = solver
    {
        let s = &mut params.solver;
        s.tolerance = tolerance.unwrap_or(s.tolerance);
        s.max_iterations = max_iterations.unwrap_or(s.max_iterations);
        s.linear_tolerance = linear_tolerance.unwrap_or(s.linear_tolerance);
        s.max_linear_iterations = max_linear_iterations.unwrap_or(s.max_linear_iterations);
    }
    Ok(params)
}

/// Motion settings; unset fields take the engine's defaults.
pub fn motion_params_from_proto(s: Option<v1::MotionSettings>) -> MotionParams {
    let mut params = MotionParams::default();
    if let Some(v1::MotionSettings {
        adaptive,
        tolerance,
        samples,
        max_frames,
        radius,
    }) = s
    {
        params.adaptive = adaptive.unwrap_or(params.adaptive);
        params.tolerance = tolerance.unwrap_or(params.tolerance);
        params.samples = samples.unwrap_or(params.samples);
        params.max_frames = max_frames.unwrap_or(params.max_frames);
        params.radius = radius.unwrap_or(params.radius);
    }
    params
}

fn energies_to_proto(e: &Energies) -> v1::DesignEnergies {
    let Energies {
        handle,
        rigidity,
        volume,
        velocity,
        acceleration,
        obstacle,
    } = *e;
    v1::DesignEnergies {
        handle,
        rigidity,
        volume,
        velocity,
        acceleration,
        obstacle,
    }
}

/// The wire form of one report of the optimiser's progress.
pub fn progress_to_proto(p: &Progress) -> v1::DesignProgress {
    let Progress {
        iteration,
        energies,
        gradient_norm,
        linear_iterations,
        frames,
        inserted,
        sampling_error,
    } = p;
    v1::DesignProgress {
        iteration: *iteration,
        energies: Some(energies_to_proto(energies)),
        gradient_norm: *gradient_norm,
        frames: count(*frames),
        inserted: count(*inserted),
        sampling_error: *sampling_error,
        linear_iterations: *linear_iterations,
    }
}

/// The wire form of what a finished solve reports.
pub fn info_to_proto(i: &SolveInfo) -> v1::DesignInfo {
    let SolveInfo {
        iterations,
        energies,
        gradient_norm,
        linear_iterations,
        converged,
        frames,
        inserted,
        sampling_error,
    } = i;
    v1::DesignInfo {
        iterations: *iterations,
        energies: Some(energies_to_proto(energies)),
        gradient_norm: *gradient_norm,
        converged: *converged,
        frames: count(*frames),
        inserted: count(*inserted),
        sampling_error: *sampling_error,
        linear_iterations: *linear_iterations,
    }
}

/// The wire form of the optimiser's settings, every field set.
pub fn design_settings_to_proto(p: &DesignParams) -> v1::DesignSettings {
    let DesignParams {
        spacing,
        particles,
        support,
        quadrature,
        weights,
        solver,
    } = *p;
    v1::DesignSettings {
        spacing: Some(spacing),
        particles: Some(particles),
        support: Some(support),
        quadrature: quadrature.to_i32(),
        weights: Some(v1::DesignWeights {
            handle: Some(weights.handle),
            rigidity: Some(weights.rigidity),
            volume: Some(weights.volume),
            velocity: Some(weights.velocity),
            acceleration: Some(weights.acceleration),
            obstacle: Some(weights.obstacle),
        }),
        solver: Some(v1::DesignSolverSettings {
            tolerance: Some(solver.tolerance),
            max_iterations: Some(solver.max_iterations),
            linear_tolerance: Some(solver.linear_tolerance),
            max_linear_iterations: Some(solver.max_linear_iterations),
        }),
    }
}

/// The wire form of motion settings, every field set.
pub fn motion_settings_to_proto(p: &MotionParams) -> v1::MotionSettings {
    let MotionParams {
        adaptive,
        tolerance,
        samples,
        max_frames,
        radius,
    } = *p;
    v1::MotionSettings {
        adaptive: Some(adaptive),
        tolerance: Some(tolerance),
        samples: Some(samples),
        max_frames: Some(max_frames),
        radius: Some(radius),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use meshless_engine::design::Weights;
    use meshless_engine::scene::ShapeSpec;

    /// Every constraint kind and setting survives the trip to the wire
    /// and back unchanged, so `ListConstraints` returns what was sent.
    #[test]
    fn design_messages_round_trip() {
        let constraints = [
            Constraint {
                name: "handle".into(),
                kind: ConstraintKind::Handle(Handle {
                    points: Selection::Particles {
                        system: 1,
                        indices: vec![3, 4],
                    },
                    target: Target::Positions(vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]),
                    time: Some(0.5),
                }),
            },
            Constraint {
                name: "region".into(),
                kind: ConstraintKind::Handle(Handle {
                    points: Selection::Region {
                        min: [0.0; 3],
                        max: [1.0; 3],
                    },
                    target: Target::Transform {
                        translation: [0.0, 0.0, 1.0],
                        rotation: [0.1, 0.0, 0.0],
                        centre: [0.5; 3],
                    },
                    time: None,
                }),
            },
            Constraint {
                name: "velocity".into(),
                kind: ConstraintKind::Velocity(Velocity {
                    time: 1.0,
                    velocity: [0.0, 1.0, 0.0],
                    points: Some(Selection::Points(vec![[0.1, 0.2, 0.3]])),
                }),
            },
            Constraint {
                name: "obstacle".into(),
                kind: ConstraintKind::Obstacle(Obstacle {
                    shape: ShapeSpec::Sphere { radius: 0.2 },
                    orientation: [0.0, 0.3, 0.0],
                    path: vec![
                        Waypoint {
                            time: 0.0,
                            position: [0.0; 3],
                        },
                        Waypoint {
                            time: 1.0,
                            position: [1.0, 0.0, 0.0],
                        },
                    ],
                }),
            },
        ];
        let grab = Control {
            system: 2,
            kind: ControlKind::Grab(Grab {
                point: Vector::new(0.1, 0.0, 0.0),
                position: Some(Vector::new(0.1, 0.2, 0.0)),
                rotation: None,
            }),
        };
        let all = constraints
            .into_iter()
            .map(SessionConstraint::Design)
            .chain([SessionConstraint::Control("grab".into(), grab)]);
        for c in all {
            let back = constraint_from_proto(session_constraint_to_proto(&c), "c");
            assert_eq!(back.expect("converts"), c);
        }
        let params = DesignParams {
            spacing: 0.1,
            particles: 77,
            support: 2.5,
            quadrature: Quadrature::Cells,
            weights: Weights {
                volume: 300.0,
                ..Weights::default()
            },
            ..DesignParams::default()
        };
        let back = design_params_from_proto(Some(design_settings_to_proto(&params)));
        assert_eq!(back.expect("converts"), params);
        let motion = MotionParams {
            adaptive: false,
            max_frames: 9,
            ..MotionParams::default()
        };
        assert_eq!(
            motion_params_from_proto(Some(motion_settings_to_proto(&motion))),
            motion
        );
        assert_eq!(
            design_params_from_proto(None).expect("defaults"),
            DesignParams::default()
        );
    }
}
