//! Checkpoints against the real `meshless-server` binary: a server killed
//! with SIGKILL mid-run and started again on the same checkpoint
//! directory comes back with every session (ids, owners, observers,
//! constraints, state), losing at most one interval of a running one; a
//! half-written or corrupted checkpoint is never read as one; a deleted
//! session's checkpoint goes with it; SIGTERM writes a last round; a
//! checkpoint that does not fit the disk is cleaned up, counted and
//! written again once it fits, the others written meanwhile; a link to
//! `/dev/zero` or a FIFO in the directory never holds up a start.

use meshless_client::{Client, Identity, v1};
use meshless_tests::{
    ServerProcess, TempDir, fixture, make_fifo, small_scene, small_solid_scene, within,
};
use std::path::Path;
use std::time::{Duration, SystemTime};

const ALICE: &str = "alice-token-checkpoint-01";
const BOB: &str = "bob-token-checkpoint-0001";

/// Seconds between checkpoints of the crash test.
const INTERVAL: f64 = 0.25;

fn as_token(token: &str) -> Identity {
    Identity {
        token: Some(token.into()),
        ..Identity::default()
    }
}

async fn spawn(dir: &Path, interval: f64) -> ServerProcess {
    let tokens = dir.join("tokens");
    let checkpoints = dir.join("checkpoints");
    ServerProcess::spawn(&[
        "--tokens-file",
        tokens.to_str().expect("utf-8"),
        "--checkpoint-dir",
        checkpoints.to_str().expect("utf-8"),
        "--checkpoint-interval",
        &interval.to_string(),
    ])
    .await
    .expect("server")
}

async fn clients(server: &ServerProcess) -> (Client, Client) {
    (
        server.client_as(&as_token(ALICE)).await.expect("alice"),
        server.client_as(&as_token(BOB)).await.expect("bob"),
    )
}

/// When `path` was last written, if it exists.
fn written(path: &Path) -> Option<SystemTime> {
    std::fs::metadata(path).and_then(|m| m.modified()).ok()
}

/// Waits until the checkpoint at `path` (of a running session, which
/// changes between rounds) has been rewritten twice after this call: a
/// round has certainly run with the session as it is now.
async fn two_rounds(path: &Path) {
    within("two checkpoint rounds", async {
        let mut seen = Vec::new();
        let mut ticks = tokio::time::interval(Duration::from_millis(20));
        while seen.len() < 3 {
            ticks.tick().await;
            if let Some(at) = written(path)
                && seen.last() != Some(&at)
            {
                seen.push(at);
            }
        }
    })
    .await;
}

fn vec3([x, y, z]: [f64; 3]) -> v1::Vec3 {
    v1::Vec3 { x, y, z }
}

/// A handle lifting the top of the small column.
fn lift() -> v1::ConstraintEdit {
    v1::ConstraintEdit {
        edit: Some(v1::constraint_edit::Edit::Add(v1::Constraint {
            name: "top".into(),
            kind: Some(v1::constraint::Kind::Handle(v1::HandleConstraint {
                points: Some(v1::Selection {
                    kind: Some(v1::selection::Kind::Region(v1::Aabb {
                        min: Some(vec3([0.3, 0.3, 0.64])),
                        max: Some(vec3([0.7, 0.7, 0.75])),
                    })),
                }),
                target: Some(v1::DesignTarget {
                    kind: Some(v1::design_target::Kind::Transform(v1::TransformTarget {
                        translation: Some(vec3([0.0, 0.0, 0.1])),
                        rotation: None,
                        centre: None,
                    })),
                }),
                time: None,
            })),
        })),
    }
}

async fn status(client: &Client, id: &str) -> v1::SessionStatus {
    within("get", client.get_session(id))
        .await
        .expect("the session")
        .status
        .expect("a status")
}

