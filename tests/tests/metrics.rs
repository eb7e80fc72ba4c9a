//! The Prometheus endpoint of the real `meshless-server` binary, scraped
//! with a real HTTP client: the counters move with the work done (steps,
//! sub-steps, stage time, frames, bytes, RPCs by method and code,
//! snapshots) and the gauges follow the sessions (by state, particles,
//! real-time factor) and the checkpoints.

use meshless_tests::{ServerProcess, TempDir, small_scene, within};

/// One scrape of `url`, as text.
async fn scrape(url: &str) -> String {
    let url = url.to_owned();
    within(
        "a scrape",
        tokio::task::spawn_blocking(move || {
            let mut response = ureq::get(&url).call().expect("the endpoint answers");
            assert_eq!(response.status(), 200);
            let kind = response
                .headers()
                .get("content-type")
                .and_then(|v| v.to_str().ok())
                .unwrap_or_default()
                .to_owned();
            assert!(kind.starts_with("text/plain"), "{kind}");
            response.body_mut().read_to_string().expect("text")
        }),
    )
    .await
    .expect("the scrape ran")
}

/// The value of the sample `series` (a name with its labels, as the text
/// format writes it), or 0 when absent.
fn value(text: &str, series: &str) -> f64 {
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .find_map(|l| {
            let (name, value) = l.rsplit_once(' ')?;
            (name == series).then(|| value.parse().expect("a number"))
        })
        .unwrap_or(0.0)
}

#[tokio::test]
async fn the_metrics_move_with_the_work() {
    let dir = TempDir::new("metrics");
    let checkpoints = dir.0.join("checkpoints");
    let server = ServerProcess::spawn(&[
        "--metrics-addr",
        "127.0.0.1:0",
        "--checkpoint-dir",
        checkpoints.to_str().expect("utf-8"),
        "--checkpoint-interval",
        "0.2",
    ])
    .await
    .expect("server");
    let url = server.metrics_url.clone().expect("a metrics address");
    let client = server.client().await.expect("client");
    let before = scrape(&url).await;

    let session = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("created");
    within("step", client.step(&session.id, 5))
        .await
        .expect("stepped");
    let missing = within("get", client.get_session("no-such-session")).await;
    assert!(missing.is_err());
    within("snapshot", client.snapshot(&session.id))
        .await
        .expect("a snapshot");
    let after = scrape(&url).await;

    let moved = |series: &str| value(&after, series) - value(&before, series);
    assert_eq!(moved("meshless_steps_total"), 5.0);
    assert!(moved("meshless_substeps_total") >= 5.0);
    assert!(moved("meshless_simulated_seconds_total") > 0.049);
    assert!(moved("meshless_stage_seconds_total{stage=\"density\"}") > 0.0);
    assert!(moved("meshless_step_seconds_count") >= 5.0);
    // One frame per step (`frame_every = 1`), each put on zenoh by a
    // task of its own, or dropped when that task is behind: until all are
    // counted one way or the other.
    let frames = |text: &str| {
        value(text, "meshless_frames_published_total")
            + value(text, "meshless_frames_dropped_total")
            - value(&before, "meshless_frames_published_total")
            - value(&before, "meshless_frames_dropped_total")
    };
    let counted = within("every frame counted", async {
        loop {
            let text = scrape(&url).await;
            if frames(&text) >= 5.0 {
                return text;
            }
            tokio::time::sleep(std::time::Duration::from_millis(20)).await;
        }
    })
    .await;
    assert!(value(&counted, "meshless_frames_published_total") > 0.0);
    let bytes = "meshless_zenoh_bytes_sent_total";
    assert!(value(&counted, bytes) > value(&before, bytes));
    assert_eq!(
        moved("meshless_rpcs_total{method=\"Step\",code=\"OK\"}"),
        1.0
    );
    assert_eq!(
        moved("meshless_rpcs_total{method=\"GetSession\",code=\"NOT_FOUND\"}"),
        1.0
    );
    assert_eq!(
        moved("meshless_rpc_seconds_count{method=\"CreateSession\"}"),
        1.0,
        "{after}"
    );
    assert_eq!(moved("meshless_snapshots_total"), 1.0);
    assert_eq!(value(&after, "meshless_sessions{state=\"paused\"}"), 1.0);
    assert_eq!(value(&after, "meshless_sessions{state=\"running\"}"), 0.0);
    assert_eq!(
        value(&after, "meshless_particles"),
        session.particle_count as f64
    );
    let factor = format!("meshless_realtime_factor{{session=\"{}\"}}", session.id);
    assert!(value(&after, &factor) > 0.0, "{after}");

    // The checkpoint round writes the session and reports its age.
    let checkpointed = within("a checkpoint round", async {
        loop {
            let text = scrape(&url).await;
            if text.contains("meshless_checkpoint_age_seconds ") {
                return text;
            }
            tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        }
    })
    .await;
    assert!(value(&checkpointed, "meshless_checkpoint_age_seconds") < 30.0);

    // A deleted session leaves no label behind.
    within("delete", client.delete_session(&session.id))
        .await
        .expect("deleted");
    let gone = scrape(&url).await;
    assert!(!gone.contains(&session.id), "{gone}");
    assert_eq!(value(&gone, "meshless_particles"), 0.0);
}

/// Solids, modal solids and shells report where their steps go, as fluids
/// do: a stage counter per kind moves with that kind's sessions.
#[tokio::test]
async fn every_kind_reports_its_stages() {
    let server = ServerProcess::spawn(&["--metrics-addr", "127.0.0.1:0"])
        .await
        .expect("server");
    let url = server.metrics_url.clone().expect("a metrics address");
    let client = server.client().await.expect("client");
    for scene in [
        meshless_tests::small_solid_scene(),
        meshless_tests::small_modal_scene(),
        meshless_tests::small_shell_scene(),
    ] {
        let session = within("create", client.create_session_toml(&scene))
            .await
            .expect("created");
        within("step", client.step(&session.id, 2))
            .await
            .expect("stepped");
    }
    let text = scrape(&url).await;
    for stage in [
        "solid_forces",
        "solid_integrate",
        "solid_contact",
        "modal_solve",
        "shell_solve",
    ] {
        let series = format!("meshless_stage_seconds_total{{stage=\"{stage}\"}}");
        assert!(value(&text, &series) > 0.0, "{series} did not move");
    }
    let fluid = "meshless_stage_seconds_total{stage=\"density\"}";
    assert_eq!(value(&text, fluid), 0.0, "no fluid, no fluid stage");
}
