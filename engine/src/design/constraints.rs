//! The user's constraints on a shape or a motion (tutorial Section 8):
//! handles that pin or drag material points (Eq. 74; per keyframe time in
//! a motion), velocities at keyframe times (Eq. 82) and obstacles, static
//! or moving (Eq. 84).
//!
//! A [`ConstraintSet`] holds them by unique name. Edits arrive in batches
//! and are applied atomically: the whole batch is checked against a copy
//! and the set changes only if every edit is valid, so a rejected request
//! leaves it as it was. Every error names the constraint at fault.

use crate::geometry::Shape;
use crate::math::{Real, Vector, vector};
use crate::scene::{MeshFiles, ShapeSpec};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A named constraint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Constraint {
    /// Unique within a set; edits address constraints by it.
    pub name: String,
    /// What it constrains; its fields sit beside `name` when serialised.
    #[serde(flatten)]
    pub kind: ConstraintKind,
}

/// The kinds of constraint, told apart by a `type` field when serialised.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ConstraintKind {
    /// Material points pinned or dragged to targets (Eq. 74).
    Handle(Handle),
    /// A velocity at a time of a motion (Eq. 82).
    Velocity(Velocity),
    /// A solid to stay out of (Eq. 84).
    Obstacle(Obstacle),
}

/// Material points that should move to targets (Eq. 74). A handle with no
/// `time` constrains a shape problem; with a `time` it is (part of) a
/// keyframe of a motion problem.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Handle {
    /// The material points it moves.
    pub points: Selection,
    /// Where they should go.
    pub target: Target,
    /// Keyframe time, s; none for a shape problem.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<Real>,
}

/// Which material points (undeformed shape, world frame) a constraint
/// acts on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Selection {
    /// Particles of a solid system of the scene, by index: their rest
    /// positions are the material points.
    Particles {
        /// Index of the solid system in the scene.
        system: usize,
        /// Indices of its particles.
        indices: Vec<u32>,
    },
    /// Material points given directly.
    Points(Vec<[Real; 3]>),
    /// Every design particle whose rest position lies in the box.
    Region {
        /// The box's lower corner, m.
        min: [Real; 3],
        /// The box's upper corner, m.
        max: [Real; 3],
    },
}

/// Where the selected points should go.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Target {
    /// One position per selected point (particles or points only: a
    /// region's size depends on the design spacing).
    Positions(Vec<[Real; 3]>),
    /// A rigid motion of the points' rest positions: the rotation vector
    /// `rotation` (axis times angle, rad) about `centre`, then `translation`.
    Transform {
        /// Applied after the rotation, m.
        #[serde(default)]
        translation: [Real; 3],
        /// Rotation vector, rad.
        #[serde(default)]
        rotation: [Real; 3],
        /// The point the rotation turns about, m.
        #[serde(default)]
        centre: [Real; 3],
    },
}

/// A velocity the deformation field should have at a keyframe time
/// (Eq. 82), at the selected points or, with no selection, at every design
/// particle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Velocity {
    /// When it applies, s: within the keyframes' span.
    pub time: Real,
    /// m/s.
    pub velocity: [Real; 3],
    /// The points it applies to; none for every design particle.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points: Option<Selection>,
}

/// A solid the shape must stay out of (Eq. 84), standing still or moving
/// along straight segments between waypoints (held at the first before
/// it and at the last after it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Obstacle {
    /// The solid's shape in its own frame, centred on each waypoint's
    /// position.
    pub shape: ShapeSpec,
    /// Rotation vector of the shape, rad.
    #[serde(default)]
    pub orientation: [Real; 3],
    /// At least one; times strictly increasing.
    pub path: Vec<Waypoint>,
}

/// One point of an obstacle's path.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Waypoint {
    /// When the obstacle is there, s; 0 if not given.
    #[serde(default)]
    pub time: Real,
    /// Where the shape's centre is, m.
    pub position: [Real; 3],
}

/// One change to a set.
#[derive(Debug, Clone, PartialEq)]
pub enum Edit {
    /// Fails if the name is taken.
    Add(Constraint),
    /// Fails unless the name exists.
    Replace(Constraint),
    /// Fails unless the name exists.
    Remove(String),
    /// Removes every constraint.
    Clear,
}

