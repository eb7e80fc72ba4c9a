//! A session's named constraints: the optimiser's (a [`ConstraintSet`])
//! and the world's runtime controls (grabs, a [`Controls`]), kept apart
//! but sharing one namespace, so that `EditConstraints` edits both in one
//! batch, all or nothing, and `ListConstraints` lists both in name order.

use meshless_engine::design::{ConstraintError, ConstraintSet, Context, Edit};
use meshless_engine::world::Controls;
use meshless_proto::v1;
use meshless_wire::design::{
    SessionConstraint, SessionEdit, constraint_to_proto, control_to_proto,
};
use std::collections::BTreeMap;

/// Which store holds a name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Home {
    Design,
    Control,
}

/// The constraints and controls `edits` leave, applied in order to copies
/// of `design` and `controls`. The optimiser's constraints are checked
/// against `context` here; the controls are checked by the world they
/// are set on.
///
/// # Errors
/// [`ConstraintError`] naming the first constraint or edit at fault;
/// nothing is changed.
pub fn plan(
    design: &ConstraintSet,
    controls: &Controls,
    edits: &[SessionEdit],
    context: &Context,
) -> Result<(ConstraintSet, Controls), ConstraintError> {
    let mut names: BTreeMap<String, Home> = design
        .iter()
        .map(|c| (c.name.clone(), Home::Design))
        .chain(controls.iter().map(|(n, _)| (n.to_owned(), Home::Control)))
        .collect();
    let mut design_edits = Vec::with_capacity(edits.len());
    let mut next_controls = controls.clone();
    for edit in edits {
        match edit {
            SessionEdit::Add(c) => {
                if names.contains_key(c.name()) {
                    return Err(error(
                        c.name(),
                        "a constraint of this name exists; replace it or pick another name",
                    ));
                }
                put(c, None, &mut design_edits, &mut next_controls)?;
                names.insert(c.name().to_owned(), home(c));
            }
            SessionEdit::Replace(c) => {
                let Some(&was) = names.get(c.name()) else {
                    return Err(error(
                        c.name(),
                        "no constraint of this name to replace; add it",
                    ));
                };
                put(c, Some(was), &mut design_edits, &mut next_controls)?;
                names.insert(c.name().to_owned(), home(c));
            }
            SessionEdit::Remove(name) => match names.remove(name) {
                None => return Err(error(name, "no constraint of this name to remove")),
                Some(Home::Design) => design_edits.push(Edit::Remove(name.clone())),
                Some(Home::Control) => {
                    next_controls.remove(name);
                }
            },
            SessionEdit::Clear => {
                names.clear();
                design_edits.push(Edit::Clear);
                next_controls = Controls::new();
            }
        }
    }
    let mut next_design = design.clone();
    next_design.apply(&design_edits, context)?;
    Ok((next_design, next_controls))
}

/// Where `c` lives.
fn home(c: &SessionConstraint) -> Home {
    match c {
        SessionConstraint::Design(_) => Home::Design,
        SessionConstraint::Control(..) => Home::Control,
    }
}

/// Puts `c` in its store, taking its name out of the store it `was` in
/// when that is the other one (a replacement may change the kind).
fn put(
    c: &SessionConstraint,
    was: Option<Home>,
    design_edits: &mut Vec<Edit>,
    controls: &mut Controls,
) -> Result<(), ConstraintError> {
    match c {
        SessionConstraint::Design(constraint) => {
            if was == Some(Home::Control) {
                controls.remove(&constraint.name);
            }
            design_edits.push(if was == Some(Home::Design) {
                Edit::Replace(constraint.clone())
            } else {
                Edit::Add(constraint.clone())
            });
        }
        SessionConstraint::Control(name, control) => {
            if name.trim().is_empty() {
                return Err(error(
                    name,
                    "the name is empty; give every constraint a name",
                ));
            }
            if was == Some(Home::Design) {
                design_edits.push(Edit::Remove(name.clone()));
            }
            controls.insert(name.clone(), *control);
        }
    }
    Ok(())
}

fn error(name: &str, message: &str) -> ConstraintError {
    ConstraintError {
        name: name.to_owned(),
        message: message.to_owned(),
    }
}

