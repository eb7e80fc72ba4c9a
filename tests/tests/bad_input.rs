//! Bad input over the real service: every case gets the right gRPC code and
//! a message naming what to change, leaves sessions as they were, and
//! never stalls the server or its other sessions.

use meshless_client::{Client, ClientError, v1};
use meshless_tests::{ServerProcess, small_scene, within};
use tonic::Code;

fn expect_code(result: Result<v1::Session, ClientError>, code: Code, mentions: &str) {
    match result {
        Ok(session) => panic!(
            "expected {code:?} mentioning {mentions:?}, got session {:?}",
            session.id
        ),
        Err(err) => {
            assert_eq!(err.code(), Some(code), "{err}");
            assert!(
                err.to_string().contains(mentions),
                "{err:?} should mention {mentions:?}"
            );
        }
    }
}

/// Makes one field of a valid scene invalid.
type Breaker = Box<dyn Fn(&mut v1::SceneSpec)>;

fn state(session: &v1::Session) -> v1::SessionState {
    v1::SessionState::try_from(session.status.as_ref().expect("status").state).expect("known")
}

/// The small scene as a proto message, via the server's own echo.
async fn small_spec(client: &Client) -> v1::SceneSpec {
    let session = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("ok");
    within("delete", client.delete_session(&session.id))
        .await
        .expect("deleted");
    session.scene.expect("scene echo")
}

