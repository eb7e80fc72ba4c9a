//! Snapshots over real gRPC against the real `meshless-server` binary:
//! `Snapshot, Restore, N steps` computes what `N steps` from the original
//! does, bit for bit, for a fluid, a solid, a rigid-body scene and a
//! design session; blobs that are not this build's, truncated, corrupted
//! or over the limit are refused with the code that says so and change
//! nothing; a forged blob (its checksum recomputed) is checked as a
//! request is: piled or stray positions and run targets `Run` refuses are
//! refused, and its memory is reserved for the state it holds;
//! `SimulateSteps` reports progress and stops at a completed step when its
//! caller goes away or its deadline passes.

use meshless_client::{Client, ClientError, FrameView, v1};
use meshless_tests::{
    ServerProcess, fixture, fluid_of, forge, small_scene, small_solid_scene, within,
};
use std::time::Duration;
use tokio_stream::StreamExt;
use tonic::Code;

/// The frame of session `id`, its session id blanked so that frames of
/// two sessions compare.
async fn frame(client: &Client, id: &str) -> FrameView {
    let mut frame = within("latest frame", client.latest_frame(id))
        .await
        .expect("a frame");
    frame.session_id.clear();
    frame
}

/// A 2D tank with a floating box and a swinging paddle.
const BODIES: &str = r#"
name = "bodies"
dimension = 2
[domain]
min = [0.0, 0.0, 0.0]
max = [0.8, 0.6, 0.0]
[time]
dt = 0.004
[output]
fields = ["velocity", "density", "pressure"]
[[systems]]
kind = "fluid"
solver = "dfsph"
spacing = 0.025
[[systems.blocks]]
region = { min = [0.0, 0.0, 0.0], max = [0.8, 0.3, 0.0] }
[[systems]]
kind = "rigid_body"
shape = { type = "box", half_extents = [0.06, 0.06, 0.06] }
position = [0.5, 0.4, 0.0]
orientation = [0.0, 0.0, 0.3]
motion = "dynamic"
density = 500.0
[[systems]]
kind = "rigid_body"
shape = { type = "box", half_extents = [0.02, 0.2, 0.15] }
position = [0.1, 0.2, 0.0]
motion = "kinematic"
oscillation = { amplitude = [0.04, 0.0, 0.0], frequency = 1.0 }
"#;

/// Steps a session of `scene` `before` steps, snapshots it, restores the
/// snapshot into a new session, steps both `after` steps and checks that
/// their frames agree bit for bit; returns the client and both ids.
async fn continues(
    scene: &str,
    before: u64,
    after: u64,
) -> (ServerProcess, Client, String, String) {
    let server = ServerProcess::spawn(&[]).await.expect("server");
    let client = server.client().await.expect("client");
    let original = within("create", client.create_session_toml(scene))
        .await
        .expect("created")
        .id;
    within("step", client.step(&original, before))
        .await
        .expect("stepped");
    let snapshot = within("snapshot", client.snapshot(&original))
        .await
        .expect("a snapshot");
    assert_eq!(snapshot.step, before);
    let restored = within("restore", client.restore(snapshot.data, None, None))
        .await
        .expect("restored");
    assert_ne!(restored.id, original);
    let status = restored.status.expect("a status");
    assert_eq!(status.step, before);
    // The state is the original's; how the last step went is not state
    // (a restored session has not stepped yet).
    let (mine, theirs) = (
        frame(&client, &restored.id).await,
        frame(&client, &original).await,
    );
    assert_eq!((mine.fields, mine.bodies), (theirs.fields, theirs.bodies));
    for id in [&original, &restored.id] {
        within("step", client.step(id, after))
            .await
            .expect("stepped");
    }
    assert_eq!(
        frame(&client, &restored.id).await,
        frame(&client, &original).await,
        "{after} steps after the restore"
    );
    let id = restored.id;
    (server, client, original, id)
}

#[tokio::test]
async fn a_fluid_continues_bit_for_bit() {
    continues(&small_scene(), 6, 9).await;
}

#[tokio::test]
async fn a_solid_continues_bit_for_bit() {
    continues(&small_solid_scene(), 5, 8).await;
}

