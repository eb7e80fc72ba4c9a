//! Outages a stranger could cause without a single valid call (issue
//! 29): connections that hold every place under `--max-connections`,
//! streams and unread answers that pile up in memory on one connection,
//! and half-sent requests to the metrics port that use up the process's
//! file descriptors. Each test runs the real server with small limits
//! and checks that a token holder is still served.
//!
//! New settings are passed as environment variables, which an older
//! server ignores, so each test also runs unchanged against the server
//! before the fix (where each fails).

use meshless_client::Identity;
use meshless_client::v1;
use meshless_tests::raw_h2::{Answers, RawH2};
use meshless_tests::{Launch, ServerProcess, TempDir, resident_bytes, small_scene, within};
use std::time::Duration;
use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;

const ALICE: &str = "alice-token-0123456789";

/// A tokens file for alice in `dir`.
fn tokens(dir: &TempDir) -> String {
    let path = dir.0.join("tokens");
    std::fs::write(&path, format!("alice {ALICE}\n")).expect("tokens");
    path.to_str().expect("utf-8").to_owned()
}

fn alice() -> Identity {
    Identity {
        token: Some(ALICE.into()),
        client_id: None,
        take_over: false,
    }
}

/// `host:port` of a server's gRPC endpoint.
fn grpc_addr(server: &ServerProcess) -> String {
    server
        .grpc_url
        .strip_prefix("http://")
        .expect("http")
        .to_owned()
}

/// Polls `answers` until `done` holds, failing with `what` and what was
/// answered after the harness's timeout.
async fn wait_for(what: &str, connection: &RawH2, done: impl Fn(&Answers) -> bool) -> Answers {
    wait_longer(what, connection, meshless_tests::TIMEOUT, done).await
}

/// [`wait_for`] with a timeout of `patience`.
async fn wait_longer(
    what: &str,
    connection: &RawH2,
    patience: Duration,
    done: impl Fn(&Answers) -> bool,
) -> Answers {
    let deadline = tokio::time::Instant::now() + patience;
    loop {
        let answers = connection.answers();
        if done(&answers) {
            return answers;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "timed out waiting for {what}: {} streams answered, {} ended, {} opened, {} \
             refused, {} reset, closed {}",
            answers.answered(),
            answers.ended,
            answers.opened,
            answers.refused,
            answers.reset,
            answers.closed
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Sockets that send one byte, sockets that send the HTTP/2 preface, and
/// tonic channels that connect and only answer pings each held a place
/// for ever: four of any kind locked every client out of a server with
/// `--max-connections 4`. A place is now earned by a call that passes
/// the token check within `--handshake-timeout`, so alice's call is
/// served while twelve strangers keep trying.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn strangers_cannot_hold_every_connection_place() {
    let dir = TempDir::new("outage-places");
    let tokens = tokens(&dir);
    let server = ServerProcess::spawn_launched(
        &["--tokens-file", &tokens, "--max-connections", "4"],
        &Launch {
            env: &[("MESHLESS_HANDSHAKE_TIMEOUT", "1")],
            ..Launch::default()
        },
    )
    .await
    .expect("server starts");
    let addr = grpc_addr(&server);
    let mut strangers = Vec::new();
    let mut channels = Vec::new();
    for _ in 0..4 {
        let endpoint = tonic::transport::Endpoint::from_shared(server.grpc_url.clone())
            .expect("url")
            .http2_keep_alive_interval(Duration::from_millis(200))
            .keep_alive_while_idle(true);
        channels.push(
            within("an idle channel", endpoint.connect())
                .await
                .expect("connects"),
        );
    }
    for prefix in [&b"P"[..], b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n"] {
        for _ in 0..4 {
            let mut socket = within("connect", TcpStream::connect(&addr))
                .await
                .expect("the kernel's backlog takes it");
            within("a prefix", socket.write_all(prefix))
                .await
                .expect("sent");
            strangers.push(socket);
        }
    }
    let client = server.client_as(&alice()).await.expect("connects");
    let info = within("alice's call past twelve strangers", client.server_info())
        .await
        .expect("served");
    assert!(!info.version.is_empty());
    drop((strangers, channels));
}

/// An earned place is kept only while it is used: alice's connection
/// with no call in flight for `--idle-timeout` is closed, so with one
/// place a second client is served, and alice's next call reconnects.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_idle_connection_gives_up_its_place() {
    let dir = TempDir::new("outage-idle");
    let tokens = tokens(&dir);
    let server = ServerProcess::spawn_launched(
        &["--tokens-file", &tokens, "--max-connections", "1"],
        &Launch {
            env: &[("MESHLESS_IDLE_TIMEOUT", "1")],
            ..Launch::default()
        },
    )
    .await
    .expect("server starts");
    let first = server.client_as(&alice()).await.expect("connects");
    within("first call", first.server_info())
        .await
        .expect("served");
    let second = server.client_as(&alice()).await.expect("connects");
    within("second client's call", second.list_sessions())
        .await
        .expect("served once the first idles");
    drop(second);
    within("the first reconnects", first.server_info())
        .await
        .expect("served again");
}

/// No limit on streams was in effect: one connection opened 20,000.
/// Past the bound, new streams are refused (REFUSED_STREAM) while those
/// open stay open.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn streams_past_the_bound_are_refused() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let mut connection = within("raw connect", RawH2::connect(&grpc_addr(&server), 65_535))
        .await
        .expect("connects");
    // Requests left open: each stream stays open, waiting for its body.
    let streams = 300;
    for _ in 0..streams {
        within(
            "open a stream",
            connection.call("/grpc.health.v1.Health/Check", &[], None),
        )
        .await
        .expect("sent");
    }
    let answers = wait_for("refusals", &connection, |a| a.refused > 0 || a.closed).await;
    assert!(
        !answers.closed,
        "the server closed the connection: {answers:?}"
    );
    // A call on a fresh connection is still served.
    let client = server.client().await.expect("connects");
    within("a call beside it", client.server_info())
        .await
        .expect("served");
    // Every stream past the first hundred, and no other, is refused.
    let answers = wait_for("every refusal", &connection, |a| a.refused >= streams - 100).await;
    assert_eq!(answers.refused, streams - 100, "{answers:?}");
}