/// What constraints are checked against: the scene they will act on.
#[derive(Debug, Clone, PartialEq)]
pub struct Context {
    /// 2 or 3.
    pub dim: usize,
    /// Per scene system, its particle count if it is an elastic solid.
    pub solids: Vec<Option<usize>>,
}

/// A constraint is invalid; nothing was changed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("constraint `{name}`: {message}")]
pub struct ConstraintError {
    /// The name of the constraint at fault.
    pub name: String,
    /// What is wrong and what to change.
    pub message: String,
}

/// Named constraints, listed in name order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ConstraintSet {
    items: BTreeMap<String, Constraint>,
}

impl ConstraintSet {
    /// An empty set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Applies `edits` in order, all or nothing.
    ///
    /// # Errors
    /// [`ConstraintError`] naming the first invalid constraint or edit;
    /// the set is then unchanged.
    pub fn apply(&mut self, edits: &[Edit], context: &Context) -> Result<(), ConstraintError> {
        let mut next = self.items.clone();
        for edit in edits {
            match edit {
                Edit::Add(c) => {
                    c.validate(context)?;
                    if next.contains_key(&c.name) {
                        return Err(c.error(
                            "a constraint of this name exists; replace it or pick another name",
                        ));
                    }
                    next.insert(c.name.clone(), c.clone());
                }
                Edit::Replace(c) => {
                    c.validate(context)?;
                    if !next.contains_key(&c.name) {
                        return Err(c.error("no constraint of this name to replace; add it"));
                    }
                    next.insert(c.name.clone(), c.clone());
                }
                Edit::Remove(name) => {
                    if next.remove(name).is_none() {
                        return Err(ConstraintError {
                            name: name.clone(),
                            message: "no constraint of this name to remove".into(),
                        });
                    }
                }
                Edit::Clear => next.clear(),
            }
        }
        self.items = next;
        Ok(())
    }

    /// The constraints in name order.
    pub fn iter(&self) -> impl Iterator<Item = &Constraint> {
        self.items.values()
    }

    /// The constraint called `name`, if any.
    pub fn get(&self, name: &str) -> Option<&Constraint> {
        self.items.get(name)
    }

    /// The number of constraints.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// Whether the set holds no constraint.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }
}

impl Constraint {
    fn error(&self, message: impl Into<String>) -> ConstraintError {
        ConstraintError {
            name: self.name.clone(),
            message: message.into(),
        }
    }

    /// Loads the mesh file an obstacle's shape names into the shape,
    /// under the host's policy (see [`ShapeSpec::load_mesh`]); other
    /// constraints are left as they are.
    ///
    /// # Errors
    /// [`ConstraintError`] naming the shape's `path` or `data`.
    pub fn load_mesh(&mut self, files: &MeshFiles, max_bytes: u64) -> Result<(), ConstraintError> {
        match &mut self.kind {
            ConstraintKind::Obstacle(obstacle) => obstacle
                .shape
                .load_mesh(files, max_bytes, "shape")
                .map_err(|e| ConstraintError {
                    name: self.name.clone(),
                    message: e.to_string(),
                }),
            ConstraintKind::Handle(_) | ConstraintKind::Velocity(_) => Ok(()),
        }
    }

    /// Checks the constraint on its own and against the scene.
    ///
    /// # Errors
    /// [`ConstraintError`] saying what to change.
    pub fn validate(&self, context: &Context) -> Result<(), ConstraintError> {
        if self.name.trim().is_empty() {
            return Err(self.error("the name is empty; give every constraint a name"));
        }
        let err = |message: String| self.error(message);
        match &self.kind {
            ConstraintKind::Handle(h) => {
                check_time(h.time, "time").map_err(err)?;
                let count = h.points.validate(context).map_err(err)?;
                match &h.target {
                    Target::Positions(p) => {
                        let Some(count) = count else {
                            return Err(err(
                                "a region selects a number of points that depends on the \
                                 design spacing; give a transform target, or select particles \
                                 or points"
                                    .into(),
                            ));
                        };
                        if p.len() != count {
                            return Err(err(format!(
                                "{} target positions for {count} selected points; give one per \
                                 point",
                                p.len()
                            )));
                        }
                        check_points(p, "target positions").map_err(err)?;
                    }
                    Target::Transform {
                        translation,
                        rotation,
                        centre,
                    } => {
                        for (what, v) in [
                            ("translation", translation),
                            ("rotation", rotation),
                            ("centre", centre),
                        ] {
                            check_points(std::slice::from_ref(v), what).map_err(err)?;
                        }
                    }
                }
            }
            ConstraintKind::Velocity(v) => {
                check_time(Some(v.time), "time").map_err(err)?;
                check_points(std::slice::from_ref(&v.velocity), "velocity").map_err(err)?;
                if let Some(points) = &v.points {
                    points.validate(context).map_err(err)?;
                }
            }
            ConstraintKind::Obstacle(o) => {
                check_points(std::slice::from_ref(&o.orientation), "orientation").map_err(err)?;
                if o.path.is_empty() {
                    return Err(err("the path is empty; give at least one waypoint".into()));
                }
                for (k, w) in o.path.iter().enumerate() {
                    check_time(Some(w.time), &format!("path[{k}].time")).map_err(err)?;
                    check_points(std::slice::from_ref(&w.position), &format!("path[{k}]"))
                        .map_err(err)?;
                    if k > 0 && w.time <= o.path[k - 1].time {
                        return Err(err(format!(
                            "path[{k}].time = {} does not follow path[{}].time = {}; waypoint \
                             times must increase",
                            w.time,
                            k - 1,
                            o.path[k - 1].time
                        )));
                    }
                }
                resolve_shape(&o.shape, context.dim).map_err(err)?;
            }
        }
        Ok(())
    }
}

