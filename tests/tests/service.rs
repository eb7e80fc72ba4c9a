//! End to end over real gRPC (TCP) and real zenoh, against the real
//! `meshless-server` binary: the lifecycle of a session, its frame and
//! status streams, and graceful shutdown.

use meshless_client::{ClientError, FrameView, ZenohLink, v1};
use meshless_tests::{ServerProcess, small_scene, within};
use tokio_stream::StreamExt;

fn state(status: &v1::SessionStatus) -> v1::SessionState {
    v1::SessionState::try_from(status.state).expect("a known state")
}

fn session_state(session: &v1::Session) -> v1::SessionState {
    state(session.status.as_ref().expect("a status"))
}

/// Receives frames until one with `step`, checking that every frame in
/// between arrives in order and has the session's particle count.
async fn frames_until(
    frames: &meshless_client::Frames,
    first: u64,
    last: u64,
    particles: usize,
) -> FrameView {
    let mut expected = first;
    loop {
        let frame = within(&format!("frame of step {expected}"), frames.recv())
            .await
            .expect("a well-formed frame");
        // The session puts its first frame (step 0) when it starts; on a
        // busy machine that put can reach a subscription declared just
        // after CreateSession answered. Earlier frames come first (one
        // publisher keeps its order), so they are skipped here.
        if frame.step < first {
            continue;
        }
        assert_eq!(frame.step, expected, "frames arrive in order, none lost");
        assert_eq!(frame.particle_count, particles);
        let positions = frame.field(v1::FieldKind::Position).expect("positions");
        assert_eq!(positions.values.len(), 3 * particles);
        assert!(positions.values.iter().all(|v| v.is_finite()));
        let density = frame
            .field(v1::FieldKind::Density)
            .expect("requested density");
        assert_eq!(density.values.len(), particles);
        if frame.step == last {
            return frame;
        }
        expected += 1;
    }
}

/// A session's whole life: create, step (frames over zenoh match the steps
/// and particle count), run to a time (status RUNNING then FINISHED over
/// gRPC and zenoh), latest frame for late joiners, reset, delete (CLOSED),
/// then SIGTERM stops the server cleanly.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_session_lives_steps_streams_and_closes() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let info = within("server info", client.server_info())
        .await
        .expect("info");
    assert_eq!(info.zenoh_locators, server.zenoh);

    let session = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("valid scene");
    let id = session.id.clone();
    let particles = session.particle_count as usize;
    assert_eq!(particles, 125);
    assert_eq!(session_state(&session), v1::SessionState::Idle);
    assert_eq!(
        session.zenoh_key_prefix,
        format!("meshless/v1/sessions/{id}")
    );

    let link = within("zenoh connect", ZenohLink::connect(&info.zenoh_locators))
        .await
        .expect("zenoh link");
    let frames = within("frame subscription", link.frames(&id))
        .await
        .expect("frames");
    let statuses = within("status subscription", link.statuses(&id))
        .await
        .expect("statuses");
    let mut watch = within("watch", client.watch_status(&id))
        .await
        .expect("watch");
    let first = within("first status", watch.next())
        .await
        .expect("an item")
        .expect("ok");
    assert_eq!(state(&first), v1::SessionState::Idle);

    // Step: five frames, steps 1..=5, then the state becomes PAUSED.
    let stepped = within("step", client.step(&id, 5)).await.expect("step");
    assert_eq!(stepped.status.as_ref().expect("status").step, 5);
    assert_eq!(session_state(&stepped), v1::SessionState::Paused);
    frames_until(&frames, 1, 5, particles).await;
    let paused = within("zenoh status", statuses.recv())
        .await
        .expect("status");
    assert_eq!((state(&paused), paused.step), (v1::SessionState::Paused, 5));
    let watched = within("watched status", watch.next())
        .await
        .expect("an item")
        .expect("ok");
    assert_eq!(state(&watched), v1::SessionState::Paused);

    // Run to 0.1 s (step 10): RUNNING, then FINISHED, on both channels.
    within("run", client.run_until(&id, 0.1, None))
        .await
        .expect("run");
    for expected in [v1::SessionState::Running, v1::SessionState::Finished] {
        let s = within("watched transition", watch.next())
            .await
            .expect("item")
            .expect("ok");
        assert_eq!(state(&s), expected, "gRPC watch: {s:?}");
        let z = within("zenoh transition", statuses.recv())
            .await
            .expect("status");
        assert_eq!(state(&z), expected, "zenoh status: {z:?}");
    }
    let last = frames_until(&frames, 6, 10, particles).await;
    assert!((last.time - 0.1).abs() < 1e-9);

    // Late joiners get the latest frame over zenoh and gRPC.
    let latest = within("latest over zenoh", link.latest_frame(&id))
        .await
        .expect("query")
        .expect("a reply");
    assert_eq!(latest, last);
    let over_grpc = within("latest over gRPC", client.latest_frame(&id))
        .await
        .expect("frame");
    assert_eq!(over_grpc, last);

    // Reset: back to step 0, IDLE, and a fresh frame 0 is published.
    let reset = within("reset", client.reset(&id)).await.expect("reset");
    assert_eq!(session_state(&reset), v1::SessionState::Idle);
    assert_eq!(reset.status.as_ref().expect("status").step, 0);
    let zero = within("frame after reset", frames.recv())
        .await
        .expect("frame");
    assert_eq!(zero.step, 0);
    let idle = within("watched reset", watch.next())
        .await
        .expect("item")
        .expect("ok");
    assert_eq!(state(&idle), v1::SessionState::Idle);

    // Delete: watchers see CLOSED and their stream ends; the id is gone.
    within("delete", client.delete_session(&id))
        .await
        .expect("delete");
    let closed = within("closing status", watch.next())
        .await
        .expect("item")
        .expect("ok");
    assert_eq!(state(&closed), v1::SessionState::Closed);
    assert!(within("end of watch", watch.next()).await.is_none());
    let gone = within("get deleted", client.get_session(&id))
        .await
        .expect_err("deleted");
    assert_eq!(gone.code(), Some(tonic::Code::NotFound));

    link.close().await;
    let exit = server.terminate().await.expect("terminates");
    assert!(
        exit.success(),
        "the server exits cleanly on SIGTERM: {exit:?}"
    );
}