#[tokio::test]
async fn a_rigid_body_scene_continues_bit_for_bit() {
    continues(BODIES, 25, 10).await;
}

fn vec3([x, y, z]: [f64; 3]) -> v1::Vec3 {
    v1::Vec3 { x, y, z }
}

/// A handle moving a region of the small column by `translation`.
fn handle(name: &str, min: [f64; 3], max: [f64; 3], translation: [f64; 3]) -> v1::ConstraintEdit {
    v1::ConstraintEdit {
        edit: Some(v1::constraint_edit::Edit::Add(v1::Constraint {
            name: name.into(),
            kind: Some(v1::constraint::Kind::Handle(v1::HandleConstraint {
                points: Some(v1::Selection {
                    kind: Some(v1::selection::Kind::Region(v1::Aabb {
                        min: Some(vec3(min)),
                        max: Some(vec3(max)),
                    })),
                }),
                target: Some(v1::DesignTarget {
                    kind: Some(v1::design_target::Kind::Transform(v1::TransformTarget {
                        translation: Some(vec3(translation)),
                        rotation: None,
                        centre: None,
                    })),
                }),
                time: None,
            })),
        })),
    }
}

fn shape(id: &str) -> v1::OptimizeRequest {
    v1::OptimizeRequest {
        session_id: id.into(),
        system: 0,
        design: Some(v1::DesignSettings {
            particles: Some(40),
            ..Default::default()
        }),
        problem: Some(v1::optimize_request::Problem::Shape(v1::ShapeProblem {})),
        playback: false,
    }
}

/// A design session: constraints, the last design and the warm start of
/// the next shape solve all come back, so the next solve after a restore
/// is the original's, and stepping goes on bit for bit.
#[tokio::test]
async fn a_design_session_continues_bit_for_bit() {
    let server = ServerProcess::spawn(&[]).await.expect("server");
    let client = server.client().await.expect("client");
    let original = within("create", client.create_session_toml(&small_solid_scene()))
        .await
        .expect("created")
        .id;
    let stretch = vec![
        handle("bottom", [0.3, 0.3, 0.25], [0.7, 0.7, 0.36], [0.0; 3]),
        handle("top", [0.3, 0.3, 0.64], [0.7, 0.7, 0.75], [0.0, 0.0, 0.1]),
    ];
    within("edit", client.edit_constraints(&original, stretch))
        .await
        .expect("constraints");
    within("optimize", client.optimize_with(shape(&original), |_| {}))
        .await
        .expect("a design");
    within("step", client.step(&original, 3))
        .await
        .expect("stepped");
    let snapshot = within("snapshot", client.snapshot(&original))
        .await
        .expect("a snapshot");
    let restored = within("restore", client.restore(snapshot.data, None, None))
        .await
        .expect("restored")
        .id;
    let constraints = |id: String| {
        let client = client.clone();
        async move {
            within("list", client.list_constraints(&id))
                .await
                .expect("listed")
        }
    };
    assert_eq!(
        constraints(restored.clone()).await,
        constraints(original.clone()).await
    );
    let design = |id: String| {
        let client = client.clone();
        async move {
            within("design", client.get_design(&id))
                .await
                .expect("a design")
        }
    };
    let (mine, theirs) = (
        design(restored.clone()).await,
        design(original.clone()).await,
    );
    assert_eq!(
        mine.session_id, restored,
        "the restored design names its session"
    );
    assert_eq!(mine.displacements, theirs.displacements);
    // Drag the top further in both: each solve starts warm from the last.
    let drag = vec![v1::ConstraintEdit {
        edit: Some(v1::constraint_edit::Edit::Replace(
            match handle("top", [0.3, 0.3, 0.64], [0.7, 0.7, 0.75], [0.0, 0.05, 0.12]).edit {
                Some(v1::constraint_edit::Edit::Add(c)) => c,
                _ => unreachable!("an add"),
            },
        )),
    }];
    for id in [&original, &restored] {
        within("drag", client.edit_constraints(id, drag.clone()))
            .await
            .expect("dragged");
        within("optimize", client.optimize_with(shape(id), |_| {}))
            .await
            .expect("a design");
        within("step", client.step(id, 4)).await.expect("stepped");
    }
    let (mine, theirs) = (
        design(restored.clone()).await,
        design(original.clone()).await,
    );
    assert_eq!(
        mine.displacements, theirs.displacements,
        "the warm solve agrees"
    );
    assert_eq!(mine.info, theirs.info);
    assert_eq!(
        frame(&client, &restored).await,
        frame(&client, &original).await
    );
}

