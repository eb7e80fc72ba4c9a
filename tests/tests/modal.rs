//! Modal EFG solids over real gRPC (TCP) and real zenoh, against the real
//! `meshless-server` binary: a session of one builds, its frames carry
//! the nodes and the deformed skin with normals, grab constraints move a
//! point to its target while the session runs, a grab off the solid
//! refuses its whole batch and leaves everything as it was, a reset and
//! a snapshot keep the grabs (the world holds them as runtime controls,
//! apart from the optimiser's constraints, under the same names), and a
//! solid whose precompute would not fit the
//! server's memory budget is refused by its estimate before it is built.

use meshless_client::{Client, FrameView, ZenohLink, v1};
use meshless_tests::{ServerProcess, rpc_status, small_modal_scene, within};
use tonic::Code;

fn vec3([x, y, z]: [f64; 3]) -> v1::Vec3 {
    v1::Vec3 { x, y, z }
}

fn grab(name: &str, point: [f64; 3], position: [f64; 3]) -> v1::ConstraintEdit {
    v1::ConstraintEdit {
        edit: Some(v1::constraint_edit::Edit::Add(v1::Constraint {
            name: name.into(),
            kind: Some(v1::constraint::Kind::Grab(v1::GrabConstraint {
                system: 0,
                point: Some(vec3(point)),
                position: Some(vec3(position)),
                rotation: None,
            })),
        })),
    }
}

/// The skin vertex nearest `rest` in the first frame, by index.
fn nearest(frame: &FrameView, rest: [f64; 3]) -> usize {
    let skin = &frame.solid_surfaces[0].mesh;
    let distance = |v: &[f32; 3]| {
        (0..3)
            .map(|k| (f64::from(v[k]) - rest[k]).powi(2))
            .sum::<f64>()
    };
    (0..skin.vertices.len())
        .min_by(|&a, &b| distance(&skin.vertices[a]).total_cmp(&distance(&skin.vertices[b])))
        .expect("a skin")
}

fn position(frame: &FrameView, vertex: usize) -> [f64; 3] {
    frame.solid_surfaces[0].mesh.vertices[vertex].map(f64::from)
}