/// Sessions are listed oldest first and each keeps its own clock.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sessions_are_independent_and_listed() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let a = within("create a", client.create_session_toml(&small_scene()))
        .await
        .expect("a");
    let b = within("create b", client.create_session_toml(&small_scene()))
        .await
        .expect("b");
    within("step a", client.step(&a.id, 3)).await.expect("step");
    let listed = within("list", client.list_sessions()).await.expect("list");
    let ids: Vec<_> = listed.iter().map(|s| s.id.as_str()).collect();
    assert_eq!(ids, vec![a.id.as_str(), b.id.as_str()]);
    let steps: Vec<_> = listed
        .iter()
        .map(|s| s.status.as_ref().expect("status").step)
        .collect();
    assert_eq!(steps, vec![3, 0]);
    // The list leaves scenes out (they may be large); GetSession has them.
    assert!(listed.iter().all(|s| s.scene.is_none()));
    let got = within("get a", client.get_session(&a.id))
        .await
        .expect("get");
    assert!(got.scene.is_some());
}

/// Errors from the client carry the server's code.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unreachable_server_is_a_connect_error() {
    let err = within(
        "connect to a closed port",
        meshless_client::Client::connect("http://127.0.0.1:1"),
    )
    .await
    .expect_err("nothing listens on port 1");
    assert!(matches!(err, ClientError::Connect { .. }), "{err}");
}

/// Every solver knob travels over the protocol: a DFSPH scene sent as a
/// `SceneSpec` message runs, and its frames report the solver's
/// iterations and the density error it reached, within tolerance.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn solver_knobs_travel_over_grpc_and_frames_report_them() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let echo = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("ok");
    let mut spec = echo.scene.expect("scene echo");
    let Some(v1::system_spec::Kind::Fluid(fluid)) = spec.systems[0].kind.as_mut() else {
        panic!("a fluid");
    };
    fluid.solver = Some(v1::SolverKind::Dfsph as i32);
    fluid.density_tolerance = Some(0.002);
    fluid.stiffness = 0.0;
    let session = within("create DFSPH", client.create_session(spec))
        .await
        .expect("valid");
    let scene = session.scene.as_ref().expect("scene");
    let Some(v1::system_spec::Kind::Fluid(echoed)) = scene.systems[0].kind.as_ref() else {
        panic!("a fluid");
    };
    assert_eq!(echoed.solver, Some(v1::SolverKind::Dfsph as i32));
    assert_eq!(echoed.density_tolerance, Some(0.002));
    within("step", client.step(&session.id, 10))
        .await
        .expect("steps");
    let frame = within("latest", client.latest_frame(&session.id))
        .await
        .expect("frame");
    assert_eq!(frame.step, 10);
    assert!(frame.solver_iterations > 0, "{frame:?}");
    assert!(frame.density_error <= 0.002, "{}", frame.density_error);
}