#[tokio::test]
async fn a_killed_server_comes_back_with_its_sessions() {
    let dir = TempDir::new("checkpoints");
    std::fs::write(dir.0.join("tokens"), format!("alice {ALICE}\nbob {BOB}\n")).expect("tokens");
    let checkpoints = dir.0.join("checkpoints");

    let server = spawn(&dir.0, INTERVAL).await;
    let (alice, bob) = clients(&server).await;
    // Alice runs a fluid in real time; Bob steps a solid with a
    // constraint that Alice may observe.
    let fluid = within("create", alice.create_session_toml(&fixture("python_tank")))
        .await
        .expect("created")
        .id;
    within("run", alice.run_forever(&fluid, Some(1.0)))
        .await
        .expect("running");
    let solid = within(
        "create",
        bob.create_session_toml_with_observers(&small_solid_scene(), vec!["alice".into()]),
    )
    .await
    .expect("created")
    .id;
    within("edit", bob.edit_constraints(&solid, vec![lift()]))
        .await
        .expect("constrained");
    within("step", bob.step(&solid, 5)).await.expect("stepped");
    let solid_frame = within("frame", bob.latest_frame(&solid))
        .await
        .expect("frame");
    // A session deleted before the crash must not come back.
    let gone = within("create", bob.create_session_toml(&small_solid_scene()))
        .await
        .expect("created")
        .id;
    // An unchanged session is written once.
    let gone_file = checkpoints.join(format!("{gone}.snapshot"));
    within("its checkpoint", async {
        let mut ticks = tokio::time::interval(Duration::from_millis(20));
        while written(&gone_file).is_none() {
            ticks.tick().await;
        }
    })
    .await;
    within("delete", bob.delete_session(&gone))
        .await
        .expect("deleted");
    assert!(
        !checkpoints.join(format!("{gone}.snapshot")).exists(),
        "a deleted session's checkpoint goes with it"
    );

    two_rounds(&checkpoints.join(format!("{fluid}.snapshot"))).await;
    let before = status(&alice, &fluid).await;
    let fluid_dt = 0.01;
    server.kill().await.expect("killed");

    // What a crash mid-write leaves, and a checkpoint gone bad.
    std::fs::write(checkpoints.join(format!("{fluid}.tmp")), b"half a chec").expect("tmp");
    let good = std::fs::read(checkpoints.join(format!("{solid}.snapshot"))).expect("read");
    std::fs::write(
        checkpoints.join("0123456789abcdef.snapshot"),
        &good[..good.len() / 3],
    )
    .expect("truncated");

    let server = spawn(&dir.0, INTERVAL).await;
    let (alice, bob) = clients(&server).await;
    let restored = status(&alice, &fluid).await;
    let lost = before.step - restored.step;
    let lost_seconds = lost as f64 * fluid_dt;
    println!(
        "crash at step {}, restored at step {}: {lost} steps, {lost_seconds:.3} s of a real-time \
         run lost with checkpoints every {INTERVAL} s",
        before.step, restored.step
    );
    assert!(restored.step <= before.step);
    // At most one interval of a real-time run, and the time the last
    // round took to write.
    assert!(lost_seconds <= INTERVAL + 0.25, "{lost_seconds} s lost");
    assert_eq!(
        restored.state,
        v1::SessionState::Paused as i32,
        "a run comes back paused: {}",
        restored.reason
    );
    assert!(restored.run_until.is_none(), "it ran forever");
    within("resume", alice.resume(&fluid))
        .await
        .expect("the run resumes");

    let session = within("get", bob.get_session(&solid)).await.expect("solid");
    assert_eq!(session.owner, "bob");
    assert_eq!(session.observers, vec!["alice".to_owned()]);
    assert_eq!(session.status.expect("status").step, 5);
    let constraints = within("list", bob.list_constraints(&solid))
        .await
        .expect("listed");
    assert_eq!(constraints.len(), 1);
    assert_eq!(constraints[0].name, "top");
    let frame = within("frame", bob.latest_frame(&solid))
        .await
        .expect("frame");
    assert_eq!(
        (frame.fields, frame.bodies),
        (solid_frame.fields, solid_frame.bodies)
    );
    // Owners are kept: Alice observes Bob's solid, and may not drive it.
    within("alice reads", alice.get_session(&solid))
        .await
        .expect("an observer reads");
    let err = within("alice steps", alice.step(&solid, 1))
        .await
        .expect_err("not hers");
    assert_eq!(err.code(), Some(tonic::Code::PermissionDenied), "{err}");
    // Nor take its snapshot: that is the owner's.
    let err = within("alice snapshots", alice.snapshot(&solid))
        .await
        .expect_err("not hers");
    assert_eq!(err.code(), Some(tonic::Code::PermissionDenied), "{err}");

    let sessions = within("list", bob.list_sessions()).await.expect("listed");
    let alices = within("list", alice.list_sessions()).await.expect("listed");
    assert_eq!(alices.len(), 2, "the fluid and the observed solid");
    assert_eq!(
        sessions.len(),
        1,
        "bob sees his solid; the deleted one stays gone"
    );
    assert!(
        !checkpoints.join(format!("{fluid}.tmp")).exists(),
        "removed at start"
    );
    assert!(
        checkpoints.join("0123456789abcdef.rejected").exists(),
        "a bad checkpoint is kept aside, never restored"
    );

    // SIGTERM writes a last round, whatever the interval.
    within("step", bob.step(&solid, 3)).await.expect("stepped");
    server.terminate().await.expect("stopped");
    let server = spawn(&dir.0, 3600.0).await;
    let (_, bob) = clients(&server).await;
    assert_eq!(status(&bob, &solid).await.step, 8);
}