async fn step(client: &Client, id: &str, steps: u64) {
    within("step", client.step(id, steps))
        .await
        .expect("the modal solid steps");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_grabbed_modal_beam_follows_its_grab_and_a_bad_batch_changes_nothing() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let session = within("create", client.create_session_toml(&small_modal_scene()))
        .await
        .expect("a valid modal scene");
    let id = session.id.clone();
    assert!(
        session.particle_count > 50,
        "nodes: {}",
        session.particle_count
    );

    let info = within("info", client.server_info()).await.expect("info");
    let link = within("zenoh", ZenohLink::connect(&info.zenoh_locators))
        .await
        .expect("zenoh link");
    let frames = within("frames", link.frames(&id)).await.expect("frames");
    let rest = within("latest", client.latest_frame(&id))
        .await
        .expect("the built world's frame");
    assert_eq!(rest.solids.len(), 1);
    assert_eq!(rest.solids[0].count as usize, rest.particle_count);
    let skin = &rest.solid_surfaces[0].mesh;
    assert_eq!(skin.triangles.len(), 12 * 16, "the box's faces split twice");
    assert_eq!(skin.normals.len(), skin.vertices.len());
    let tip = nearest(&rest, [0.16, 0.0, 0.0]);
    let start = position(&rest, tip);

    let target = [0.15, 0.05, 0.0];
    let listed = within(
        "grab",
        client.edit_constraints(&id, vec![grab("tip", start, target)]),
    )
    .await
    .expect("a grab on the solid");
    assert_eq!(listed.len(), 1);
    step(&client, &id, 60).await;
    let streamed = within("a zenoh frame", frames.recv())
        .await
        .expect("a frame over zenoh");
    assert_eq!(
        streamed.solid_surfaces.len(),
        1,
        "zenoh frames carry the skin"
    );
    let held = within("latest", client.latest_frame(&id))
        .await
        .expect("frame");
    let at = position(&held, tip);
    let error = (0..3)
        .map(|k| (at[k] - target[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(
        error < 1e-3,
        "the grabbed vertex reaches its target: {at:?} vs {target:?}"
    );
    let n = held.solid_surfaces[0].mesh.normals[tip];
    let length = n.iter().map(|c| f64::from(*c).powi(2)).sum::<f64>().sqrt();
    assert!((length - 1.0).abs() < 1e-5, "a unit normal: {n:?}");

    // A batch with a good grab and one off the solid: refused whole.
    let batch = vec![
        grab("good", [0.08, 0.0, 0.0], [0.08, 0.01, 0.0]),
        grab("far", [2.0, 0.0, 0.0], [2.0, 0.0, 0.0]),
    ];
    let status = rpc_status(
        within("bad batch", client.edit_constraints(&id, batch))
            .await
            .expect_err("a grab off the solid"),
    );
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    assert!(
        status.message().contains("not on the solid"),
        "the message says what is wrong: {}",
        status.message()
    );
    let after = within("list", client.list_constraints(&id))
        .await
        .expect("list");
    assert_eq!(after, listed, "nothing changed");
    step(&client, &id, 5).await;
    let still = within("latest", client.latest_frame(&id))
        .await
        .expect("frame");
    let at = position(&still, tip);
    let error = (0..3)
        .map(|k| (at[k] - target[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(error < 1e-3, "the first grab still holds: {at:?}");

    // A grab on a system that is no modal solid names the constraint.
    let mut wrong = grab("nowhere", start, target);
    if let Some(v1::constraint_edit::Edit::Add(v1::Constraint {
        kind: Some(v1::constraint::Kind::Grab(g)),
        ..
    })) = &mut wrong.edit
    {
        g.system = 7;
    }
    let status = rpc_status(
        within("wrong system", client.edit_constraints(&id, vec![wrong]))
            .await
            .expect_err("no such modal solid"),
    );
    assert_eq!(status.code(), Code::InvalidArgument);
    assert!(status.message().contains("nowhere"), "{}", status.message());

    // A reset rebuilds the world and holds the grabs again.
    within("reset", client.reset(&id)).await.expect("reset");
    step(&client, &id, 60).await;
    let again = within("latest", client.latest_frame(&id))
        .await
        .expect("frame");
    let at = position(&again, tip);
    let error = (0..3)
        .map(|k| (at[k] - target[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(error < 1e-3, "held again after the reset: {at:?}");

    // A snapshot carries the grab: restored into a new session, it is
    // listed under its name and holds from the first step.
    let snapshot = within("snapshot", client.snapshot(&id))
        .await
        .expect("a snapshot");
    let restored = within("restore", client.restore(snapshot.data, None, None))
        .await
        .expect("the snapshot restores");
    let listed_there = within("list", client.list_constraints(&restored.id))
        .await
        .expect("list");
    assert_eq!(listed_there, listed, "the grab comes back by name");
    within("reset", client.reset(&restored.id))
        .await
        .expect("reset");
    step(&client, &restored.id, 60).await;
    let there = within("latest", client.latest_frame(&restored.id))
        .await
        .expect("frame");
    let at = position(&there, tip);
    let error = (0..3)
        .map(|k| (at[k] - target[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(error < 1e-3, "held in the restored session: {at:?}");

    // One namespace: a design constraint may not take the grab's name, a
    // replacement may change the kind, and then the grab lets go.
    let velocity = v1::Constraint {
        name: "tip".into(),
        kind: Some(v1::constraint::Kind::Velocity(v1::VelocityConstraint {
            time: 1.0,
            velocity: Some(vec3([0.0, 0.1, 0.0])),
            points: None,
        })),
    };
    let taken = v1::ConstraintEdit {
        edit: Some(v1::constraint_edit::Edit::Add(velocity.clone())),
    };
    let status = rpc_status(
        within("a taken name", client.edit_constraints(&id, vec![taken]))
            .await
            .expect_err("the name is the grab's"),
    );
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    assert!(status.message().contains("`tip`"), "{}", status.message());
    let replace = v1::ConstraintEdit {
        edit: Some(v1::constraint_edit::Edit::Replace(velocity.clone())),
    };
    let now = within("replace", client.edit_constraints(&id, vec![replace]))
        .await
        .expect("a replacement of another kind");
    assert_eq!(now, vec![velocity], "the name now holds the velocity");
    within("reset", client.reset(&id)).await.expect("reset");
    step(&client, &id, 60).await;
    let free = within("latest", client.latest_frame(&id))
        .await
        .expect("frame");
    let at = position(&free, tip);
    let error = (0..3)
        .map(|k| (at[k] - target[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(error > 1e-2, "released, the tip leaves the target: {at:?}");
}

/// A modal solid of some 16,000 nodes (a 50 x 25 x 25 cm block on
/// 1.25 cm octants) needs gigabytes for its shape functions and
/// matrices. Under a 64 MB budget the server refuses it from the
/// estimate it makes once the octree stands, before the precompute
/// allocates anything, with RESOURCE_EXHAUSTED and a message giving the
/// estimate, the budget and what to change; before, it was measured
/// after a build of minutes and gigabytes, and refused then. The
/// refusal keeps nothing: no session, the budget whole for a small one.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_modal_solid_over_the_memory_budget_is_refused_before_it_is_built() {
    let server = ServerProcess::spawn(&["--memory-budget-mb", "64"])
        .await
        .expect("server starts");
    let client = server.client().await.expect("client");
    let large = r#"
        name = "a block too large for the budget"
        [domain]
        min = [-0.3, -0.2, -0.2]
        max = [0.3, 0.2, 0.2]
        [time]
        dt = 0.02
        [[systems]]
        kind = "modal_solid"
        shape = { type = "box", half_extents = [0.25, 0.125, 0.125] }
        position = [0.0, 0.0, 0.0]
        young = 1.0e5
        cell = 0.0125
        modes = 12
    "#;
    let status = rpc_status(
        within("the refusal", client.create_session_toml(large))
            .await
            .expect_err("over the budget"),
    );
    assert_eq!(status.code(), Code::ResourceExhausted, "{status:?}");
    let message = status.message();
    for part in [
        "systems[0]",
        "by its estimate",
        "of its 64 MB memory budget",
        "--memory-budget-mb",
        "`cell`",
    ] {
        assert!(message.contains(part), "{part:?} in: {message}");
    }
    let sessions = within("list", client.list_sessions()).await.expect("list");
    assert!(sessions.is_empty(), "nothing kept: {sessions:?}");
    within(
        "a small one",
        client.create_session_toml(&small_modal_scene()),
    )
    .await
    .expect("the budget is whole again for a small modal solid");
}