/// A scene that asks for a surface gets it in every frame, over zenoh and
/// gRPC alike, bit for bit the mesh the engine makes in-process (vertices
/// as f32): closed, and enclosing the volume of the fluid block it wraps.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_carry_the_surface_the_scene_asks_for() {
    let toml = small_scene().replace("[output]", "[output]\nsurface = { iso = 0.5 }");
    let mut world = meshless_engine::Scene::from_toml_str(&toml)
        .and_then(|s| s.build(&meshless_engine::BuildOptions::default()))
        .expect("a valid scene");
    world.step().expect("a step");
    let expected = world.frame().surface.expect("the engine meshes it");

    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let info = within("server info", client.server_info())
        .await
        .expect("info");
    let session = within("create", client.create_session_toml(&toml))
        .await
        .expect("valid scene");
    let output = session.scene.as_ref().and_then(|s| s.output.as_ref());
    let surface_spec = output.and_then(|o| o.surface).expect("surface echoed");
    assert_eq!(surface_spec.iso, Some(0.5));
    assert_eq!(surface_spec.cell, Some(0.02), "half the spacing by default");

    let link = within("zenoh connect", ZenohLink::connect(&info.zenoh_locators))
        .await
        .expect("zenoh link");
    let frames = within("frame subscription", link.frames(&session.id))
        .await
        .expect("frames");
    within("step", client.step(&session.id, 1))
        .await
        .expect("step");
    let frame = frames_until(&frames, 1, 1, session.particle_count as usize).await;
    let surface = frame.surface.clone().expect("a surface over zenoh");
    let over_grpc = within("latest over gRPC", client.latest_frame(&session.id))
        .await
        .expect("frame");
    assert_eq!(over_grpc, frame);

    assert_eq!(surface.triangles, expected.triangles);
    assert_eq!(surface.vertices.len(), expected.vertices.len());
    for (got, want) in surface.vertices.iter().zip(&expected.vertices) {
        assert_eq!(*got, [want.x as f32, want.y as f32, want.z as f32]);
    }
    // The 0.2 m cube of fluid sits in a corner, so the mesh closes just
    // outside the walls; its volume is the cube's to the rounding of its
    // nine free edges at five particles across (measured -2.4 %).
    let volume = expected.signed_volume();
    assert!(
        (volume / 0.008 - 1.0).abs() < 0.05,
        "surface volume {volume} m^3 against the block's 0.008"
    );
    link.close().await;
}

/// The small tank plus an elastic cube in the air away from the water,
/// embedding a surface of 12 * 4^2 triangles.
fn tank_and_solid() -> String {
    small_scene()
        + r#"
[[systems]]
kind = "solid"
shape = { type = "box", half_extents = [0.08, 0.08, 0.08] }
position = [0.35, 0.35, 0.35]
spacing = 0.04
young = 1.0e5
surface = { subdivisions = 2 }
"#
}

/// Mean height of a solid surface's vertices, after checking its normals
/// are unit length and one per vertex.
fn surface_height(surface: &meshless_client::SolidSurfaceView) -> f64 {
    let mesh = &surface.mesh;
    assert_eq!(mesh.normals.len(), mesh.vertices.len());
    for n in &mesh.normals {
        let norm = n.iter().map(|c| c * c).sum::<f32>().sqrt();
        assert!((norm - 1.0).abs() < 1e-4, "normal {n:?}");
    }
    mesh.vertices.iter().map(|v| f64::from(v[1])).sum::<f64>() / mesh.vertices.len() as f64
}

/// The solid's rows of a frame: its range, checked against the frame.
fn solid_heights(frame: &FrameView, fluid: usize) -> Vec<f32> {
    assert_eq!(frame.solids.len(), 1, "one solid");
    let range = frame.solids[0];
    assert_eq!(range.system, 1, "the solid is the second system");
    assert_eq!(range.first, fluid as u64, "the solid follows the fluid");
    assert_eq!(
        range.first + range.count,
        frame.particle_count as u64,
        "the ranges cover every particle after the fluid's"
    );
    let positions = frame.field(v1::FieldKind::Position).expect("positions");
    positions.values[3 * range.first as usize..]
        .chunks_exact(3)
        .map(|p| p[1])
        .collect()
}