/// The step of the checkpoint at `path`, if one is there and whole.
fn checkpoint_step(path: &Path) -> Option<u64> {
    let data = std::fs::read(path).ok()?;
    let payload = meshless_proto::snapshot::decode(&data, usize::MAX).ok()?;
    payload.world.map(|w| w.step)
}

/// A long `Step` does not escape the checkpoints: a round during it
/// writes the step it has reached, so a server killed with SIGKILL in
/// the middle of a `Step(1_000_000)` comes back at a step past the one
/// the `Step` began at, paused there, and steps on.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_long_step_is_checkpointed_between_its_steps() {
    let dir = TempDir::new("checkpoints-long-step");
    std::fs::write(dir.0.join("tokens"), format!("alice {ALICE}\n")).expect("tokens");
    let server = spawn(&dir.0, INTERVAL).await;
    let (alice, _) = clients(&server).await;
    // At rest without gravity: short steps, never a fault.
    let scene = format!("gravity = [0.0, 0.0, 0.0]\n{}", small_solid_scene());
    let id = within("create", alice.create_session_toml(&scene))
        .await
        .expect("created")
        .id;
    let began = within("step", alice.step(&id, 3))
        .await
        .expect("stepped")
        .status
        .expect("a status")
        .step;
    let step = tokio::spawn({
        let (alice, id) = (alice.clone(), id.clone());
        async move { alice.step(&id, 1_000_000).await }
    });
    let file = dir.0.join("checkpoints").join(format!("{id}.snapshot"));
    let checkpointed = within("a checkpoint inside the Step", async {
        let mut ticks = tokio::time::interval(Duration::from_millis(20));
        loop {
            ticks.tick().await;
            if let Some(step) = checkpoint_step(&file).filter(|&s| s > began) {
                return step;
            }
        }
    })
    .await;
    assert!(!step.is_finished(), "written while the Step is in progress");
    server.kill().await.expect("killed");
    let _ = step.await;

    let server = spawn(&dir.0, INTERVAL).await;
    let (alice, _) = clients(&server).await;
    let restored = status(&alice, &id).await;
    println!(
        "Step began at {began}, checkpointed at {checkpointed}, restored at {}",
        restored.step
    );
    assert!(
        restored.step >= checkpointed,
        "the last checkpoint, written at or after step {checkpointed}"
    );
    assert_eq!(
        restored.state,
        v1::SessionState::Paused as i32,
        "{}",
        restored.reason
    );
    assert!(
        restored
            .reason
            .contains("stepping when the snapshot was taken"),
        "{}",
        restored.reason
    );
    let on = within("step", alice.step(&id, 1)).await.expect("steps on");
    assert_eq!(on.status.expect("a status").step, restored.step + 1);
}

/// The value of counter `name` on the server's metrics endpoint.
async fn counter(url: &str, name: &str) -> f64 {
    let (url, name) = (url.to_owned(), name.to_owned());
    within(
        "a scrape",
        tokio::task::spawn_blocking(move || {
            let text = ureq::get(&url)
                .call()
                .expect("the endpoint answers")
                .body_mut()
                .read_to_string()
                .expect("text");
            text.lines()
                .find_map(|l| l.strip_prefix(&format!("{name} ")))
                .and_then(|v| v.trim().parse().ok())
                .unwrap_or_else(|| panic!("no {name} in\n{text}"))
        }),
    )
    .await
    .expect("scraped")
}

/// Polls `done` every 20 ms until it holds.
async fn until(what: &str, mut done: impl FnMut() -> bool) {
    within(what, async {
        let mut ticks = tokio::time::interval(Duration::from_millis(20));
        while !done() {
            ticks.tick().await;
        }
    })
    .await;
}