impl Selection {
    /// The number of points it selects, `None` for a region (known only
    /// once the design particles are placed).
    fn validate(&self, context: &Context) -> Result<Option<usize>, String> {
        match self {
            Self::Particles { system, indices } => {
                let Some(count) = context.solids.get(*system).copied().flatten() else {
                    return Err(format!(
                        "system {system} is not an elastic solid of this scene; select particles \
                         of a solid system"
                    ));
                };
                if indices.is_empty() {
                    return Err("selects no particle; list at least one".into());
                }
                if let Some(bad) = indices.iter().find(|&&i| i as usize >= count) {
                    return Err(format!(
                        "particle {bad} does not exist: system {system} has {count} particles"
                    ));
                }
                Ok(Some(indices.len()))
            }
            Self::Points(points) => {
                if points.is_empty() {
                    return Err("selects no point; list at least one".into());
                }
                check_points(points, "points")?;
                Ok(Some(points.len()))
            }
            Self::Region { min, max } => {
                check_points(&[*min, *max], "region")?;
                if let Some(a) = (0..context.dim).find(|&a| min[a] > max[a]) {
                    return Err(format!(
                        "region min[{a}] = {} exceeds max[{a}] = {}; swap them",
                        min[a], max[a]
                    ));
                }
                Ok(None)
            }
        }
    }
}

fn check_time(time: Option<Real>, what: &str) -> Result<(), String> {
    match time {
        Some(t) if !t.is_finite() => Err(format!("{what} is {t}; give a finite time")),
        _ => Ok(()),
    }
}

fn check_points(points: &[[Real; 3]], what: &str) -> Result<(), String> {
    match points.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
        Some(k) => Err(format!(
            "{what}[{k}] = {:?} is not finite; give finite numbers",
            points[k]
        )),
        None => Ok(()),
    }
}

/// The engine shape of an obstacle: bounded and not degenerate.
pub(crate) fn resolve_shape(spec: &ShapeSpec, dim: usize) -> Result<Shape, String> {
    let shape = crate::scene::checked_shape("shape", spec, dim).map_err(|e| e.to_string())?;
    match shape.volume(dim) {
        Some(v) if v > 0.0 && v.is_finite() => Ok(shape),
        Some(_) => Err("the shape has no volume; give it positive extents".into()),
        // A plane: unbounded, but a valid wall.
        None if matches!(shape, Shape::Plane { .. }) => Ok(shape),
        None => Err("the shape has no finite volume".into()),
    }
}