/// An elastic solid created over gRPC streams over zenoh like the fluid:
/// frames list its particles after the fluid's, `solids` says where, its
/// requested fields come along, and gravity moves it, its embedded surface
/// with it (at rest, bit for bit the engine's in-process mesh; over zenoh
/// and gRPC alike); the scene echo carries its parameters with the
/// defaults made explicit.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn solids_stream_frames_whose_ranges_cover_their_particles() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let info = within("server info", client.server_info())
        .await
        .expect("info");
    let session = within("create", client.create_session_toml(&tank_and_solid()))
        .await
        .expect("valid scene");
    let scene = session.scene.as_ref().expect("scene echo");
    let Some(v1::system_spec::Kind::Solid(solid)) = scene.systems[1].kind.as_ref() else {
        panic!("the second system is the solid: {scene:?}");
    };
    assert_eq!(solid.young, 1.0e5);
    assert_eq!(solid.poisson, Some(0.3), "the default, made explicit");
    assert_eq!(solid.order, Some(v1::MlsOrder::Linear as i32));
    assert_eq!(
        solid.surface,
        Some(v1::SolidSurfaceSpec {
            method: Some(v1::EmbeddingMethod::ShapeFunctions as i32),
            subdivisions: Some(2),
        }),
        "the default method, made explicit"
    );
    let particles = session.particle_count as usize;
    let fluid = 125;
    assert_eq!(particles, fluid + 4 * 4 * 4, "4 spacings across the cube");

    let link = within("zenoh connect", ZenohLink::connect(&info.zenoh_locators))
        .await
        .expect("zenoh link");
    let frames = within("frame subscription", link.frames(&session.id))
        .await
        .expect("frames");
    let start = within("latest over zenoh", link.latest_frame(&session.id))
        .await
        .expect("query")
        .expect("frame 0");
    let before = solid_heights(&start, fluid);
    assert_eq!(before.len(), particles - fluid);
    let rest = meshless_engine::Scene::from_toml_str(&tank_and_solid())
        .and_then(|s| s.build(&meshless_engine::BuildOptions::default()))
        .expect("a valid scene")
        .solid_surfaces();
    let [expected] = &rest[..] else {
        panic!("the engine embeds one surface")
    };
    let [surface_before] = &start.solid_surfaces[..] else {
        panic!("one solid surface over zenoh: {:?}", start.solid_surfaces)
    };
    assert_eq!(surface_before.system, 1);
    assert_eq!(surface_before.mesh.triangles, expected.mesh.triangles);
    assert_eq!(surface_before.mesh.triangles.len(), 12 * 16);
    let f32s = |v: &[meshless_engine::math::Vector]| -> Vec<[f32; 3]> {
        v.iter()
            .map(|v| [v.x as f32, v.y as f32, v.z as f32])
            .collect()
    };
    assert_eq!(surface_before.mesh.vertices, f32s(&expected.mesh.vertices));
    assert_eq!(surface_before.mesh.normals, f32s(&expected.normals));

    within("step", client.step(&session.id, 5))
        .await
        .expect("steps");
    let last = frames_until(&frames, 1, 5, particles).await;
    let after = solid_heights(&last, fluid);
    assert!(after.iter().all(|y| y.is_finite()));
    // Free fall for 0.05 s: every particle drops, the centre by g t^2 / 2
    // to within the sub-steps' symplectic Euler excess (under g t dt / 2).
    let mean = |ys: &[f32]| ys.iter().map(|&y| f64::from(y)).sum::<f64>() / ys.len() as f64;
    let drop = mean(&before) - mean(&after);
    let free_fall = 0.5 * 9.81 * 0.05f64.powi(2);
    assert!(
        drop > free_fall * 0.99 && drop < free_fall * 1.25,
        "the solid's centre fell {drop} m, free fall {free_fall} m"
    );
    assert!(before.iter().zip(&after).all(|(b, a)| a < b));
    let [surface_after] = &last.solid_surfaces[..] else {
        panic!("one solid surface in every frame")
    };
    assert_eq!(surface_after.mesh.triangles, surface_before.mesh.triangles);
    let surface_drop = surface_height(surface_before) - surface_height(surface_after);
    assert!(
        (surface_drop / drop - 1.0).abs() < 0.05,
        "the surface fell {surface_drop} m, the particles {drop} m"
    );

    let over_grpc = within("latest over gRPC", client.latest_frame(&session.id))
        .await
        .expect("frame");
    assert_eq!(over_grpc, last);
    link.close().await;
}

