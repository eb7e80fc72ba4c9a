//! Long steps over the real service: a step that would run for a minute
//! (a large `time.dt` in tens of thousands of sub-steps) is stopped within
//! a few seconds by Pause, by a `Step` call the client gives up on, by
//! DeleteSession and by SIGTERM; the session keeps its last completed
//! step and steps on from it. A long stepping call (a million short
//! steps) answers a snapshot between two of its steps; stepping calls
//! sent together take their own steps one after the other; and the step
//! counter never wraps.

use meshless_client::{Client, ClientError, v1};
use meshless_engine::{BuildOptions, Scene};
use meshless_tests::{ServerProcess, rpc_status, small_solid_scene, within};
use std::future::Future;
use std::time::{Duration, Instant};
use tokio_stream::{Stream, StreamExt};
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

/// The small column floating at rest (no gravity): its steps are short
/// and it never faults, so a `Step(1_000_000)` of it is in progress for
/// as long as a test looks.
fn resting_column() -> String {
    format!("gravity = [0.0, 0.0, 0.0]\n{}", small_solid_scene())
}

/// Most steps one `Step` call may take: longer than any test here.
const LONG: u64 = 1_000_000;

/// Polls `session` until it has taken more than `step` steps.
async fn past_step(client: &Client, id: &str, step: u64) -> v1::SessionStatus {
    within("the session to step on", async {
        let mut ticks = tokio::time::interval(Duration::from_millis(20));
        loop {
            ticks.tick().await;
            let session = client.get_session(id).await.expect("the session");
            let status = session.status.expect("a status");
            if status.step > step {
                return status;
            }
        }
    })
    .await
}

/// A call refused with `code`, whose message says `says`.
fn assert_refused<T: std::fmt::Debug>(
    result: Result<T, ClientError>,
    code: Code,
    says: &str,
) -> String {
    let status = rpc_status(result.expect_err("refused"));
    assert_eq!(status.code(), code, "{}", status.message());
    assert!(
        status.message().contains(says),
        "{:?} does not say {says:?}",
        status.message()
    );
    status.message().to_owned()
}

/// A long `Step` is not a wall: between two of its steps the session
/// answers `Snapshot` with the step reached (held as paused there, as the
/// call would leave it), and refuses a `Restore` into it at once, naming
/// the call and how far it is, instead of making either wait for a million
/// steps.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_snapshot_answers_between_the_steps_of_a_long_step() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let id = within("create", client.create_session_toml(&resting_column()))
        .await
        .expect("created")
        .id;
    let step = tokio::spawn({
        let (client, id) = (client.clone(), id.clone());
        async move { client.step(&id, LONG).await }
    });
    past_step(&client, &id, 0).await;

    let snapshot = promptly("Snapshot during a Step", client.snapshot(&id))
        .await
        .expect("a snapshot");
    assert!(snapshot.step > 0, "taken after a step of the call");
    assert!(!step.is_finished(), "the Step is still in progress");
    let refused = promptly(
        "Restore into a session inside a Step",
        client.restore(snapshot.data.clone(), Some(&id), None),
    )
    .await;
    let message = assert_refused(
        refused,
        Code::FailedPrecondition,
        "stepping for another call",
    );
    assert!(
        message.contains(&format!("Step of {LONG} steps")),
        "{message}"
    );

    // The snapshot holds the session paused at the step it was taken.
    let copy = within("restore", client.restore(snapshot.data, None, None))
        .await
        .expect("restored");
    let copied = status(&copy);
    assert_eq!(copied.step, snapshot.step);
    assert_eq!(
        copied.state,
        v1::SessionState::Paused as i32,
        "{}",
        copied.reason
    );

    promptly("Pause", client.pause(&id)).await.expect("paused");
    let stepped = promptly("the interrupted Step", step)
        .await
        .expect("the task ran")
        .expect("answered");
    assert!(status(&stepped).step >= snapshot.step);
    assert!(
        status(&stepped).reason.contains("interrupted after"),
        "{}",
        status(&stepped).reason
    );
}

/// Whether `stream` has an item ready now, without waiting for one.
async fn ready<S: Stream + Unpin>(stream: &mut S) -> bool {
    tokio::time::timeout(Duration::ZERO, stream.next())
        .await
        .is_ok()
}

/// Reads `SimulateSteps` progress from `stream` until the call has taken
/// `steps` steps, checking `idle` (another call's) after each message.
async fn progress_until<S>(
    stream: &mut S,
    steps: u64,
    mut idle: impl FnMut(),
) -> v1::SimulateProgress
where
    S: Stream<Item = Result<v1::SimulateProgress, ClientError>> + Unpin,
{
    within("progress", async {
        loop {
            let progress = stream
                .next()
                .await
                .expect("the call goes on")
                .expect("progress");
            idle();
            if progress.steps_done >= steps {
                return progress;
            }
        }
    })
    .await
}