/// A full disk, for real: the session's temporary file is a link to
/// `/dev/full`, whose every write fails with "no space left on device".
/// The failed checkpoint removes its temporary file (once a leftover that
/// made every later write fail), counts in
/// `meshless_checkpoint_failures_total`, leaves the other session's
/// checkpoint to be written, and the next round writes it.
#[tokio::test]
async fn a_checkpoint_that_does_not_fit_is_cleaned_up_and_written_once_it_fits() {
    if !Path::new("/dev/full").exists() {
        eprintln!("skipped: this host has no /dev/full");
        return;
    }
    let dir = TempDir::new("checkpoints-full");
    std::fs::write(dir.0.join("tokens"), format!("alice {ALICE}\n")).expect("tokens");
    let checkpoints = dir.0.join("checkpoints");
    let server = ServerProcess::spawn(&[
        "--tokens-file",
        dir.0.join("tokens").to_str().expect("utf-8"),
        "--checkpoint-dir",
        checkpoints.to_str().expect("utf-8"),
        "--checkpoint-interval",
        &INTERVAL.to_string(),
        "--metrics-addr",
        "127.0.0.1:0",
    ])
    .await
    .expect("server");
    let metrics = server.metrics_url.clone().expect("metrics");
    let alice = server.client_as(&as_token(ALICE)).await.expect("alice");
    let mut ids = Vec::new();
    for _ in 0..2 {
        let id = within("create", alice.create_session_toml(&small_scene()))
            .await
            .expect("created")
            .id;
        ids.push(id);
    }
    let file = |id: &str, extension: &str| checkpoints.join(format!("{id}.{extension}"));
    until("both checkpoints", || {
        ids.iter().all(|id| file(id, "snapshot").exists())
    })
    .await;
    let (full, fits) = (&ids[0], &ids[1]);
    let (full_before, fits_before) = (
        std::fs::read(file(full, "snapshot")).expect("read"),
        std::fs::read(file(fits, "snapshot")).expect("read"),
    );
    std::os::unix::fs::symlink("/dev/full", file(full, "tmp")).expect("link");
    for id in &ids {
        within("step", alice.step(id, 1)).await.expect("stepped");
    }
    // The other session is written in spite of it, and the full one
    // once its temporary file is gone (a leftover once failed it for
    // good); the failure was counted.
    until("the other checkpoint", || {
        std::fs::read(file(fits, "snapshot")).is_ok_and(|d| d != fits_before)
    })
    .await;
    until("the checkpoint that did not fit, written", || {
        std::fs::read(file(full, "snapshot")).is_ok_and(|d| d != full_before)
    })
    .await;
    let failures = counter(&metrics, "meshless_checkpoint_failures_total").await;
    assert!(failures >= 1.0, "{failures} checkpoint failures counted");
    assert!(
        std::fs::symlink_metadata(file(full, "tmp")).is_err(),
        "the temporary file outlived the failure"
    );
    server.terminate().await.expect("stopped");
}

/// A checkpoint directory holding a link to `/dev/zero` (once read to the
/// end of memory) and a FIFO (once waited on for ever) under checkpoint
/// names: the server starts promptly, restores the good checkpoint and
/// puts the other two aside.
#[tokio::test]
async fn a_device_link_and_a_fifo_never_hold_up_a_start() {
    let dir = TempDir::new("checkpoints-special");
    std::fs::write(dir.0.join("tokens"), format!("alice {ALICE}\n")).expect("tokens");
    let checkpoints = dir.0.join("checkpoints");
    let server = spawn(&dir.0, 3600.0).await;
    let alice = server.client_as(&as_token(ALICE)).await.expect("alice");
    let id = within("create", alice.create_session_toml(&small_scene()))
        .await
        .expect("created")
        .id;
    within("step", alice.step(&id, 2)).await.expect("stepped");
    server.terminate().await.expect("stopped: a last round");
    assert!(checkpoints.join(format!("{id}.snapshot")).exists());
    std::os::unix::fs::symlink("/dev/zero", checkpoints.join("0000000000000000.snapshot"))
        .expect("link");
    make_fifo(&checkpoints.join("1111111111111111.snapshot"));

    let server = spawn(&dir.0, 3600.0).await;
    let alice = server.client_as(&as_token(ALICE)).await.expect("alice");
    assert_eq!(status(&alice, &id).await.step, 2, "the good checkpoint");
    let sessions = within("list", alice.list_sessions()).await.expect("listed");
    assert_eq!(sessions.len(), 1, "only the good checkpoint is a session");
    for name in ["0000000000000000", "1111111111111111"] {
        assert!(
            std::fs::symlink_metadata(checkpoints.join(format!("{name}.rejected"))).is_ok(),
            "{name} was not put aside"
        );
    }
    server.terminate().await.expect("stopped");
}