/// The code and message of a refused restore of `data` into `into`.
async fn refused(client: &Client, data: Vec<u8>, into: Option<&str>) -> (Code, String) {
    let err = within("restore", client.restore(data, into, None))
        .await
        .expect_err("refused");
    let ClientError::Rpc(status) = err else {
        panic!("not an RPC error: {err}")
    };
    (status.code(), status.message().to_owned())
}

/// A small tank's session, its snapshot after `at` steps, and its frame
/// after `then` more: a session that has moved on from a snapshot, for a
/// refused restore to leave as it is.
async fn moved_on(client: &Client, at: u64, then: u64) -> (String, Vec<u8>, FrameView) {
    let id = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("created")
        .id;
    within("step", client.step(&id, at)).await.expect("stepped");
    let good = within("snapshot", client.snapshot(&id))
        .await
        .expect("a snapshot")
        .data;
    within("step", client.step(&id, then))
        .await
        .expect("stepped");
    let before = frame(client, &id).await;
    (id, good, before)
}

#[tokio::test]
async fn bad_blobs_are_refused_and_change_nothing() {
    let server = ServerProcess::spawn(&["--max-snapshot-mb", "1"])
        .await
        .expect("server");
    let client = server.client().await.expect("client");
    let (id, good, before) = moved_on(&client, 4, 3).await;
    let sessions = || async {
        within("list", client.list_sessions())
            .await
            .expect("listed")
            .len()
    };
    let count = sessions().await;

    let truncated = good[..good.len() / 2].to_vec();
    let mut corrupted = good.clone();
    let middle = corrupted.len() - 40;
    corrupted[middle] ^= 0x01;
    let mut other_build = good.clone();
    // The build string starts after the magic, format and length: "meshless 0..."
    other_build[8 + 4 + 2 + "meshless ".len()] = b'7';
    let mut other_format = good.clone();
    other_format[8] = 9;
    let cases: [(&str, Vec<u8>, Code, &str); 6] = [
        ("truncated", truncated, Code::InvalidArgument, "truncated"),
        ("corrupted", corrupted, Code::InvalidArgument, "checksum"),
        (
            "another build",
            other_build,
            Code::InvalidArgument,
            "written by \"meshless 7",
        ),
        (
            "another format",
            other_format,
            Code::InvalidArgument,
            "format 9",
        ),
        (
            "not a snapshot",
            b"{\"scene\": 1}".to_vec(),
            Code::InvalidArgument,
            "not a meshless snapshot",
        ),
        (
            "over the limit",
            vec![0; (1 << 20) + 10],
            Code::ResourceExhausted,
            "over this server's limit",
        ),
    ];
    for (what, data, code, text) in cases {
        for into in [None, Some(id.as_str())] {
            let (got, message) = refused(&client, data.clone(), into).await;
            assert_eq!(got, code, "{what}: {message}");
            assert!(message.contains(text), "{what}: {message}");
            assert!(message.len() < 600, "{what}: the message is bounded");
        }
    }
    // A good blob of another scene is refused by an existing session.
    let solid = within("create", client.create_session_toml(&small_solid_scene()))
        .await
        .expect("created")
        .id;
    let (code, message) = refused(&client, good.clone(), Some(&solid)).await;
    assert_eq!(code, Code::InvalidArgument, "{message}");
    assert!(message.contains("new session"), "{message}");
    within("delete", client.delete_session(&solid))
        .await
        .expect("deleted");

    assert_eq!(sessions().await, count, "no session was made");
    assert_eq!(
        frame(&client, &id).await,
        before,
        "the session is unchanged"
    );
    // Another server of the same build takes it, to the same state.
    let other = ServerProcess::spawn(&[]).await.expect("another server");
    let elsewhere = other.client().await.expect("client");
    let moved = within(
        "restore elsewhere",
        elsewhere.restore(good.clone(), None, None),
    )
    .await
    .expect("restored on another server");
    within("step", elsewhere.step(&moved.id, 3))
        .await
        .expect("stepped");
    let there = frame(&elsewhere, &moved.id).await;
    assert_eq!((there.step, &there.fields), (before.step, &before.fields));

    // The good blob goes back into the session: back at step 4.
    let status = within("restore", client.restore(good, Some(&id), None))
        .await
        .expect("restored")
        .status
        .expect("a status");
    assert_eq!(status.step, 4);
    assert_eq!(
        status.state,
        v1::SessionState::Paused as i32,
        "{}",
        status.reason
    );
}

