//! Shape and motion design over real gRPC (TCP) and real zenoh, against
//! the real `meshless-server` binary: constraint edits are atomic and
//! name the constraint at fault, an optimisation streams progress, keeps
//! its result and plays it back on the frame key, and a cancelled or
//! refused one changes nothing.

use meshless_client::{Client, ClientError, Design, DesignKind, OptimizeEvent, ZenohLink, v1};
use meshless_tests::{ServerProcess, rpc_status, small_solid_scene, within};
use tokio_stream::{Stream, StreamExt};
use tonic::Code;

/// How long a playback burst may pause before the test stops reading it:
/// the frames come at once, so a gap this long means the rest were dropped.
const BURST_GAP: std::time::Duration = std::time::Duration::from_secs(5);

fn vec3([x, y, z]: [f64; 3]) -> v1::Vec3 {
    v1::Vec3 { x, y, z }
}

fn constraint(name: &str, kind: v1::constraint::Kind) -> v1::Constraint {
    v1::Constraint {
        name: name.into(),
        kind: Some(kind),
    }
}

/// A handle moving a region of the column by `translation`.
fn region_handle(
    name: &str,
    min: [f64; 3],
    max: [f64; 3],
    translation: [f64; 3],
) -> v1::Constraint {
    constraint(
        name,
        v1::constraint::Kind::Handle(v1::HandleConstraint {
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
        }),
    )
}

/// A handle pinning particles of system 0 to `targets`.
fn particle_handle(name: &str, indices: Vec<u32>, targets: Vec<[f64; 3]>) -> v1::Constraint {
    constraint(
        name,
        v1::constraint::Kind::Handle(v1::HandleConstraint {
            points: Some(v1::Selection {
                kind: Some(v1::selection::Kind::Particles(v1::ParticleSelection {
                    system: 0,
                    indices,
                })),
            }),
            target: Some(v1::DesignTarget {
                kind: Some(v1::design_target::Kind::Positions(v1::PositionsTarget {
                    positions: targets.into_iter().map(vec3).collect(),
                })),
            }),
            time: None,
        }),
    )
}

fn sphere_obstacle(name: &str, radius: f64) -> v1::Constraint {
    constraint(
        name,
        v1::constraint::Kind::Obstacle(v1::ObstacleConstraint {
            shape: Some(v1::Shape {
                kind: Some(v1::shape::Kind::Sphere(v1::SphereShape { radius })),
            }),
            orientation: None,
            path: vec![v1::Waypoint {
                time: 0.0,
                position: Some(vec3([0.5, 0.5, 0.9])),
            }],
        }),
    )
}

fn add(c: v1::Constraint) -> v1::ConstraintEdit {
    v1::ConstraintEdit {
        edit: Some(v1::constraint_edit::Edit::Add(c)),
    }
}

fn names(constraints: &[v1::Constraint]) -> Vec<&str> {
    constraints.iter().map(|c| c.name.as_str()).collect()
}

/// The column's bottom fixed and its top lifted by 0.1 m (Figure 13 in
/// small).
fn stretch() -> Vec<v1::ConstraintEdit> {
    vec![
        add(region_handle(
            "bottom",
            [0.3, 0.3, 0.25],
            [0.7, 0.7, 0.36],
            [0.0; 3],
        )),
        add(region_handle(
            "top",
            [0.3, 0.3, 0.64],
            [0.7, 0.7, 0.75],
            [0.0, 0.0, 0.1],
        )),
    ]
}

fn shape_request(id: &str, settings: v1::DesignSettings, playback: bool) -> v1::OptimizeRequest {
    v1::OptimizeRequest {
        session_id: id.into(),
        system: 0,
        design: Some(settings),
        problem: Some(v1::optimize_request::Problem::Shape(v1::ShapeProblem {})),
        playback,
    }
}

fn small_design() -> v1::DesignSettings {
    v1::DesignSettings {
        particles: Some(40),
        ..Default::default()
    }
}

/// A design slow enough to cancel: many particles and a tolerance no
/// solve reaches.
fn slow_design() -> v1::DesignSettings {
    v1::DesignSettings {
        particles: Some(3000),
        solver: Some(v1::DesignSolverSettings {
            tolerance: Some(1e-300),
            max_iterations: Some(100_000),
            ..Default::default()
        }),
        ..Default::default()
    }
}