/// The step at which the session, created idle, was first paused: where
/// the first stepping call on it ended, by its status events.
async fn first_pause<S>(events: &mut S) -> u64
where
    S: Stream<Item = Result<v1::SessionStatus, ClientError>> + Unpin,
{
    within("the first pause", async {
        loop {
            let status = events.next().await.expect("events").expect("a status");
            if status.state == v1::SessionState::Paused as i32 {
                return status.step;
            }
        }
    })
    .await
}

/// Steps the other call could have taken meanwhile, had it slipped in
/// between the first call's steps: many of its chunks' worth.
const WINDOW: u64 = 2_000;

/// A resting column's session, its status events watched, with a long
/// `SimulateSteps` (0.02 s progress) that has taken its first step: what
/// a second stepping call meets. Returns the id, the events, the call's
/// progress stream and its first progress.
async fn simulating(
    client: &Client,
) -> (
    String,
    impl Stream<Item = Result<v1::SessionStatus, ClientError>> + Unpin,
    impl Stream<Item = Result<v1::SimulateProgress, ClientError>> + Unpin,
    v1::SimulateProgress,
) {
    let id = within("create", client.create_session_toml(&resting_column()))
        .await
        .expect("created")
        .id;
    let events = within("watch", client.watch_status(&id))
        .await
        .expect("watching");
    let mut simulate = within("simulate", client.simulate_steps(&id, 100_000_000, 0.02))
        .await
        .expect("a stream");
    let began = progress_until(&mut simulate, 1, || {}).await;
    (id, events, simulate, began)
}

/// A `Step` sent while a `SimulateSteps` is in progress waits for it and
/// then takes its own 500 steps; it never slips in between (the
/// `SimulateSteps` would then end early, counting the `Step`'s steps as
/// its own). `Step` and `SimulateSteps` during a run are refused.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_step_sent_during_simulate_steps_takes_its_own_steps_after_it() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let (id, mut events, mut simulate, sent_at) = simulating(&client).await;
    let step = tokio::spawn({
        let (client, id) = (client.clone(), id.clone());
        async move { client.step(&id, 500).await }
    });
    let seen = progress_until(&mut simulate, sent_at.steps_done + WINDOW, || {
        assert!(!step.is_finished(), "the Step slipped in between");
    })
    .await;
    let seen_step = seen.status.expect("a status").step;
    assert_eq!(seen_step, seen.steps_done, "the call counts its own steps");
    // Cancelled: its steps end, and the Step's begin.
    drop(simulate);
    let stepped = within("the Step", step)
        .await
        .expect("the task ran")
        .expect("stepped");
    let ended = first_pause(&mut events).await;
    assert!(ended >= seen_step);
    assert_eq!(
        status(&stepped).step,
        ended + 500,
        "the Step's own 500 steps, after the SimulateSteps ended at {ended}"
    );

    // While running, both are refused.
    within("run", client.run_forever(&id, None))
        .await
        .expect("runs");
    let refused = within("step", client.step(&id, 1)).await;
    assert_refused(refused, Code::FailedPrecondition, "pause it first");
    let refused = within("simulate", simulate_error(&client, &id, 5)).await;
    assert_refused(refused, Code::FailedPrecondition, "pause it first");
}

/// The error a `SimulateSteps` call ends with, at the call or on its stream.
async fn simulate_error(client: &Client, id: &str, steps: u64) -> Result<(), ClientError> {
    let mut stream = client.simulate_steps(id, steps, 0.0).await?;
    while let Some(item) = stream.next().await {
        item?;
    }
    Ok(())
}

/// A second `SimulateSteps` waits for the first: no progress message
/// until its own steps begin, then it reports its own 40 steps, not the
/// session's.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn simulate_steps_during_simulate_steps_counts_its_own_steps_after_it() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let (id, mut events, mut first, sent_at) = simulating(&client).await;
    let mut second = within("simulate", client.simulate_steps(&id, 40, 0.01))
        .await
        .expect("a stream");
    progress_until(&mut first, sent_at.steps_done + WINDOW, || {}).await;
    // A message sent meanwhile would be waiting in the stream.
    assert!(
        !ready(&mut second).await,
        "the second call reported before its steps began"
    );
    drop(first);

    let mut messages = Vec::new();
    while let Some(progress) = within("progress", second.next()).await {
        messages.push(progress.expect("progress"));
    }
    let ended = first_pause(&mut events).await;
    let last = messages.last().expect("messages");
    assert!(last.done, "{last:?}");
    assert_eq!(last.steps_done, 40, "its own steps");
    assert_eq!(
        last.status.as_ref().expect("a status").step,
        ended + 40,
        "after the first call ended at {ended}"
    );
    for progress in &messages {
        let step = progress.status.as_ref().expect("a status").step;
        assert_eq!(step, ended + progress.steps_done, "{progress:?}");
    }
}