/// A client that grants no flow-control window and asks for frames it
/// never reads made the server hold every answer (400 frames of 1 MB
/// held 473 MB). Now a connection holds at most its response budget of
/// unread answers; the rest are refused with RESOURCE_EXHAUSTED at once.
/// With 4 MB frames, forty calls (fewer than the streams one connection
/// may open) would hold 160 MB without the budget.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unread_answers_do_not_pile_up() {
    let dir = TempDir::new("outage-unread");
    let tokens = tokens(&dir);
    let server = ServerProcess::spawn(&["--tokens-file", &tokens])
        .await
        .expect("server starts");
    let pid = server.pid().expect("running");
    let client = server.client_as(&alice()).await.expect("connects");
    // 146,000 particles, stepped once in one short sub-step.
    let scene = small_scene()
        .replacen("spacing = 0.04", "spacing = 0.0038", 1)
        .replacen("dt = 0.01", "dt = 0.00002", 1);
    let session = within("create a big tank", client.create_session_toml(&scene))
        .await
        .expect("created");
    within("step", client.step(&session.id, 1))
        .await
        .expect("steps");
    let frame = within("a frame", client.latest_frame(&session.id))
        .await
        .expect("a frame");
    assert!(
        frame.particle_count >= 120_000,
        "{} particles: the frame is not about 4 MB",
        frame.particle_count
    );
    let before = resident_bytes(pid);

    let mut connection = within("raw connect", RawH2::connect(&grpc_addr(&server), 0))
        .await
        .expect("connects");
    let request = prost::Message::encode_to_vec(&v1::SessionRef {
        session_id: session.id.clone(),
    });
    let bearer = format!("Bearer {ALICE}");
    let calls = 40;
    for _ in 0..calls {
        within(
            "ask for a frame",
            connection.call(
                "/meshless.v1.Simulation/GetLatestFrame",
                &[("authorization", &bearer)],
                Some(&request),
            ),
        )
        .await
        .expect("sent");
    }
    // Each answer encodes 4 MB in a debug build: slow on a loaded host.
    let patience = Duration::from_secs(300);
    let answers = wait_longer("an answer to every call", &connection, patience, |a| {
        a.answered() >= calls || a.closed
    })
    .await;
    let grown = resident_bytes(pid).saturating_sub(before);
    println!(
        "{} of {calls} answers held, {} refused; the server grew by {} MB",
        answers.opened,
        answers.ended,
        grown >> 20
    );
    assert_eq!(answers.data_bytes, 0, "a zero window was overrun");
    // Positions, velocities and densities take at least 28 bytes a
    // particle: at most this many answers fit the 64 MB budget.
    let fit = (64 << 20) / (frame.particle_count * 28) + 1;
    assert!(
        answers.opened <= fit && answers.ended + answers.opened == calls,
        "{} answers held unread on one connection, {} refused; at most {fit} fit its budget",
        answers.opened,
        answers.ended
    );
    // Freed answers may stay in the allocator's arenas: a loose bound.
    assert!(
        grown < 512 << 20,
        "the server holds {} MB more for {calls} unread answers",
        grown >> 20
    );
    // Alice, on her own connection, is still served.
    within("a frame beside it", client.latest_frame(&session.id))
        .await
        .expect("served");
}

/// Half-sent requests to the metrics port held a file descriptor each
/// until the process had none left, and gRPC could accept nothing. The
/// endpoint now serves at most a few connections at once and closes one
/// whose headers are late, so gRPC and a full scrape still answer.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn half_sent_metrics_requests_starve_nothing() {
    let server = ServerProcess::spawn_launched(
        &["--metrics-addr", "127.0.0.1:0"],
        &Launch {
            env: &[("MESHLESS_METRICS_HEADER_TIMEOUT", "0.3")],
            fd_limit: Some(256),
            ..Launch::default()
        },
    )
    .await
    .expect("server starts");
    let url = server.metrics_url.clone().expect("metrics");
    let addr = url
        .strip_prefix("http://")
        .and_then(|rest| rest.strip_suffix("/metrics"))
        .expect("http://ADDR/metrics")
        .to_owned();
    let mut half_sent = Vec::new();
    for _ in 0..300 {
        let mut socket = within("connect", TcpStream::connect(&addr))
            .await
            .expect("the kernel's backlog takes it");
        within(
            "half a request",
            socket.write_all(b"GET /metrics HTTP/1.1\r\nHost: x\r\n"),
        )
        .await
        .expect("sent");
        half_sent.push(socket);
    }
    let client = server.client().await.expect("connects");
    within("a gRPC call beside them", client.server_info())
        .await
        .expect("served");
    let scraped = within(
        "a full scrape behind them",
        tokio::task::spawn_blocking(move || {
            ureq::get(&url)
                .call()
                .and_then(|mut r| r.body_mut().read_to_string())
        }),
    )
    .await
    .expect("the scrape ran")
    .expect("the endpoint answers");
    assert!(scraped.contains("meshless_"), "{scraped:.300}");
    drop(half_sent);
}