async fn next_event(
    events: &mut (impl Stream<Item = Result<OptimizeEvent, ClientError>> + Unpin),
) -> Option<Result<OptimizeEvent, ClientError>> {
    within("optimisation event", events.next()).await
}

/// Runs an optimisation to its end: the progress reports and the design.
async fn optimise(client: &Client, request: v1::OptimizeRequest) -> (usize, Design) {
    let mut events = within("optimize", client.optimize(request))
        .await
        .expect("the optimisation starts");
    let mut progress = 0;
    while let Some(event) = next_event(&mut events).await {
        match event.expect("a successful optimisation") {
            OptimizeEvent::Progress(_) => progress += 1,
            OptimizeEvent::Done(design) => return (progress, design),
        }
    }
    panic!("the stream ended without a design after {progress} progress reports");
}

/// The error an optimisation ends with, whether refused at the call or
/// on the stream.
async fn optimise_error(client: &Client, request: v1::OptimizeRequest) -> tonic::Status {
    let mut events = match within("optimize", client.optimize(request)).await {
        Ok(events) => events,
        Err(ClientError::Rpc(status)) => return status,
        Err(e) => panic!("expected a gRPC status, got {e}"),
    };
    while let Some(event) = next_event(&mut events).await {
        match event {
            Ok(OptimizeEvent::Progress(_)) => {}
            Ok(OptimizeEvent::Done(design)) => panic!("expected a failure, got {design:?}"),
            Err(ClientError::Rpc(status)) => return status,
            Err(e) => panic!("expected a gRPC status, got {e}"),
        }
    }
    panic!("the stream ended without an error");
}

/// Constraint edits: add, replace and remove round-trip through the list;
/// a batch with one bad edit (an unknown particle, a NaN target, a
/// zero-radius obstacle, a taken name, a missing kind) is refused with
/// INVALID_ARGUMENT naming the constraint, and changes nothing, not even
/// the batch's good edits.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn constraint_edits_are_atomic_and_name_the_bad_constraint() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let session = within("create", client.create_session_toml(&small_solid_scene()))
        .await
        .expect("valid scene");
    let id = session.id.clone();
    assert_eq!(session.particle_count, 128);

    let pin = particle_handle("pin", vec![0, 1], vec![[0.4, 0.4, 0.3], [0.45, 0.4, 0.3]]);
    let listed = within(
        "edit",
        client.edit_constraints(
            &id,
            vec![add(pin.clone()), add(sphere_obstacle("ball", 0.05))],
        ),
    )
    .await
    .expect("valid constraints");
    assert_eq!(names(&listed), ["ball", "pin"], "listed in name order");
    assert_eq!(listed[1], pin, "a constraint round-trips unchanged");

    let moved = particle_handle("pin", vec![2], vec![[0.5, 0.5, 0.3]]);
    let replace = v1::ConstraintEdit {
        edit: Some(v1::constraint_edit::Edit::Replace(moved.clone())),
    };
    let remove = v1::ConstraintEdit {
        edit: Some(v1::constraint_edit::Edit::Remove("ball".into())),
    };
    let listed = within(
        "replace and remove",
        client.edit_constraints(&id, vec![replace, remove]),
    )
    .await
    .expect("valid edits");
    assert_eq!(listed, vec![moved.clone()]);
    assert_eq!(
        within("list", client.list_constraints(&id))
            .await
            .expect("list"),
        listed
    );

    let bad = [
        (
            "unknown particle",
            particle_handle("far", vec![100_000], vec![[0.0; 3]]),
            "far",
        ),
        (
            "NaN target",
            particle_handle("nan", vec![3], vec![[f64::NAN, 0.0, 0.0]]),
            "nan",
        ),
        ("zero radius", sphere_obstacle("flat", 0.0), "flat"),
        (
            "taken name",
            particle_handle("pin", vec![4], vec![[0.5; 3]]),
            "pin",
        ),
        (
            "no kind",
            v1::Constraint {
                name: "empty".into(),
                kind: None,
            },
            "empty",
        ),
    ];
    for (what, constraint, name) in bad {
        let good = add(sphere_obstacle("good", 0.05));
        let error = within(
            what,
            client.edit_constraints(&id, vec![good, add(constraint)]),
        )
        .await
        .expect_err(what);
        let status = rpc_status(error);
        assert_eq!(status.code(), Code::InvalidArgument, "{what}: {status:?}");
        assert!(
            status.message().contains(name),
            "{what}: the message names `{name}`: {}",
            status.message()
        );
        let after = within("list", client.list_constraints(&id))
            .await
            .expect("list");
        assert_eq!(after, vec![moved.clone()], "{what}: nothing changed");
    }
}