fn fluid(spec: &mut v1::SceneSpec) -> &mut v1::FluidSpec {
    match spec.systems[0].kind.as_mut() {
        Some(v1::system_spec::Kind::Fluid(f)) => f,
        Some(
            v1::system_spec::Kind::RigidBody(_)
            | v1::system_spec::Kind::Solid(_)
            | v1::system_spec::Kind::ModalSolid(_)
            | v1::system_spec::Kind::Shell(_),
        )
        | None => panic!("a fluid"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_input_gets_the_right_code_and_loses_nothing() {
    let server = ServerProcess::spawn(&["--max-particles", "1000", "--max-sessions", "4"])
        .await
        .expect("server starts");
    let client = server.client().await.expect("client");
    let spec = small_spec(&client).await;

    // A healthy session runs (paced to real time) through everything below.
    let healthy = within("create", client.create_session(spec.clone()))
        .await
        .expect("ok");
    within("run", client.run_forever(&healthy.id, Some(1.0)))
        .await
        .expect("runs");

    // Invalid scenes: INVALID_ARGUMENT naming the field and the range.
    let cases: Vec<(&str, Breaker)> = vec![
        ("systems[0].spacing", Box::new(|s| fluid(s).spacing = -0.1)),
        (
            "systems[0].support_radius",
            Box::new(|s| fluid(s).support_radius = Some(0.0)),
        ),
        (
            "systems[0].stiffness",
            Box::new(|s| fluid(s).stiffness = f64::NAN),
        ),
        (
            "gravity.y",
            Box::new(|s| s.gravity.as_mut().expect("g").y = f64::INFINITY),
        ),
        (
            "domain",
            Box::new(|s| s.domain.as_mut().expect("d").max.as_mut().expect("max").x = 0.0),
        ),
        ("systems[0].kind", Box::new(|s| s.systems[0].kind = None)),
        ("time", Box::new(|s| s.time = None)),
        (
            "output.fields[2]",
            Box::new(|s| s.output.as_mut().expect("o").fields.push(42)),
        ),
    ];
    for (field, break_it) in cases {
        let mut bad = spec.clone();
        break_it(&mut bad);
        expect_code(
            within(field, client.create_session(bad)).await,
            Code::InvalidArgument,
            field,
        );
    }
    let toml = small_scene().replace("kind = \"fluid\"", "kind = \"plasma\"");
    expect_code(
        within("unknown system", client.create_session_toml(&toml)).await,
        Code::InvalidArgument,
        "plasma",
    );

    // Particles piled at one point (50,000 once took the server past 3 GB
    // of neighbour lists; 500 stay under this server's particle limit):
    // refused before any neighbour search, naming the pile.
    let mut pile = spec.clone();
    let at = v1::Vec3 {
        x: 0.1,
        y: 0.1,
        z: 0.1,
    };
    fluid(&mut pile).particles = vec![
        v1::Particle {
            position: Some(at),
            velocity: None,
        };
        500
    ];
    expect_code(
        within("piled particles", client.create_session(pile)).await,
        Code::InvalidArgument,
        "within one spacing",
    );

    // Limits: RESOURCE_EXHAUSTED.
    let mut big = spec.clone();
    fluid(&mut big).spacing = 0.01;
    fluid(&mut big).support_radius = Some(0.02);
    expect_code(
        within("too many particles", client.create_session(big)).await,
        Code::ResourceExhausted,
        "limit of 1000",
    );

    // Unknown ids: NOT_FOUND, for every call that takes one.
    expect_code(
        within("get", client.get_session("nope")).await,
        Code::NotFound,
        "nope",
    );
    expect_code(
        within("step", client.step("nope", 1)).await,
        Code::NotFound,
        "nope",
    );
    expect_code(
        within("reset", client.reset("nope")).await,
        Code::NotFound,
        "nope",
    );
    // A 20 kB id: still NOT_FOUND (not a header overflow), quoting a prefix.
    let long_id = "z".repeat(20_000);
    match within("long id", client.get_session(&long_id)).await {
        Ok(session) => panic!("a 20 kB id found session {:?}", session.id),
        Err(err) => {
            assert_eq!(err.code(), Some(Code::NotFound), "{err}");
            let message = err.to_string();
            assert!(message.len() < 300, "echoes {} bytes", message.len());
            assert!(message.contains("20002 bytes in all"), "{message}");
        }
    }
    let mut long_name = spec.clone();
    long_name.name = "n".repeat(1 << 20);
    expect_code(
        within("1 MB name", client.create_session(long_name)).await,
        Code::InvalidArgument,
        "name",
    );
    let err = within("delete", client.delete_session("nope"))
        .await
        .expect_err("unknown");
    assert_eq!(err.code(), Some(Code::NotFound));
    let err = within("watch", client.watch_status("nope"))
        .await
        .err()
        .expect("unknown");
    assert_eq!(err.code(), Some(Code::NotFound));

    // Bad commands on a good session leave it unchanged.
    let other = within("create", client.create_session(spec.clone()))
        .await
        .expect("ok");
    within("step", client.step(&other.id, 2))
        .await
        .expect("steps");
    let before = within("get", client.get_session(&other.id))
        .await
        .expect("ok");
    expect_code(
        within("0 steps", client.step(&other.id, 0)).await,
        Code::InvalidArgument,
        "steps",
    );
    expect_code(
        within("past time", client.run_until(&other.id, 0.01, None)).await,
        Code::InvalidArgument,
        "until_time",
    );
    expect_code(
        within("NaN rate", client.run_until(&other.id, 1.0, Some(f64::NAN))).await,
        Code::InvalidArgument,
        "realtime_factor",
    );
    // A factor too small to pace by (it once panicked the compute thread)
    // or too large to mean anything, printed short.
    for (factor, printed) in [(1e-300, "1e-300"), (1e-7, "1e-7"), (1e300, "1e300")] {
        expect_code(
            within(
                "extreme rate",
                client.run_until(&other.id, 1.0, Some(factor)),
            )
            .await,
            Code::InvalidArgument,
            printed,
        );
    }
    expect_code(
        within("nothing to resume", client.resume(&other.id)).await,
        Code::FailedPrecondition,
        "resume",
    );
    let after = within("get", client.get_session(&other.id))
        .await
        .expect("ok");
    assert_eq!(before, after, "rejected requests changed the session");

    // A running session refuses a step.
    expect_code(
        within("step while running", client.step(&healthy.id, 1)).await,
        Code::FailedPrecondition,
        "running",
    );

    // A simulation that blows up: FAULTED with the reason, last good frame
    // kept, further steps refused, reset recovers.
    let mut unstable = spec.clone();
    fluid(&mut unstable).stiffness = 1e12;
    unstable.time.as_mut().expect("time").max_substeps = Some(1);
    let doomed = within("create", client.create_session(unstable))
        .await
        .expect("valid");
    let faulted = within("step to blow-up", client.step(&doomed.id, 200))
        .await
        .expect("answers");
    assert_eq!(state(&faulted), v1::SessionState::Faulted);
    let reason = &faulted.status.as_ref().expect("status").reason;
    assert!(reason.contains("unstable"), "{reason}");
    let kept = within("latest", client.latest_frame(&doomed.id))
        .await
        .expect("frame");
    assert!(
        kept.fields
            .iter()
            .all(|f| f.values.iter().all(|v| v.is_finite()))
    );
    expect_code(
        within("step faulted", client.step(&doomed.id, 1)).await,
        Code::FailedPrecondition,
        "faulted",
    );
    expect_code(
        within("run faulted", client.run_until(&doomed.id, 5.0, None)).await,
        Code::FailedPrecondition,
        "faulted",
    );
    let reset = within("reset", client.reset(&doomed.id))
        .await
        .expect("reset");
    assert_eq!(state(&reset), v1::SessionState::Idle);

    // Four sessions exist (healthy, other, doomed, plus none deleted): the
    // fifth is refused at the session limit.
    within("fourth", client.create_session(spec.clone()))
        .await
        .expect("room for 4");
    expect_code(
        within("fifth", client.create_session(spec.clone())).await,
        Code::ResourceExhausted,
        "limit",
    );

    // Through all of it the healthy session kept running.
    let healthy_now = within("get", client.get_session(&healthy.id))
        .await
        .expect("ok");
    assert_eq!(state(&healthy_now), v1::SessionState::Running);
    let step = healthy_now.status.as_ref().expect("status").step;
    let paused = within("pause", client.pause(&healthy.id))
        .await
        .expect("pauses");
    assert_eq!(state(&paused), v1::SessionState::Paused);
    let stepped = within("step", client.step(&healthy.id, 1))
        .await
        .expect("steps");
    assert!(stepped.status.as_ref().expect("status").step > step);
}

/// A soft cube in the air of the small tank, as the server echoes it.
async fn solid_spec(client: &Client) -> v1::SceneSpec {
    let mut spec = small_spec(client).await;
    spec.systems.push(v1::SystemSpec {
        kind: Some(v1::system_spec::Kind::Solid(v1::SolidSpec {
            shape: Some(v1::Shape {
                kind: Some(v1::shape::Kind::Box(v1::BoxShape {
                    half_extents: Some(v1::Vec3 {
                        x: 0.08,
                        y: 0.08,
                        z: 0.08,
                    }),
                })),
            }),
            position: Some(v1::Vec3 {
                x: 0.35,
                y: 0.35,
                z: 0.35,
            }),
            spacing: 0.04,
            young: 1e5,
            ..Default::default()
        })),
    });
    spec
}

fn solid(spec: &mut v1::SceneSpec) -> &mut v1::SolidSpec {
    match spec.systems[1].kind.as_mut() {
        Some(v1::system_spec::Kind::Solid(s)) => s,
        Some(
            v1::system_spec::Kind::Fluid(_)
            | v1::system_spec::Kind::RigidBody(_)
            | v1::system_spec::Kind::ModalSolid(_)
            | v1::system_spec::Kind::Shell(_),
        )
        | None => panic!("a solid"),
    }
}

/// Bad solids get INVALID_ARGUMENT naming the field, whether the protocol
/// conversion or the engine's validation catches them, and the server
/// goes on creating and stepping solids afterwards.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_solids_are_invalid_arguments_naming_the_field() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let spec = solid_spec(&client).await;
    let anchor = |x: f64| v1::Aabb {
        min: Some(v1::Vec3 { x, y: x, z: x }),
        max: Some(v1::Vec3 {
            x: x + 0.01,
            y: x + 0.01,
            z: x + 0.01,
        }),
    };
    let cases: Vec<(&str, Breaker)> = vec![
        (
            "systems[1].poisson",
            Box::new(|s| solid(s).poisson = Some(0.5)),
        ),
        (
            "systems[1].support",
            Box::new(|s| solid(s).support = Some(1.0)),
        ),
        (
            "systems[1].anchors[0]",
            Box::new(move |s| solid(s).anchors.push(anchor(0.45))),
        ),
        (
            "systems[1].shape",
            Box::new(|s| {
                solid(s).shape = Some(v1::Shape {
                    kind: Some(v1::shape::Kind::Plane(v1::PlaneShape {
                        normal: Some(v1::Vec3 {
                            x: 0.0,
                            y: 1.0,
                            z: 0.0,
                        }),
                        offset: 0.0,
                    })),
                });
            }),
        ),
        ("systems[1].young", Box::new(|s| solid(s).young = 0.0)),
        ("systems[1].order", Box::new(|s| solid(s).order = Some(99))),
        (
            "systems[1].integrator",
            Box::new(|s| solid(s).integrator = Some(v1::SolidIntegrator::Unspecified as i32)),
        ),
        (
            "systems[1].position",
            Box::new(|s| solid(s).position = None),
        ),
        (
            "systems[1].implicit.max_cg_iterations",
            Box::new(|s| {
                solid(s).implicit = Some(v1::ImplicitSettings {
                    max_cg_iterations: Some(0),
                    ..Default::default()
                });
            }),
        ),
        (
            "systems[1].plasticity.creep",
            Box::new(|s| {
                solid(s).plasticity = Some(v1::Plasticity {
                    yield_strain: 0.01,
                    creep: 0.0,
                    max: 0.5,
                    rebase: None,
                });
            }),
        ),
        (
            "systems[1].fracture",
            Box::new(|s| {
                solid(s).fracture = Some(v1::Fracture {
                    stress: Some(1e5),
                    kappa: Some(0.0),
                    ..Default::default()
                });
            }),
        ),
        (
            // Both thresholds, or neither: the scene must say which.
            "systems[1].fracture",
            Box::new(|s| {
                solid(s).fracture = Some(v1::Fracture {
                    stress: Some(1e5),
                    plastic_strain: Some(0.1),
                    ..Default::default()
                });
            }),
        ),
        (
            // A ductile threshold on a solid that does not flow.
            "systems[1].fracture",
            Box::new(|s| {
                solid(s).fracture = Some(v1::Fracture {
                    plastic_strain: Some(0.1),
                    ..Default::default()
                });
            }),
        ),
        (
            "systems[1].fracture.toughness",
            Box::new(|s| {
                solid(s).fracture = Some(v1::Fracture {
                    // A toughness beside a ductile threshold: it
                    // needs the strength that starts cracks.
                    plastic_strain: Some(0.1),
                    toughness: Some(1e4),
                    ..Default::default()
                });
            }),
        ),
        (
            // A notch whose plane has no normal.
            "systems[1].fracture.notches[0]",
            Box::new(|s| {
                solid(s).fracture = Some(v1::Fracture {
                    stress: Some(1e5),
                    notches: vec![v1::Notch {
                        center: Some(v1::Vec3::default()),
                        normal: Some(v1::Vec3::default()),
                        radius: 0.1,
                    }],
                    ..Default::default()
                });
            }),
        ),
        (
            "systems[1].fracture.criterion",
            Box::new(|s| {
                solid(s).fracture = Some(v1::Fracture {
                    stress: Some(1e5),
                    criterion: Some(99),
                    ..Default::default()
                });
            }),
        ),
        (
            "systems[1].surface.method",
            Box::new(|s| {
                solid(s).surface = Some(v1::SolidSurfaceSpec {
                    method: Some(99),
                    subdivisions: None,
                });
            }),
        ),
        (
            "systems[1].surface.subdivisions",
            Box::new(|s| {
                solid(s).surface = Some(v1::SolidSurfaceSpec {
                    method: None,
                    subdivisions: Some(8),
                });
            }),
        ),
        (
            // A capsule has no surface mesh to embed.
            "systems[1].surface",
            Box::new(|s| {
                let solid = solid(s);
                solid.shape = Some(v1::Shape {
                    kind: Some(v1::shape::Kind::Capsule(v1::CapsuleShape {
                        half_length: 0.04,
                        radius: 0.06,
                    })),
                });
                solid.surface = Some(v1::SolidSurfaceSpec::default());
            }),
        ),
    ];
    for (field, break_it) in cases {
        let mut bad = spec.clone();
        break_it(&mut bad);
        expect_code(
            within(field, client.create_session(bad)).await,
            Code::InvalidArgument,
            field,
        );
    }
    // Too many particles is a resource limit for a solid as for a fluid.
    let mut fine = spec.clone();
    solid(&mut fine).spacing = 1e-5;
    expect_code(
        within("too fine", client.create_session(fine)).await,
        Code::ResourceExhausted,
        "systems[1].spacing",
    );
    // Embedded surfaces are 3D only.
    let flat = r#"
dimension = 2
[domain]
min = [0.0, 0.0, 0.0]
max = [1.0, 1.0, 0.0]
[time]
dt = 0.01
[[systems]]
kind = "solid"
shape = { type = "box", half_extents = [0.1, 0.1, 0.0] }
position = [0.5, 0.5, 0.0]
spacing = 0.04
young = 1.0e5
surface = {}
"#;
    expect_code(
        within("2D surface", client.create_session_toml(flat)).await,
        Code::InvalidArgument,
        "systems[0].surface: embedded surfaces are 3D only",
    );
    within(
        "2D solid",
        client.create_session_toml(&flat.replace("surface = {}\n", "")),
    )
    .await
    .expect("the same solid without a surface is valid");

    // A solid that blows up (a stiff one, hanging from a corner so that it
    // strains, forced into one sub-step per step) faults its session,
    // naming the solid; reset recovers. The domain is wide enough that no
    // particle reaches a wall, whose collisions would hold the runaway
    // particles there before the check sees them.
    let unstable = r#"
[domain]
min = [-1.0e6, -1.0e6, -1.0e6]
max = [1.0e6, 1.0e6, 1.0e6]
[time]
dt = 0.01
max_substeps = 1
[[systems]]
kind = "solid"
shape = { type = "box", half_extents = [0.08, 0.08, 0.08] }
position = [0.35, 0.35, 0.35]
spacing = 0.04
young = 1.0e12
anchors = [{ min = [0.285, 0.285, 0.285], max = [0.295, 0.295, 0.295] }]
"#;
    let doomed = within("create", client.create_session_toml(unstable))
        .await
        .expect("valid");
    let faulted = within("step to blow-up", client.step(&doomed.id, 100))
        .await
        .expect("answers");
    assert_eq!(state(&faulted), v1::SessionState::Faulted);
    let reason = &faulted.status.as_ref().expect("status").reason;
    assert!(
        reason.contains("unstable") && reason.contains("systems[0]"),
        "{reason}"
    );
    let reset = within("reset", client.reset(&doomed.id))
        .await
        .expect("reset");
    assert_eq!(state(&reset), v1::SessionState::Idle);

    // Still serving: the valid solid, anchored by a box about its corner
    // particle (at 0.29 on each axis), is created and steps.
    let mut good = spec;
    solid(&mut good).anchors.push(anchor(0.285));
    let session = within("create", client.create_session(good))
        .await
        .expect("valid");
    let stepped = within("step", client.step(&session.id, 2))
        .await
        .expect("steps");
    assert_eq!(state(&stepped), v1::SessionState::Paused);
    assert_eq!(stepped.status.as_ref().expect("status").step, 2);
}

/// Sessions are admitted by their memory estimate against the server's
/// budget, before anything is allocated: a scene that does not fit is
/// RESOURCE_EXHAUSTED naming the budget, the others run on, and deleting a
/// session gives its share back.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scenes_beyond_the_memory_budget_are_refused() {
    let server = ServerProcess::spawn(&["--memory-budget-mb", "4"])
        .await
        .expect("server starts");
    let client = server.client().await.expect("client");
    let spec = small_spec(&client).await;
    let small = within("create", client.create_session(spec.clone()))
        .await
        .expect("a small scene fits");

    // 8,000 particles: about 8 MB by the estimate, over the 4 MB budget.
    let mut big = spec.clone();
    fluid(&mut big).spacing = 0.01;
    fluid(&mut big).support_radius = Some(0.02);
    expect_code(
        within("over budget", client.create_session(big.clone())).await,
        Code::ResourceExhausted,
        "memory budget",
    );
    let listed = within("list", client.list_sessions()).await.expect("ok");
    assert_eq!(listed.len(), 1, "the refused scene left nothing behind");
    within("step", client.step(&small.id, 1))
        .await
        .expect("the admitted session runs on");

    // A scene that fits only once the first session's share is back.
    let mut half = spec.clone();
    fluid(&mut half).spacing = 0.015;
    fluid(&mut half).support_radius = Some(0.03);
    let mut sessions = Vec::new();
    loop {
        match within("fill", client.create_session(half.clone())).await {
            Ok(session) => sessions.push(session.id),
            Err(err) => {
                assert_eq!(err.code(), Some(Code::ResourceExhausted), "{err}");
                break;
            }
        }
        assert!(sessions.len() < 100, "the budget never filled");
    }
    let freed = sessions.pop().expect("at least one fitted");
    within("delete", client.delete_session(&freed))
        .await
        .expect("deleted");
    within("refill", client.create_session(half))
        .await
        .expect("a deleted session's share is given back");
}

/// A request over the server's size limit is RESOURCE_EXHAUSTED naming
/// the limit (tonic's codec alone would say OUT_OF_RANGE), and the server
/// serves the next request.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn oversize_requests_are_resource_exhausted() {
    let server = ServerProcess::spawn(&["--max-request-mb", "1"])
        .await
        .expect("server starts");
    let client = server.client().await.expect("client");
    let spec = small_spec(&client).await;
    let mut huge = spec.clone();
    huge.name = "n".repeat(2 << 20);
    let err = within("2 MB request", client.create_session(huge))
        .await
        .expect_err("over the limit");
    assert_eq!(err.code(), Some(Code::ResourceExhausted), "{err}");
    assert!(err.to_string().contains("--max-request-mb"), "{err}");
    within("next request", client.create_session(spec))
        .await
        .expect("still serving");
}