/// A snapshot forged to sit at `step` (with its checksum made again):
/// only a snapshot can put a session near the end of the step counter.
fn at_step(data: &[u8], step: u64) -> Vec<u8> {
    let mut payload =
        meshless_proto::snapshot::decode(data, usize::MAX).expect("a snapshot of this build");
    payload.world.as_mut().expect("a world").step = step;
    meshless_proto::snapshot::encode(&payload)
}

/// The step counter never wraps. At step 2^64 - 2 one step is left: a
/// `Step(2)` or `SimulateSteps(2)` is refused with the count left and
/// changes nothing; `Step(1)` takes it; every step after is refused, the
/// session unchanged (not faulted, not back at step 0). A run from there
/// stops, paused, at the last step; a restored step of 2^64 - 1 is either
/// refused or never stepped.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_step_counter_never_wraps() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let id = within("create", client.create_session_toml(&resting_column()))
        .await
        .expect("created")
        .id;
    within("step", client.step(&id, 2)).await.expect("stepped");
    let data = within("snapshot", client.snapshot(&id))
        .await
        .expect("a snapshot")
        .data;
    let near = at_step(&data, u64::MAX - 1);

    let id = within("restore", client.restore(near.clone(), None, None))
        .await
        .expect("restored")
        .id;
    let before = status(
        &within("get", client.get_session(&id))
            .await
            .expect("session"),
    )
    .clone();
    assert_eq!(before.step, u64::MAX - 1);
    let refused = within("Step(2)", client.step(&id, 2)).await;
    let message = assert_refused(refused, Code::FailedPrecondition, "never wraps");
    assert!(message.contains("at most 1 steps"), "{message}");
    let refused = within("SimulateSteps(2)", simulate_error(&client, &id, 2)).await;
    assert_refused(refused, Code::FailedPrecondition, "never wraps");
    let unchanged = status(
        &within("get", client.get_session(&id))
            .await
            .expect("session"),
    )
    .clone();
    assert_eq!(
        (unchanged.step, unchanged.state, &unchanged.reason),
        (before.step, before.state, &before.reason),
        "a refused step changes nothing"
    );

    let last = within("Step(1)", client.step(&id, 1))
        .await
        .expect("stepped");
    assert_eq!(status(&last).step, u64::MAX);
    let refused = within("Step(1)", client.step(&id, 1)).await;
    assert_refused(refused, Code::FailedPrecondition, "never wraps");
    let refused = within("Run", client.run_forever(&id, None)).await;
    assert_refused(refused, Code::FailedPrecondition, "never wraps");
    let after = status(
        &within("get", client.get_session(&id))
            .await
            .expect("session"),
    )
    .clone();
    assert_eq!(after.step, u64::MAX);
    assert_eq!(
        after.state,
        v1::SessionState::Paused as i32,
        "{}",
        after.reason
    );
    let frame = within("frame", client.latest_frame(&id))
        .await
        .expect("frame");
    assert_eq!(frame.step, u64::MAX, "the last frame is the last step's");

    // A run from one step before the end stops there, paused.
    let running = within("restore", client.restore(near, None, None))
        .await
        .expect("restored")
        .id;
    within("run", client.run_forever(&running, None))
        .await
        .expect("runs");
    let stopped = within("the run to stop", async {
        let mut ticks = tokio::time::interval(Duration::from_millis(20));
        loop {
            ticks.tick().await;
            let session = client.get_session(&running).await.expect("the session");
            let status = session.status.expect("a status");
            if status.state != v1::SessionState::Running as i32 {
                return status;
            }
        }
    })
    .await;
    assert_eq!(stopped.step, u64::MAX);
    assert_eq!(
        stopped.state,
        v1::SessionState::Paused as i32,
        "{}",
        stopped.reason
    );
    assert!(stopped.reason.contains("never wraps"), "{}", stopped.reason);

    // At the very end: refused at the restore (as a state no session
    // reaches by stepping) or at the first step, never wrapped.
    match within(
        "restore",
        client.restore(at_step(&data, u64::MAX), None, None),
    )
    .await
    {
        Ok(session) => {
            let refused = within("Step(1)", client.step(&session.id, 1)).await;
            assert_refused(refused, Code::FailedPrecondition, "never wraps");
        }
        Err(e) => assert_eq!(e.code(), Some(Code::InvalidArgument), "{e}"),
    }
}