#[tokio::test]
async fn a_running_session_is_snapshot_and_not_restored_into() {
    let server = ServerProcess::spawn(&[]).await.expect("server");
    let client = server.client().await.expect("client");
    let id = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("created")
        .id;
    let data = within("snapshot", client.snapshot(&id))
        .await
        .expect("idle")
        .data;
    within("run", client.run_forever(&id, Some(0.5)))
        .await
        .expect("running");
    // A running session gives a snapshot and runs on...
    let running = within("snapshot", client.snapshot(&id))
        .await
        .expect("a snapshot of a running session");
    let restored = within("restore", client.restore(running.data, None, None))
        .await
        .expect("restored");
    let status = restored.status.expect("a status");
    assert_eq!(
        status.state,
        v1::SessionState::Paused as i32,
        "a restored run waits for Resume: {}",
        status.reason
    );
    within("resume", client.resume(&restored.id))
        .await
        .expect("the restored run resumes");
    // ...but refuses to be restored into.
    let (code, message) = refused(&client, data, Some(&id)).await;
    assert_eq!(code, Code::FailedPrecondition, "{message}");
    assert!(message.contains("pause it first"), "{message}");
}

#[tokio::test]
async fn simulate_steps_reports_progress_and_stops_at_a_completed_step() {
    let server = ServerProcess::spawn(&[]).await.expect("server");
    let client = server.client().await.expect("client");
    // Short steps: the deadlines below let it take a thousand or more,
    // which at the fixture's 10 ms would pass the seconds after which
    // this coarse WCSPH tank gains energy and faults.
    let scene = fixture("python_tank").replace("dt = 0.01", "dt = 0.002");
    assert!(scene.contains("dt = 0.002"));
    let id = within("create", client.create_session_toml(&scene))
        .await
        .expect("created")
        .id;
    let twin = within("create", client.create_session_toml(&scene))
        .await
        .expect("created")
        .id;
    // All of it, with progress.
    let mut stream = within("simulate", client.simulate_steps(&id, 40, 0.01))
        .await
        .expect("a stream");
    let mut last = None;
    let mut messages = 0;
    while let Some(progress) = within("progress", stream.next()).await {
        let progress = progress.expect("progress");
        messages += 1;
        assert_eq!(progress.steps_total, 40);
        if let Some(previous) = &last {
            let previous: &v1::SimulateProgress = previous;
            assert!(progress.steps_done >= previous.steps_done);
        }
        last = Some(progress);
    }
    let last = last.expect("progress came");
    assert!(last.done && last.steps_done == 40, "{last:?}");
    assert!(messages >= 2, "a first message and a last one at least");
    within("step", client.step(&twin, 40))
        .await
        .expect("stepped");
    assert_eq!(frame(&client, &id).await, frame(&client, &twin).await);

    // Dropped part-way: the session ends paused at a completed step,
    // bit for bit the twin's after as many steps.
    let mut stream = within("simulate", client.simulate_steps(&id, 1_000_000, 0.01))
        .await
        .expect("a stream");
    let first = within("progress", stream.next()).await.expect("a message");
    first.expect("progress");
    let second = within("progress", stream.next()).await.expect("a message");
    second.expect("progress");
    drop(stream);
    // Queued behind the abandoned chunk, which stops at its step in
    // progress: this step is taken from a completed one.
    let stopped = within("a step after", client.step(&id, 1))
        .await
        .expect("stepped")
        .status
        .expect("status");
    let taken = stopped.step - 40;
    assert!(taken < 1_000_000, "the call stopped early");
    within("step", client.step(&twin, taken))
        .await
        .expect("stepped");
    assert_eq!(frame(&client, &id).await, frame(&client, &twin).await);

    // A deadline: DEADLINE_EXCEEDED, and again a completed step.
    let mut stream = within("simulate", async {
        let mut request = tonic::Request::new(v1::SimulateStepsRequest {
            session_id: id.clone(),
            steps: 1_000_000,
            progress_interval: 0.05,
        });
        request.set_timeout(Duration::from_millis(700));
        let mut grpc = v1::simulation_client::SimulationClient::connect(server.grpc_url.clone())
            .await
            .expect("connects");
        grpc.simulate_steps(request)
            .await
            .map(tonic::Response::into_inner)
    })
    .await
    .expect("a stream");
    let mut code = None;
    while let Some(item) = within("progress", stream.next()).await {
        if let Err(status) = item {
            code = Some(status.code());
            break;
        }
    }
    assert_eq!(code, Some(Code::DeadlineExceeded));
    // As above: the next step starts from a completed one.
    let status = within("a step after", client.step(&id, 1))
        .await
        .expect("stepped")
        .status
        .expect("status");
    assert_eq!(
        status.state,
        v1::SessionState::Paused as i32,
        "{}",
        status.reason
    );
    within("step", client.step(&twin, status.step - stopped.step))
        .await
        .expect("stepped");
    assert_eq!(frame(&client, &id).await, frame(&client, &twin).await);

    // A unary Step past its deadline ends, and the session stays at a
    // completed step. The server answers DEADLINE_EXCEEDED; tonic's client
    // also runs its own timer on the same `grpc-timeout`, and on a loaded
    // machine that timer can fire first (CANCELLED, "Timeout expired").
    // Either way the call ended at its deadline: a server that ignored it
    // would still be stepping, and the step after would time out below.
    let mut grpc = v1::simulation_client::SimulationClient::connect(server.grpc_url.clone())
        .await
        .expect("connects");
    let mut request = tonic::Request::new(v1::StepRequest {
        session_id: id.clone(),
        steps: 1_000_000,
    });
    request.set_timeout(Duration::from_millis(400));
    let err = within("a step past its deadline", grpc.step(request))
        .await
        .expect_err("past the deadline");
    let client_timer = err.code() == Code::Cancelled && err.message().contains("Timeout expired");
    assert!(
        err.code() == Code::DeadlineExceeded || client_timer,
        "{:?}: {}",
        err.code(),
        err.message()
    );
    let after = within("a step after", client.step(&id, 1))
        .await
        .expect("stepped")
        .status
        .expect("status");
    within("step", client.step(&twin, after.step - status.step))
        .await
        .expect("stepped");
    assert_eq!(frame(&client, &id).await, frame(&client, &twin).await);

    // Bad numbers are refused up front.
    for (steps, interval) in [(0, 0.0), (5, 0.001), (5, -1.0)] {
        let err = within("simulate", client.simulate_steps(&id, steps, interval))
            .await
            .err()
            .expect("refused");
        assert_eq!(err.code(), Some(Code::InvalidArgument), "{err}");
    }
}

