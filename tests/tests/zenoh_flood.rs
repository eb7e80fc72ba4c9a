//! The server's zenoh port under a flood of silent connections, end to
//! end: raw TCP sockets connect to the port the real server listens on
//! and never send a byte, as a port scan, a health check that only
//! connects or a hostile client does. zenoh holds each such link in its
//! handshake until `accept_timeout` and closes every link beyond
//! `accept_pending` at once, so at zenoh's defaults (100 links, 10 s)
//! 300 silent sockets refused every new subscriber for 10 s at a time.
//! The server sets both itself (`--zenoh-accept-pending`,
//! `--zenoh-accept-timeout-ms`; docs/operations.md, "Zenoh limits").
//!
//! A new connection waits in the kernel's accept queue behind the
//! flood's, which is first come first served, so by the time the server
//! takes up the subscriber's link it has taken up all of the flood's.

use meshless_client::ZenohLink;
use meshless_tests::{ServerProcess, small_scene, within};
use tokio::net::TcpStream;

/// Silent connections in the flood: three times zenoh's own limit of
/// pending links, and under the server's default.
const FLOOD: usize = 300;

/// `FLOOD` TCP connections to the server's zenoh port that send nothing;
/// they stay open while the returned sockets live.
async fn silent_flood(server: &ServerProcess) -> Vec<TcpStream> {
    let endpoint = server.zenoh.first().expect("a zenoh endpoint");
    let addr = endpoint
        .strip_prefix("tcp/")
        .unwrap_or_else(|| panic!("{endpoint} is a tcp/ endpoint"))
        .to_owned();
    let mut sockets = Vec::with_capacity(FLOOD);
    for i in 0..FLOOD {
        let socket = within("a silent connection", TcpStream::connect(&addr))
            .await
            .unwrap_or_else(|e| panic!("connection {i} to {addr}: {e}"));
        sockets.push(socket);
    }
    sockets
}

/// At the server's defaults, a subscriber that connects while 300 silent
/// connections are open gets in, subscribes and receives the frames of
/// the next steps.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn silent_connections_do_not_keep_a_subscriber_out() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let session = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("session");
    let id = session.id.as_str();
    let flood = silent_flood(&server).await;

    let link = within("zenoh connect", ZenohLink::connect(&server.zenoh))
        .await
        .expect("the subscriber connects through the flood");
    let frames = within("subscribe", link.frames(id)).await.expect("frames");
    within("step", client.step(id, 2)).await.expect("steps");
    for step in 1..=2 {
        let frame = within(&format!("frame of step {step}"), frames.recv())
            .await
            .expect("a frame");
        assert_eq!((frame.session_id.as_str(), frame.step), (id, step));
    }
    link.close().await;
    drop(flood);
}

/// The same flood against a server set to zenoh's own limit of 100
/// pending links (and a timeout far beyond the test) refuses the
/// subscriber: the flood is what the test above survives, and the
/// setting reaches zenoh.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn zenohs_own_pending_limit_refuses_a_subscriber_behind_the_flood() {
    let server = ServerProcess::spawn(&[
        "--zenoh-accept-pending",
        "100",
        "--zenoh-accept-timeout-ms",
        "600000",
    ])
    .await
    .expect("server starts");
    let flood = silent_flood(&server).await;
    let refused = within("zenoh connect", ZenohLink::connect(&server.zenoh)).await;
    assert!(
        refused.is_err(),
        "with 100 pending links, the 101st connection is closed before its handshake"
    );
    drop(flood);
}