/// A shape optimisation of the column stretched by its handles: progress
/// streams, the result converges with the handles met, `GetDesign`
/// returns it, and its playback frame arrives over zenoh with the top of
/// the solid lifted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shape_optimisation_streams_stores_and_plays_back() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let info = within("info", client.server_info()).await.expect("info");
    let session = within("create", client.create_session_toml(&small_solid_scene()))
        .await
        .expect("valid scene");
    let id = session.id.clone();
    let missing = within("no design yet", client.get_design(&id))
        .await
        .expect_err("no design before the first optimisation");
    assert_eq!(missing.code(), Some(Code::NotFound));

    within("edit", client.edit_constraints(&id, stretch()))
        .await
        .expect("valid handles");
    let link = within("zenoh", ZenohLink::connect(&info.zenoh_locators))
        .await
        .expect("zenoh link");
    let frames = within("frames", link.frames(&id)).await.expect("frames");
    let rest = within("latest", client.latest_frame(&id))
        .await
        .expect("frame");

    let (progress, design) = optimise(&client, shape_request(&id, small_design(), true)).await;
    assert!(progress >= 1, "at least one progress report");
    let info = design.info;
    let energies = info.energies.expect("energies");
    assert!(info.converged, "converges: {info:?}");
    assert!(
        energies.handle < 1.0,
        "the handles are met closely: {energies:?}"
    );
    assert_eq!(design.kind, DesignKind::Shape);
    assert_eq!(design.times, [0.0]);
    assert!(!design.rest_positions.is_empty());
    let lifted = design
        .positions(0)
        .expect("one frame")
        .iter()
        .zip(&design.rest_positions)
        .map(|(x, r)| x[2] - r[2])
        .fold(f64::MIN, f64::max);
    assert!(
        (lifted - 0.1).abs() < 0.02,
        "the top design particles rise by the handle's 0.1 m: {lifted}"
    );
    let stored = within("get design", client.get_design(&id))
        .await
        .expect("the design is kept");
    assert_eq!(stored, design);

    let played = within("playback frame", frames.recv())
        .await
        .expect("a frame");
    let z = |frame: &meshless_client::FrameView| {
        let positions = frame.field(v1::FieldKind::Position).expect("positions");
        positions
            .values
            .chunks_exact(3)
            .map(|p| f64::from(p[2]))
            .fold(f64::MIN, f64::max)
    };
    let rise = z(&played) - z(&rest);
    assert!(
        (rise - 0.1).abs() < 0.03,
        "the solid's top particles rise with the design: {rise}"
    );
    assert_eq!(played.step, rest.step, "playback does not step the world");
}