/// The position of the particle `id` of `system` (`None`: the fluid) in a
/// frame, found by its id.
fn position_of(frame: &FrameView, system: Option<u32>, id: u32) -> Option<[f32; 3]> {
    let row = frame.row_of(system, id)?;
    let p = &frame
        .field(v1::FieldKind::Position)
        .expect("positions")
        .values;
    Some([p[3 * row], p[3 * row + 1], p[3 * row + 2]])
}

/// Particles leave and join a served fluid mid-run, and a client follows
/// them by id over zenoh: survivors keep their ids (the fluid's and the
/// solid's), new particles get the next ids where they were put, and a
/// refused change (a solid's particles, an unknown id, a position outside
/// the domain) answers INVALID_ARGUMENT and queues nothing.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn particles_leave_and_join_and_clients_follow_them_by_id() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let info = within("server info", client.server_info())
        .await
        .expect("info");
    let scene = tank_and_solid().replace(
        r#"fields = ["velocity", "density"]"#,
        r#"fields = ["id", "velocity", "density"]"#,
    );
    let session = within("create", client.create_session_toml(&scene))
        .await
        .expect("valid scene");
    let id = session.id.clone();
    let link = within("zenoh connect", ZenohLink::connect(&info.zenoh_locators))
        .await
        .expect("zenoh link");
    let frames = within("frame subscription", link.frames(&id))
        .await
        .expect("frames");
    within("step", client.step(&id, 1)).await.expect("step");
    let before = loop {
        let frame = within("frame 1", frames.recv()).await.expect("frame");
        if frame.step == 1 {
            break frame;
        }
    };
    let ids = before.ids.clone().expect("the scene names ids");
    let fluid = before.solids[0].first as usize;
    assert_eq!(fluid, 125);
    assert_eq!(ids[..fluid], (0..125).collect::<Vec<u32>>());
    let followed = position_of(&before, None, 60).expect("fluid particle 60");
    let solid_5 = position_of(&before, Some(1), 5).expect("solid particle 5");

    let refused = [
        client.change_particles(&id, 1, &[0], &[], &[]).await,
        client.change_particles(&id, 0, &[1, 999], &[], &[]).await,
        client
            .change_particles(&id, 0, &[1], &[[0.1, 0.9, 0.1]], &[[0.0; 3]])
            .await,
    ];
    for (result, mentions) in refused.into_iter().zip([
        "cannot remove particles",
        "no particle with id 999",
        "outside",
    ]) {
        let status = meshless_tests::rpc_status(result.expect_err(mentions));
        assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
        assert!(status.message().contains(mentions), "{}", status.message());
    }
    let (_, inserted) = within(
        "change",
        client.change_particles(&id, 0, &[1, 2, 124], &[[0.1, 0.35, 0.1]], &[[0.0; 3]]),
    )
    .await
    .expect("a valid change");
    assert_eq!(inserted, 125..126);

    within("step", client.step(&id, 1)).await.expect("step");
    let after = within("frame 2", frames.recv()).await.expect("frame");
    assert_eq!(after.step, 2);
    let fluid_after = after.solids[0].first as usize;
    assert_eq!(fluid_after, 123, "three left, one joined");
    let mut expected: Vec<u32> = (0..126).filter(|i| ![1, 2, 124].contains(i)).collect();
    let mut got = after.ids.as_ref().expect("ids")[..fluid_after].to_vec();
    got.sort_unstable();
    expected.sort_unstable();
    assert_eq!(got, expected);
    let moved = |a: [f32; 3], b: [f32; 3]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f32>()
            .sqrt()
    };
    let now = position_of(&after, None, 60).expect("60 stays");
    assert!(moved(now, followed) < 0.01, "{followed:?} -> {now:?}");
    let joined = position_of(&after, None, 125).expect("the new particle");
    assert!(moved(joined, [0.1, 0.35, 0.1]) < 0.01, "{joined:?}");
    let solid_now = position_of(&after, Some(1), 5).expect("solid particle 5");
    assert!(
        moved(solid_now, solid_5) < 0.01,
        "{solid_5:?} -> {solid_now:?}"
    );
    let over_grpc = within("latest over gRPC", client.latest_frame(&id))
        .await
        .expect("frame");
    assert_eq!(over_grpc, after);
}