/// A forged snapshot is input like a request: the checksum only catches
/// corruption. Positions piled on one point (whose neighbour lists grow
/// with the square of the pile; the restore once never finished) or
/// outside the domain are refused as `CreateSession` refuses them, and so
/// are run targets `Run` refuses; neither a new session nor the existing
/// one changes.
#[tokio::test]
async fn forged_positions_and_run_targets_are_refused_as_requests_are() {
    let server = ServerProcess::spawn(&[]).await.expect("server");
    let client = server.client().await.expect("client");
    let (id, good, before) = moved_on(&client, 2, 1).await;

    let piled = forge(&good, |payload| {
        let fluid = fluid_of(payload);
        let first = [fluid.positions[0], fluid.positions[1], fluid.positions[2]];
        for (k, x) in fluid.positions.iter_mut().enumerate() {
            *x = first[k % 3];
        }
    });
    let stray = forge(&good, |payload| fluid_of(payload).positions[3 * 7] = 5.0);
    let run = |until: Option<f64>, factor: Option<f64>| {
        forge(&good, |payload| {
            payload.session.as_mut().expect("a record").run = Some(v1::RunRecord {
                until_time: until,
                realtime_factor: factor,
            });
        })
    };
    let cases = [
        ("piled on one point", piled, "within one spacing"),
        ("outside the domain", stray, "positions[7]"),
        ("factor -1", run(None, Some(-1.0)), "realtime_factor"),
        ("factor NaN", run(None, Some(f64::NAN)), "realtime_factor"),
        ("factor 1e-300", run(None, Some(1e-300)), "realtime_factor"),
        ("end time NaN", run(Some(f64::NAN), None), "until_time"),
        ("end time -1", run(Some(-1.0), Some(1.0)), "until_time"),
    ];
    for (what, data, mentions) in cases {
        for into in [None, Some(id.as_str())] {
            let (code, message) = refused(&client, data.clone(), into).await;
            assert_eq!(
                code,
                Code::InvalidArgument,
                "{what} into {into:?}: {message}"
            );
            assert!(
                message.contains(mentions),
                "{what} into {into:?}: no mention of {mentions:?}: {message}"
            );
        }
    }
    assert_eq!(
        within("list", client.list_sessions())
            .await
            .expect("listed")
            .len(),
        1,
        "no session was made"
    );
    assert_eq!(
        frame(&client, &id).await,
        before,
        "the session is unchanged"
    );
    // The same run target as Run accepts it restores.
    let paced = run(Some(1.0), Some(0.5));
    within("restore", client.restore(paced, None, None))
        .await
        .expect("a run target Run accepts is restored");
}