/// A cancelled optimisation ends with CANCELLED and changes nothing: the
/// session steps, the constraints and the last design are as they were.
/// A second optimisation while one runs is FAILED_PRECONDITION, and
/// dropping the stream cancels too (the session steps again at once).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cancelled_optimisation_changes_nothing() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let session = within("create", client.create_session_toml(&small_solid_scene()))
        .await
        .expect("valid scene");
    let id = session.id.clone();
    let constraints = within("edit", client.edit_constraints(&id, stretch()))
        .await
        .expect("valid handles");
    let (_, previous) = optimise(&client, shape_request(&id, small_design(), false)).await;

    let mut events = within(
        "optimize",
        client.optimize(shape_request(&id, slow_design(), false)),
    )
    .await
    .expect("starts");
    match next_event(&mut events).await {
        Some(Ok(OptimizeEvent::Progress(_))) => {}
        other => panic!("expected a first progress report, got {other:?}"),
    }
    let second = optimise_error(&client, shape_request(&id, small_design(), false)).await;
    assert_eq!(second.code(), Code::FailedPrecondition, "{second:?}");
    assert!(
        within("cancel", client.cancel_optimize(&id))
            .await
            .expect("cancel"),
        "an optimisation was running"
    );
    let ended = loop {
        match next_event(&mut events).await {
            Some(Ok(OptimizeEvent::Progress(_))) => {}
            Some(Err(e)) => break rpc_status(e),
            other => panic!("expected CANCELLED, got {other:?}"),
        }
    };
    assert_eq!(ended.code(), Code::Cancelled, "{ended:?}");
    assert!(next_event(&mut events).await.is_none(), "the stream ends");

    let stepped = within("step after cancel", client.step(&id, 1))
        .await
        .expect("the session still steps");
    assert_eq!(stepped.status.expect("status").step, 1);
    assert_eq!(
        within("list", client.list_constraints(&id))
            .await
            .expect("list"),
        constraints
    );
    assert_eq!(
        within("get design", client.get_design(&id))
            .await
            .expect("kept"),
        previous
    );
    assert!(
        !within("cancel", client.cancel_optimize(&id))
            .await
            .expect("cancel"),
        "nothing left to cancel"
    );

    // Dropping the stream cancels: the step queued behind it runs at once.
    let mut events = within(
        "optimize",
        client.optimize(shape_request(&id, slow_design(), false)),
    )
    .await
    .expect("starts");
    assert!(matches!(
        next_event(&mut events).await,
        Some(Ok(OptimizeEvent::Progress(_)))
    ));
    drop(events);
    let stepped = within("step after a dropped stream", client.step(&id, 1))
        .await
        .expect("the session still steps");
    assert_eq!(stepped.status.expect("status").step, 2);
    assert_eq!(
        within("get design", client.get_design(&id))
            .await
            .expect("kept"),
        previous
    );
}

/// Bad requests are INVALID_ARGUMENT naming what to change: no problem, a
/// system that is not a solid, a negative weight, a zero playback rate,
/// and a motion with a single keyframe time (which reaches the engine).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_optimisations_are_invalid_arguments() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let session = within("create", client.create_session_toml(&small_solid_scene()))
        .await
        .expect("valid scene");
    let id = session.id.clone();
    within("edit", client.edit_constraints(&id, stretch()))
        .await
        .expect("valid handles");
    let motion = |settings: v1::DesignSettings, playback_rate| v1::OptimizeRequest {
        problem: Some(v1::optimize_request::Problem::Motion(v1::MotionProblem {
            settings: None,
            playback_rate,
        })),
        ..shape_request(&id, settings, true)
    };
    let negative = v1::DesignSettings {
        weights: Some(v1::DesignWeights {
            rigidity: Some(-1.0),
            ..Default::default()
        }),
        ..small_design()
    };
    let cases = [
        (
            "no problem",
            v1::OptimizeRequest {
                problem: None,
                ..shape_request(&id, small_design(), false)
            },
            "problem",
        ),
        (
            "not a solid",
            v1::OptimizeRequest {
                system: 3,
                ..shape_request(&id, small_design(), false)
            },
            "system 3",
        ),
        (
            "negative weight",
            shape_request(&id, negative, false),
            "rigidity",
        ),
        (
            "zero playback rate",
            motion(small_design(), Some(0.0)),
            "playback_rate",
        ),
        // Untimed handles only: no keyframes for a motion.
        ("motion without keyframes", motion(small_design(), None), ""),
    ];
    for (what, request, names) in cases {
        let status = optimise_error(&client, request).await;
        assert_eq!(status.code(), Code::InvalidArgument, "{what}: {status:?}");
        assert!(
            status.message().contains(names),
            "{what}: the message names `{names}`: {}",
            status.message()
        );
    }
    let missing = within("no design", client.get_design(&id))
        .await
        .expect_err("failed optimisations store nothing");
    assert_eq!(missing.code(), Some(Code::NotFound));
}

