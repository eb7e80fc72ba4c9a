//! Long steps over the real service: a step that would run for a minute
//! (a large `time.dt` in tens of thousands of sub-steps) is stopped within
//! a few seconds by Pause, by a `Step` call the client gives up on, by
//! DeleteSession and by SIGTERM; the session keeps its last completed
//! step and steps on from it.

use meshless_client::{Client, v1};
use meshless_engine::{BuildOptions, Scene};
use meshless_tests::{ServerProcess, within};
use std::future::Future;
use std::time::{Duration, Instant};
use tonic::Code;

/// Longest any of them may take while a step is in progress: a bound on
/// the interruption, where the step itself runs for a minute or more.
const PROMPT: Duration = Duration::from_secs(5);

async fn promptly<T>(what: &str, future: impl Future<Output = T>) -> T {
    let started = Instant::now();
    let value = within(what, future).await;
    let took = started.elapsed();
    println!("{what}: {took:?}");
    assert!(took < PROMPT, "{what} took {took:?} during a long step");
    value
}

/// A 2D tank of 900 particles whose one step takes about 50 000
/// sub-steps, as TOML. The sub-step length comes from a short probe step
/// on the engine here.
fn long_step_scene() -> String {
    let scene = |dt: f64| {
        format!(
            r#"
            dimension = 2
            [domain]
            min = [0.0, 0.0, 0.0]
            max = [1.0, 1.0, 0.0]
            [time]
            dt = {dt:e}
            max_substeps = 1000000
            cfl = 0.2
            [[systems]]
            kind = "fluid"
            spacing = 0.02
            stiffness = 1000.0
            [[systems.blocks]]
            region = {{ min = [0.0, 0.0, 0.0], max = [0.6, 0.6, 0.0] }}
            "#
        )
    };
    let probe_dt = 0.01;
    let mut probe = Scene::from_toml_str(&scene(probe_dt))
        .expect("the tank parses")
        .build(&BuildOptions::default())
        .expect("a valid tank");
    let substeps = probe.step().expect("a stable probe step").substeps;
    scene(50_000.0 * probe_dt / f64::from(substeps))
}

fn status(session: &v1::Session) -> &v1::SessionStatus {
    session.status.as_ref().expect("a status")
}

async fn create_running(client: &Client, scene: &str) -> String {
    let session = within("create", client.create_session_toml(scene))
        .await
        .expect("created");
    let running = within("run", client.run_forever(&session.id, None))
        .await
        .expect("runs");
    assert_eq!(status(&running).state, v1::SessionState::Running as i32);
    session.id
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pause_a_dropped_step_and_delete_stop_a_long_step_promptly() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let id = create_running(&client, &long_step_scene()).await;

    // The run is inside its first step: Pause stops it there.
    let paused = promptly("Pause", client.pause(&id)).await.expect("paused");
    assert_eq!(status(&paused).state, v1::SessionState::Paused as i32);
    assert_eq!(status(&paused).step, 0, "the last completed step is kept");

    // A Step the client gives up on (its call dropped, as a deadline
    // does) stops too: the next command is answered promptly.
    let gave_up = tokio::time::timeout(Duration::from_millis(500), client.step(&id, 1)).await;
    assert!(
        gave_up.is_err(),
        "the step cannot have finished: {gave_up:?}"
    );
    let running = promptly("Run after a dropped Step", client.run_forever(&id, None))
        .await
        .expect("runs again");
    assert_eq!(status(&running).state, v1::SessionState::Running as i32);
    assert_eq!(status(&running).step, 0, "from the same step");

    // Deleting the running session stops its step and its thread.
    promptly("DeleteSession", client.delete_session(&id))
        .await
        .expect("deleted");
    let gone = within("get", client.get_session(&id))
        .await
        .expect_err("gone");
    assert_eq!(gone.code(), Some(Code::NotFound), "{gone}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_stops_a_long_step_promptly() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    create_running(&client, &long_step_scene()).await;
    let exit = promptly("SIGTERM", server.terminate())
        .await
        .expect("the server exits");
    assert!(exit.success(), "{exit:?}");
}