/// A restore reserves memory for the state it restores: a forged fluid
/// squeezed to 8 particles a cell (as many as a scene may place) has about
/// eight times the neighbour pairs of its scene's lattice, and is refused
/// where the scene itself fits.
#[tokio::test]
async fn a_restore_reserves_for_its_positions_not_its_scene() {
    // 16^3 = 4096 particles: about 4.1 MB by the scene's estimate, about
    // 16 MB squeezed to half their spacing on every axis.
    const CUBE: &str = r#"
name = "cube"
[domain]
min = [0.0, 0.0, 0.0]
max = [1.0, 1.0, 1.0]
[time]
dt = 0.005
[[systems]]
kind = "fluid"
spacing = 0.05
stiffness = 2.0e4
[[systems.blocks]]
region = { min = [0.0, 0.0, 0.0], max = [0.8, 0.8, 0.8] }
"#;
    let server = ServerProcess::spawn(&["--memory-budget-mb", "12"])
        .await
        .expect("server");
    let client = server.client().await.expect("client");
    let id = within("create", client.create_session_toml(CUBE))
        .await
        .expect("the scene fits")
        .id;
    let good = within("snapshot", client.snapshot(&id))
        .await
        .expect("a snapshot")
        .data;
    // Its own state fits beside it, and goes again.
    let twin = within("restore", client.restore(good.clone(), None, None))
        .await
        .expect("the scene's own state fits")
        .id;
    within("delete", client.delete_session(&twin))
        .await
        .expect("deleted");
    let squeezed = forge(&good, |payload| {
        for x in &mut fluid_of(payload).positions {
            *x *= 0.5;
        }
    });
    let (code, message) = refused(&client, squeezed.clone(), None).await;
    assert_eq!(code, Code::ResourceExhausted, "{message}");
    // Into the session itself: its reservation must grow to the squeezed
    // state's, which does not fit beside nothing else either; the session
    // is left as it was, and its own state still restores into it.
    within("step", client.step(&id, 2)).await.expect("stepped");
    let (code, message) = refused(&client, squeezed, Some(&id)).await;
    assert_eq!(code, Code::ResourceExhausted, "{message}");
    let kept = within("get", client.get_session(&id))
        .await
        .expect("the session")
        .status
        .expect("a status");
    assert_eq!(kept.step, 2, "the refused restore changed nothing");
    within("restore", client.restore(good, Some(&id), None))
        .await
        .expect("its own state fits where it is");
}