/// A keyframe handle on the whole column, moved by `translation` at `time`.
fn keyframe(name: &str, time: f64, translation: [f64; 3]) -> v1::Constraint {
    let mut c = region_handle(name, [0.0; 3], [1.0; 3], translation);
    if let Some(v1::constraint::Kind::Handle(h)) = &mut c.kind {
        h.time = Some(time);
    }
    c
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn motion_optimisation_plays_back_along_the_motion() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let info = within("info", client.server_info()).await.expect("info");
    let session = within("create", client.create_session_toml(&small_solid_scene()))
        .await
        .expect("valid scene");
    let id = session.id.clone();
    // The session's own frame: where the column starts.
    let start = within("latest frame", client.latest_frame(&id))
        .await
        .expect("a frame");
    let edits = vec![
        add(keyframe("start", 0.0, [0.0; 3])),
        add(keyframe("middle", 0.5, [0.1, 0.0, 0.0])),
        add(keyframe("end", 1.0, [0.2, 0.1, 0.0])),
    ];
    within("edit", client.edit_constraints(&id, edits))
        .await
        .expect("valid keyframes");
    let link = within("zenoh", ZenohLink::connect(&info.zenoh_locators))
        .await
        .expect("zenoh link");
    let frames = within("frames", link.frames(&id)).await.expect("frames");
    let rate = 10.0;
    let request = v1::OptimizeRequest {
        session_id: id.clone(),
        system: 0,
        design: Some(small_design()),
        problem: Some(v1::optimize_request::Problem::Motion(v1::MotionProblem {
            settings: None,
            playback_rate: Some(rate),
        })),
        playback: true,
    };
    let (progress, design) = optimise(&client, request).await;
    assert!(progress >= 1);
    assert_eq!(design.kind, DesignKind::Motion);
    assert!(design.times.len() >= 3, "frames at the keyframes at least");
    assert_eq!(design.times.first(), Some(&0.0));
    assert_eq!(design.times.last(), Some(&1.0));
    assert!(design.info.converged, "{:?}", design.info);

    // Up to span * rate + 1 frames, in time order, the column moving with
    // the keyframes: 0.2 m along x by the end. Frames are drop-not-block,
    // so a loaded machine may lose some of the burst (waiting for all 11
    // once timed out in CI), the last included (waiting for it timed out
    // in CI too): read while the burst lasts, check each frame against the
    // design at its time, and the end against the design's last frame.
    let mean_x = |frame: &meshless_client::FrameView| {
        let p = frame.field(v1::FieldKind::Position).expect("positions");
        let xs: Vec<f64> = p.values.chunks_exact(3).map(|p| f64::from(p[0])).collect();
        xs.iter().sum::<f64>() / xs.len() as f64
    };
    let mut played = Vec::new();
    while let Ok(frame) = tokio::time::timeout(BURST_GAP, frames.recv()).await {
        let frame = frame.expect("a frame");
        let last = (frame.time - 1.0).abs() < 1e-9;
        played.push(frame);
        if last {
            break;
        }
        assert!(played.len() < 11, "no frame at the end of the motion");
    }
    let times: Vec<f64> = played.iter().map(|f| f.time).collect();
    assert!(
        times.windows(2).all(|w| w[1] > w[0]),
        "playback times increase: {times:?}"
    );
    assert!(
        times
            .iter()
            .all(|t| (t * rate - (t * rate).round()).abs() < 1e-9),
        "one frame per tenth of a second: {times:?}"
    );
    assert!(!played.is_empty(), "no playback frame arrived");
    // The design's own frames (at its times; playback interpolates
    // between them) and the frames played at those times agree.
    let designed_x = |time: f64| {
        let k = design.times.iter().position(|&t| (t - time).abs() < 1e-9)?;
        let positions = design.positions(k)?;
        Some(positions.iter().map(|p| p[0]).sum::<f64>() / positions.len() as f64)
    };
    for frame in &played {
        if let Some(want) = designed_x(frame.time) {
            let got = mean_x(frame);
            assert!(
                (got - want).abs() < 1e-5,
                "at {} s: {got} vs the design's {want}",
                frame.time
            );
        }
    }
    let shift = designed_x(1.0).expect("the design ends at 1 s") - mean_x(&start);
    assert!(
        (shift - 0.2).abs() < 0.01,
        "the column ends 0.2 m along x: {shift}"
    );
}
