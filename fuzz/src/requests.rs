//! The requests a client sends whose validation does not need a running
//! session: `CreateSession` (either scene source), `EditConstraints`
//! (each edit against a scene's context, all or nothing) and `Optimize`'s
//! settings. `Step` and `Run` carry only numbers, checked in the server's
//! handler (`server/src/service.rs`).

use crate::echo::assert_quotes_briefly;
use crate::scene::admitted;
use meshless_engine::Scene;
use meshless_engine::design::constraints::Context;
use meshless_engine::design::motion::check_motion;
use meshless_engine::design::{ConstraintSet, Edit, check_params};
use meshless_engine::scene::MeshFiles;
use meshless_proto::v1;
use meshless_wire::design::{
    SessionConstraint, SessionEdit, constraint_from_proto, constraint_to_proto,
    design_params_from_proto, edit_from_proto, motion_params_from_proto,
    session_constraint_to_proto,
};
use meshless_wire::scene::scene_from_proto;
use prost::Message;

/// Largest obstacle mesh an edit may carry here (a server's limit,
/// scaled down as in the scene targets).
const MAX_MESH_BYTES: u64 = 64 << 10;

/// The first byte picks the request (its low two bits) and, for
/// `EditConstraints`, the scene's dimension (bit 2); the rest is the
/// encoded request. Each goes through the checks its handler runs before
/// it touches a session, with these properties:
///
/// - `CreateSession`: as the scene targets ([`crate::scene_toml`],
///   [`crate::scene_spec`]).
/// - `EditConstraints`: the optimiser's half of a batch (runtime
///   controls are checked by a session's world, which this target has
///   not): a refused batch leaves the constraint set as it was; an
///   accepted one leaves only constraints that pass validation on their
///   own and survive the trip to the protocol and back. Every control
///   survives that trip too.
/// - `Optimize`: the settings convert, and the engine's checks of them
///   either pass or name the setting.
///
/// Every error quotes briefly.
pub fn requests(data: &[u8]) {
    let Some((&selector, message)) = data.split_first() else {
        return;
    };
    match selector & 3 {
        0 => create_session(message),
        1 => edit_constraints(message, if selector & 4 == 0 { 3 } else { 2 }),
        _ => optimize(message),
    }
}

fn create_session(bytes: &[u8]) {
    let Ok(v1::CreateSessionRequest {
        source,
        observers: _,
    }) = v1::CreateSessionRequest::decode(bytes)
    else {
        return;
    };
    let scene = match source {
        Some(v1::create_session_request::Source::Scene(spec)) => {
            scene_from_proto(spec).map_err(|e| e.to_string())
        }
        Some(v1::create_session_request::Source::SceneToml(text)) => {
            Scene::from_toml_str(&text).map_err(|e| e.to_string())
        }
        None => return,
    };
    match scene {
        Ok(scene) => admitted(bytes, scene),
        Err(e) => assert_quotes_briefly(bytes, &e),
    }
}

/// The scene the edits act on: a fluid, then two solids of 8 and 125
/// particles, as `design::context` would describe it.
fn context(dim: usize) -> Context {
    Context {
        dim,
        solids: vec![None, Some(8), Some(125)],
    }
}

fn edit_constraints(bytes: &[u8], dim: usize) {
    let Ok(v1::EditConstraintsRequest {
        session_id: _,
        edits,
    }) = v1::EditConstraintsRequest::decode(bytes)
    else {
        return;
    };
    let edits = edits
        .into_iter()
        .enumerate()
        .map(|(k, e)| edit_from_proto(e, &format!("edits[{k}]")))
        .collect::<Result<Vec<_>, _>>();
    let edits = match edits {
        Ok(edits) => edits,
        Err(e) => return assert_quotes_briefly(bytes, &e.to_string()),
    };
    let mut design_edits = Vec::with_capacity(edits.len());
    for edit in edits {
        let (constraint, replace) = match edit {
            SessionEdit::Add(c) => (c, false),
            SessionEdit::Replace(c) => (c, true),
            SessionEdit::Remove(name) => {
                design_edits.push(Edit::Remove(name));
                continue;
            }
            SessionEdit::Clear => {
                design_edits.push(Edit::Clear);
                continue;
            }
        };
        let wire = session_constraint_to_proto(&constraint);
        let back = constraint_from_proto(wire.clone(), "constraint")
            .unwrap_or_else(|e| panic!("a converted constraint does not convert back: {e}"));
        // As bytes: a NaN a control carries is unequal to itself.
        assert_eq!(
            session_constraint_to_proto(&back).encode_to_vec(),
            wire.encode_to_vec(),
            "constraint round trip"
        );
        if let SessionConstraint::Design(mut constraint) = constraint {
            if let Err(e) = constraint.load_mesh(&MeshFiles::None, MAX_MESH_BYTES) {
                return assert_quotes_briefly(bytes, &e.to_string());
            }
            design_edits.push(if replace {
                Edit::Replace(constraint)
            } else {
                Edit::Add(constraint)
            });
        }
    }
    let edits = design_edits;
    let context = context(dim);
    let mut set = ConstraintSet::new();
    if let Err(e) = set.apply(&edits, &context) {
        assert!(set.is_empty(), "a refused batch changed the set");
        return assert_quotes_briefly(bytes, &e.to_string());
    }
    for constraint in set.iter() {
        if let Err(e) = constraint.validate(&context) {
            panic!("an accepted constraint fails validation: {e}");
        }
        let wire = constraint_to_proto(constraint);
        let back = constraint_from_proto(wire.clone(), "constraint")
            .unwrap_or_else(|e| panic!("an accepted constraint does not convert back: {e}"));
        assert_eq!(
            session_constraint_to_proto(&back),
            wire,
            "constraint round trip"
        );
    }
}

fn optimize(bytes: &[u8]) {
    let Ok(v1::OptimizeRequest {
        session_id: _,
        system: _,
        design,
        problem,
        playback: _,
    }) = v1::OptimizeRequest::decode(bytes)
    else {
        return;
    };
    let params = match design_params_from_proto(design) {
        Ok(params) => params,
        Err(e) => return assert_quotes_briefly(bytes, &e.to_string()),
    };
    if let Err(e) = check_params(&params) {
        return assert_quotes_briefly(bytes, &e.to_string());
    }
    if let Some(v1::optimize_request::Problem::Motion(v1::MotionProblem { settings, .. })) = problem
        && let Err(e) = check_motion(&motion_params_from_proto(settings))
    {
        assert_quotes_briefly(bytes, &e.to_string());
    }
}