impl Target {
    /// The target of each of `rest` (the selected points at rest); public
    /// so that experiments can measure how closely a solve met it.
    pub fn resolve(&self, rest: &[Vector]) -> Vec<Vector> {
        match self {
            Self::Positions(p) => p.iter().map(|&p| vector(p)).collect(),
            Self::Transform {
                translation,
                rotation,
                centre,
            } => {
                let r = nalgebra::Rotation3::from_scaled_axis(vector(*rotation));
                let (t, c) = (vector(*translation), vector(*centre));
                rest.iter().map(|x| c + r * (x - c) + t).collect()
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn context() -> Context {
        Context {
            dim: 3,
            solids: vec![None, Some(10)],
        }
    }

    fn handle(name: &str, points: Selection, target: Target) -> Constraint {
        Constraint {
            name: name.into(),
            kind: ConstraintKind::Handle(Handle {
                points,
                target,
                time: None,
            }),
        }
    }

    fn pin(name: &str) -> Constraint {
        handle(
            name,
            Selection::Particles {
                system: 1,
                indices: vec![0, 9],
            },
            Target::Positions(vec![[0.0; 3], [1.0; 3]]),
        )
    }

    fn ball(name: &str, radius: Real, path: Vec<Waypoint>) -> Constraint {
        Constraint {
            name: name.into(),
            kind: ConstraintKind::Obstacle(Obstacle {
                shape: ShapeSpec::Sphere { radius },
                orientation: [0.0; 3],
                path,
            }),
        }
    }

    fn at(time: Real) -> Waypoint {
        Waypoint {
            time,
            position: [0.0; 3],
        }
    }

    /// Each bad constraint is refused with its name and a reason, and the
    /// batch it came in changes nothing.
    #[test]
    fn bad_constraints_are_refused_by_name_and_change_nothing() {
        let mut set = ConstraintSet::new();
        set.apply(&[Edit::Add(pin("a"))], &context())
            .expect("valid");
        let before = set.clone();
        let bad: Vec<(Constraint, &str)> = vec![
            (pin("a"), "exists"),
            (
                handle(
                    "b",
                    Selection::Particles {
                        system: 1,
                        indices: vec![10],
                    },
                    Target::Positions(vec![[0.0; 3]]),
                ),
                "particle 10 does not exist",
            ),
            (
                handle(
                    "c",
                    Selection::Particles {
                        system: 0,
                        indices: vec![0],
                    },
                    Target::Positions(vec![[0.0; 3]]),
                ),
                "not an elastic solid",
            ),
            (
                handle(
                    "d",
                    Selection::Points(vec![[0.0; 3]]),
                    Target::Positions(vec![[Real::NAN, 0.0, 0.0]]),
                ),
                "not finite",
            ),
            (
                handle(
                    "e",
                    Selection::Region {
                        min: [1.0; 3],
                        max: [0.0; 3],
                    },
                    Target::Transform {
                        translation: [0.0; 3],
                        rotation: [0.0; 3],
                        centre: [0.0; 3],
                    },
                ),
                "exceeds",
            ),
            (
                handle(
                    "f",
                    Selection::Region {
                        min: [0.0; 3],
                        max: [1.0; 3],
                    },
                    Target::Positions(vec![[0.0; 3]]),
                ),
                "region",
            ),
            (ball("g", 0.0, vec![at(0.0)]), "radius"),
            (ball("h", 1.0, vec![]), "path is empty"),
            (ball("i", 1.0, vec![at(1.0), at(1.0)]), "must increase"),
            (pin(" "), "name is empty"),
        ];
        for (c, reason) in bad {
            let name = c.name.clone();
            let err = set
                .apply(&[Edit::Add(pin("new")), Edit::Add(c)], &context())
                .expect_err(reason);
            assert_eq!(err.name, name);
            assert!(err.message.contains(reason), "{name}: {err}");
            assert_eq!(set, before, "{name}: the set changed");
        }
        assert!(set.apply(&[Edit::Remove("zz".into())], &context()).is_err());
        assert!(set.apply(&[Edit::Replace(pin("zz"))], &context()).is_err());
        set.apply(&[Edit::Replace(pin("a")), Edit::Add(pin("b"))], &context())
            .expect("valid");
        assert_eq!(
            set.iter().map(|c| c.name.as_str()).collect::<Vec<_>>(),
            ["a", "b"]
        );
        set.apply(&[Edit::Clear], &context()).expect("valid");
        assert!(set.is_empty());
    }

    #[test]
    fn transforms_turn_about_their_centre_then_move() {
        let target = Target::Transform {
            translation: [1.0, 0.0, 0.0],
            rotation: [0.0, 0.0, std::f64::consts::FRAC_PI_2],
            centre: [1.0, 0.0, 0.0],
        };
        let moved = target.resolve(&[Vector::new(2.0, 0.0, 0.0)]);
        assert!(
            (moved[0] - Vector::new(2.0, 1.0, 0.0)).norm() < 1e-12,
            "{moved:?}"
        );
    }
}