/// Both stores' entries as `Constraint` messages, in name order.
pub fn list(design: &ConstraintSet, controls: &Controls) -> Vec<v1::Constraint> {
    let mut all: Vec<v1::Constraint> = design
        .iter()
        .map(constraint_to_proto)
        .chain(controls.iter().map(|(n, c)| control_to_proto(n, c)))
        .collect();
    all.sort_by(|a, b| a.name.cmp(&b.name));
    all
}

#[cfg(test)]
mod tests {
    use super::*;
    use meshless_engine::design::{Constraint, ConstraintKind, Velocity};
    use meshless_engine::efg::Grab;
    use meshless_engine::math::Vector;
    use meshless_engine::world::{Control, ControlKind};

    fn context() -> Context {
        Context {
            dim: 3,
            solids: vec![Some(4), None],
        }
    }

    fn velocity(name: &str) -> SessionConstraint {
        SessionConstraint::Design(Constraint {
            name: name.into(),
            kind: ConstraintKind::Velocity(Velocity {
                time: 1.0,
                velocity: [0.0, 1.0, 0.0],
                points: None,
            }),
        })
    }

    fn grab(name: &str) -> SessionConstraint {
        SessionConstraint::Control(
            name.into(),
            Control {
                system: 1,
                kind: ControlKind::Grab(Grab {
                    point: Vector::zeros(),
                    position: Some(Vector::x()),
                    rotation: None,
                }),
            },
        )
    }

    fn names(design: &ConstraintSet, controls: &Controls) -> (Vec<String>, Vec<String>) {
        (
            design.iter().map(|c| c.name.clone()).collect(),
            controls.iter().map(|(n, _)| n.to_owned()).collect(),
        )
    }

    /// Grabs go to the controls, the rest to the optimiser's set, and a
    /// replacement that changes the kind moves the name across.
    #[test]
    fn a_batch_sorts_its_constraints_into_the_two_stores() {
        let edits = [
            SessionEdit::Add(velocity("v")),
            SessionEdit::Add(grab("g")),
            SessionEdit::Add(grab("h")),
            SessionEdit::Replace(velocity("h")),
            SessionEdit::Replace(grab("v")),
            SessionEdit::Remove("g".into()),
        ];
        let (design, controls) =
            plan(&ConstraintSet::new(), &Controls::new(), &edits, &context()).expect("valid");
        assert_eq!(
            names(&design, &controls),
            (vec!["h".to_owned()], vec!["v".to_owned()])
        );
        let listed: Vec<String> = list(&design, &controls)
            .into_iter()
            .map(|c| c.name)
            .collect();
        assert_eq!(listed, ["h", "v"]);
        let (design, controls) =
            plan(&design, &controls, &[SessionEdit::Clear], &context()).expect("a clear is valid");
        assert!(design.is_empty() && controls.is_empty());
    }

    /// One namespace: a grab may not take a design constraint's name, and
    /// a refused batch leaves both stores as they were.
    #[test]
    fn names_are_shared_and_a_refused_batch_changes_nothing() {
        let (design, controls) = plan(
            &ConstraintSet::new(),
            &Controls::new(),
            &[SessionEdit::Add(velocity("v")), SessionEdit::Add(grab("g"))],
            &context(),
        )
        .expect("valid");
        for (edits, name) in [
            (vec![SessionEdit::Add(grab("v"))], "v"),
            (vec![SessionEdit::Add(velocity("g"))], "g"),
            (vec![SessionEdit::Replace(grab("x"))], "x"),
            (vec![SessionEdit::Remove("x".into())], "x"),
            (vec![SessionEdit::Add(grab(" "))], " "),
            (
                vec![
                    SessionEdit::Remove("g".into()),
                    SessionEdit::Remove("g".into()),
                ],
                "g",
            ),
        ] {
            let refused = plan(&design, &controls, &edits, &context()).expect_err("refused");
            assert_eq!(refused.name, name, "{refused}");
        }
        assert_eq!(
            names(&design, &controls),
            (vec!["v".to_owned()], vec!["g".to_owned()])
        );
    }
}
