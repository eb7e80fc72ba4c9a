//! A hostile zenoh peer against the subscribers, end to end: a second
//! zenoh session connected to the real server puts garbage, forged and
//! replayed messages on a session's keys and answers its latest-frame
//! queries, while the session is stepped.
//!
//! By default the server's zenoh access control drops all of it, so even
//! a well-formed forgery in the session's name never reaches a subscriber
//! (the last test). Behind `--zenoh-publishers any` (a network whose
//! router enforces nothing) everything reaches them, and the subscribers
//! (`Frames`, `Statuses`, `latest_frame`, `meshless watch`) hand on only
//! the server's messages and count what they drop.
//!
//! The peer's puts reach the subscriber through the server, so a query
//! the peer sends after them and sees answered means the server has
//! forwarded them; the steps that follow publish behind them.

use meshless_client::{Frames, ZenohLink, v1};
use meshless_tests::{ServerProcess, binary, small_scene, within};
use prost::Message;
use std::future::IntoFuture;
use std::process::Stdio;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::Command;
use zenoh::query::QueryTarget;

/// A server that lets any peer publish on its keys.
const OPEN: [&str; 2] = ["--zenoh-publishers", "any"];

/// A zenoh session in client mode connected to `endpoints`, as any
/// program on the network can open one.
async fn hostile_peer(endpoints: &[String]) -> zenoh::Session {
    let endpoints = format!(
        "[{}]",
        endpoints
            .iter()
            .map(|e| format!("{e:?}"))
            .collect::<Vec<_>>()
            .join(",")
    );
    let mut config = zenoh::Config::default();
    for (key, value) in [
        ("mode", "\"client\""),
        ("connect/endpoints", endpoints.as_str()),
        ("scouting/multicast/enabled", "false"),
    ] {
        config.insert_json5(key, value).expect("a valid setting");
    }
    within("hostile peer connects", zenoh::open(config).into_future())
        .await
        .expect("zenoh opens")
}

/// Puts each payload on its key from the peer, then waits for the server
/// to answer a query from the peer: the puts went before it.
async fn put_all(peer: &zenoh::Session, prefix: &str, puts: Vec<(String, Vec<u8>)>) {
    for (key, payload) in puts {
        within("hostile put", peer.put(&key, payload).into_future())
            .await
            .expect("zenoh lets any peer put");
    }
    let replies = within(
        "fence query",
        peer.get(format!("{prefix}/latest")).into_future(),
    )
    .await
    .expect("query");
    let mut answered = false;
    while let Ok(reply) = within("fence reply", replies.recv_async()).await {
        answered |= reply.result().is_ok();
    }
    assert!(answered, "the server answers the peer's query");
}

/// A consistent frame of one particle naming `session_id`.
fn forged_frame(session_id: &str, step: u64) -> v1::Frame {
    v1::Frame {
        header: Some(v1::FrameHeader {
            session_id: session_id.into(),
            step,
            time: 999.0,
            particle_count: 1,
            fields: vec![v1::FieldKind::Position as i32],
            ..Default::default()
        }),
        fields: vec![v1::FieldData {
            kind: v1::FieldKind::Position as i32,
            components: 3,
            scalar: v1::ScalarType::F32 as i32,
            data: vec![0; 12].into(),
        }],
        ..Default::default()
    }
}

/// Garbage that is no protobuf message: a varint that never ends.
const GARBAGE: &[u8] = &[0xff; 8];
/// Two bytes that Python's protobuf once read as an empty frame.
const TWO_BYTES: &[u8] = b"\x08\x01";

/// Receives the next frame and checks it is the session's, at `step`.
async fn real_frame(frames: &Frames, id: &str, step: u64, particles: usize) {
    let frame = within(&format!("frame of step {step}"), frames.recv())
        .await
        .expect("bad samples never end the stream");
    assert_eq!(
        (frame.session_id.as_str(), frame.step, frame.particle_count),
        (id, step, particles),
        "only the server's frames come through"
    );
}

/// Garbage, a two-byte payload, a forged frame of session "FAKE" at step
/// 999999, another session's real frame replayed, an inconsistent frame
/// naming the session, and a frame naming it put on a wildcard key: the
/// subscriber hands on only the stepped session's frames and counts the
/// six it dropped, by reason.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn forged_frames_are_dropped_and_counted() {
    let server = ServerProcess::spawn(&OPEN).await.expect("server starts");
    let client = server.client().await.expect("client");
    let info = within("info", client.server_info()).await.expect("info");
    let session = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("session");
    let other = within("create other", client.create_session_toml(&small_scene()))
        .await
        .expect("other session");
    let (id, particles) = (session.id.as_str(), session.particle_count as usize);
    let link = within("zenoh connect", ZenohLink::connect(&info.zenoh_locators))
        .await
        .expect("zenoh link");
    let frames = within("subscribe", link.frames(id)).await.expect("frames");
    let replayed = within("other's frame", link.latest_message(&other.id))
        .await
        .expect("query")
        .expect("the other session's frame 0");

    let peer = hostile_peer(&info.zenoh_locators).await;
    let prefix = &session.zenoh_key_prefix;
    let key = format!("{prefix}/frames");
    let mut inconsistent = forged_frame(id, 999_999);
    inconsistent.fields[0].data.truncate(8);
    put_all(
        &peer,
        prefix,
        vec![
            (key.clone(), GARBAGE.to_vec()),
            (key.clone(), TWO_BYTES.to_vec()),
            (key.clone(), forged_frame("FAKE", 999_999).encode_to_vec()),
            (key.clone(), replayed.encode_to_vec()),
            (key.clone(), inconsistent.encode_to_vec()),
            (
                "meshless/v1/sessions/*/frames".into(),
                forged_frame(id, 999_999).encode_to_vec(),
            ),
        ],
    )
    .await;

    within("step", client.step(id, 3)).await.expect("steps");
    for step in 1..=3 {
        real_frame(&frames, id, step, particles).await;
    }
    // Drops are counted as `recv` meets them: step on until it has met
    // all six (they went out before the first step, so none should be
    // needed).
    let mut step = 3;
    while frames.dropped().total() < 6 {
        step += 1;
        within("step", client.step(id, 1)).await.expect("steps");
        real_frame(&frames, id, step, particles).await;
    }
    let dropped = frames.dropped();
    assert_eq!(
        (
            dropped.undecodable,
            dropped.wrong_session,
            dropped.malformed,
            dropped.wrong_key
        ),
        (2, 2, 1, 1),
        "{dropped:?}"
    );
    link.close().await;
}

/// Garbage, a forged FAULTED status of session "FAKE", another session's
/// status on this session's key and a status naming this session on a
/// wildcard key: the subscriber hands on only the server's status changes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn forged_statuses_are_dropped_and_counted() {
    let server = ServerProcess::spawn(&OPEN).await.expect("server starts");
    let client = server.client().await.expect("client");
    let info = within("info", client.server_info()).await.expect("info");
    let session = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("session");
    let id = session.id.as_str();
    let link = within("zenoh connect", ZenohLink::connect(&info.zenoh_locators))
        .await
        .expect("zenoh link");
    let statuses = within("subscribe", link.statuses(id))
        .await
        .expect("statuses");

    let forged = |session_id: &str| {
        v1::SessionStatus {
            session_id: session_id.into(),
            state: v1::SessionState::Faulted as i32,
            step: 999_999,
            reason: "forged".into(),
            ..Default::default()
        }
        .encode_to_vec()
    };
    let peer = hostile_peer(&info.zenoh_locators).await;
    let prefix = &session.zenoh_key_prefix;
    let key = format!("{prefix}/status");
    put_all(
        &peer,
        prefix,
        vec![
            (key.clone(), GARBAGE.to_vec()),
            (key.clone(), forged("FAKE")),
            (key.clone(), forged("another-session")),
            ("meshless/v1/sessions/*/status".into(), forged(id)),
        ],
    )
    .await;

    within("step", client.step(id, 3)).await.expect("steps");
    let status = within("status", statuses.recv())
        .await
        .expect("bad samples never end the stream");
    assert_eq!(
        (
            status.session_id.as_str(),
            v1::SessionState::try_from(status.state),
            status.step
        ),
        (id, Ok(v1::SessionState::Paused), 3)
    );
    // As for frames: reset and step for more status changes until all
    // four drops have been met.
    while statuses.dropped().total() < 4 {
        within("reset", client.reset(id)).await.expect("resets");
        let idle = within("status", statuses.recv()).await.expect("status");
        assert_eq!((idle.session_id.as_str(), idle.step), (id, 0));
        within("step", client.step(id, 1)).await.expect("steps");
        let paused = within("status", statuses.recv()).await.expect("status");
        assert_eq!((paused.session_id.as_str(), paused.step), (id, 1));
    }
    let dropped = statuses.dropped();
    assert_eq!(
        (
            dropped.undecodable,
            dropped.wrong_session,
            dropped.wrong_key
        ),
        (1, 2, 1),
        "{dropped:?}"
    );
    link.close().await;
}

/// A peer's queryable on the session's `latest` key, declared complete
/// (so that by default only it is asked), answering garbage, a forged
/// frame and an error: the latest-frame query still asks the server and
/// takes its frame.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn latest_frame_ignores_forged_replies() {
    let server = ServerProcess::spawn(&OPEN).await.expect("server starts");
    let client = server.client().await.expect("client");
    let info = within("info", client.server_info()).await.expect("info");
    let session = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("session");
    let id = session.id.as_str();
    within("step", client.step(id, 2)).await.expect("steps");

    let peer = hostile_peer(&info.zenoh_locators).await;
    let key = format!("{}/latest", session.zenoh_key_prefix);
    let queryable = within(
        "hostile queryable",
        peer.declare_queryable(&key).complete(true).into_future(),
    )
    .await
    .expect("declared");
    let asked = Arc::new(AtomicUsize::new(0));
    let answering = {
        let (asked, key) = (Arc::clone(&asked), key.clone());
        tokio::spawn(async move {
            while let Ok(query) = queryable.recv_async().await {
                for payload in [
                    GARBAGE.to_vec(),
                    forged_frame("FAKE", 999_999).encode_to_vec(),
                ] {
                    query.reply(&key, payload).await.expect("reply");
                }
                query.reply_err("forged error").await.expect("error reply");
                asked.fetch_add(1, Ordering::SeqCst);
            }
        })
    };

    let link = within("zenoh connect", ZenohLink::connect(&info.zenoh_locators))
        .await
        .expect("zenoh link");
    // The peer's queryable reaches the server some time after it is
    // declared; query until it has been asked too.
    within("a query the peer answers", async {
        loop {
            let known = asked.load(Ordering::SeqCst) > 0;
            let latest = link
                .latest_frame(id)
                .await
                .expect("forged replies are skipped");
            let frame = latest.expect("the server's frame");
            assert_eq!((frame.session_id.as_str(), frame.step), (id, 2));
            let message = link
                .latest_message(id)
                .await
                .expect("forged replies are skipped")
                .expect("the server's frame");
            assert_eq!(message.header.map(|h| h.step), Some(2));
            // Once the peer has been asked, the server knows its
            // queryable: both queries above were put to it too.
            if known {
                break;
            }
        }
    })
    .await;
    answering.abort();
    link.close().await;
}

/// `meshless watch` goes on through garbage and forged frames and reports
/// how many it dropped.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watch_counts_dropped_frames_and_goes_on() {
    let server = ServerProcess::spawn(&OPEN).await.expect("server starts");
    let client = server.client().await.expect("client");
    let info = within("info", client.server_info()).await.expect("info");
    let session = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("session");
    let id = session.id.as_str();
    let mut watch = Command::new(binary("meshless").expect("built"))
        .args(["watch", id, "--frames", "3", "--server", &server.grpc_url])
        .env("MESHLESS_LOG", "error")
        .stdout(Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .expect("watch starts");
    let mut lines = BufReader::new(watch.stdout.take().expect("stdout")).lines();
    let first = within("watch subscribes", lines.next_line())
        .await
        .expect("reads")
        .expect("a line");
    assert!(first.starts_with("watching"), "{first}");

    let peer = hostile_peer(&info.zenoh_locators).await;
    let prefix = &session.zenoh_key_prefix;
    let key = format!("{prefix}/frames");
    put_all(
        &peer,
        prefix,
        vec![
            (key.clone(), GARBAGE.to_vec()),
            (key.clone(), forged_frame("FAKE", 999_999).encode_to_vec()),
        ],
    )
    .await;
    within("step", client.step(id, 3)).await.expect("steps");
    let mut rest = Vec::new();
    while let Some(line) = within("watch output", lines.next_line())
        .await
        .expect("reads")
    {
        rest.push(line);
    }
    let status = within("watch exits", watch.wait())
        .await
        .expect("exit status");
    assert!(status.success(), "{rest:?}");
    let summary = rest.last().expect("a summary line");
    assert!(
        summary.starts_with("3 frames in") && summary.contains(", 2 dropped (last "),
        "{rest:?}"
    );
}

/// With the server's access control (the default): a peer puts a
/// well-formed frame and status forged in the session's name on its exact
/// keys and declares a queryable answering latest-frame queries with a
/// forged frame. No subscriber sees any of it, and no query reaches the
/// peer's queryable.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_peer_publishes_or_answers_through_the_server() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let info = within("info", client.server_info()).await.expect("info");
    let session = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("session");
    let (id, particles) = (session.id.as_str(), session.particle_count as usize);
    within("step", client.step(id, 2)).await.expect("steps");
    let link = within("zenoh connect", ZenohLink::connect(&info.zenoh_locators))
        .await
        .expect("zenoh link");
    let frames = within("subscribe", link.frames(id)).await.expect("frames");
    let statuses = within("subscribe", link.statuses(id))
        .await
        .expect("statuses");

    let peer = hostile_peer(&info.zenoh_locators).await;
    let prefix = &session.zenoh_key_prefix;
    let latest = format!("{prefix}/latest");
    let queryable = within(
        "hostile queryable",
        peer.declare_queryable(&latest).complete(true).into_future(),
    )
    .await
    .expect("zenoh declares it locally");
    let answering = {
        let latest = latest.clone();
        let forgery = forged_frame(id, 999_999).encode_to_vec();
        tokio::spawn(async move {
            while let Ok(query) = queryable.recv_async().await {
                let _ = query.reply(&latest, forgery.clone()).await;
            }
        })
    };
    let forged_status = v1::SessionStatus {
        session_id: id.into(),
        state: v1::SessionState::Faulted as i32,
        step: 999_999,
        reason: "forged".into(),
        ..Default::default()
    };
    for (key, payload) in [
        (
            format!("{prefix}/frames"),
            forged_frame(id, 999_999).encode_to_vec(),
        ),
        (format!("{prefix}/status"), forged_status.encode_to_vec()),
    ] {
        within("hostile put", peer.put(&key, payload).into_future())
            .await
            .expect("zenoh sends it");
    }
    // The server answers the peer's own query after it has handled (and
    // dropped) the declaration and the puts sent before it; the peer's
    // own queryable answers too, locally. A peer that has only just
    // connected may not know the server's queryable yet: ask until the
    // server answers.
    within("the server answers the peer", async {
        loop {
            let replies = peer
                .get(&latest)
                .target(QueryTarget::All)
                .await
                .expect("query");
            while let Ok(reply) = replies.recv_async().await {
                let Ok(sample) = reply.result() else { continue };
                let frame = v1::Frame::decode(&*sample.payload().to_bytes()).expect("a frame");
                if frame.header.map(|h| h.step) == Some(2) {
                    return;
                }
            }
        }
    })
    .await;

    within("step", client.step(id, 1)).await.expect("steps");
    real_frame(&frames, id, 3, particles).await;
    // Were the peer's queryable asked, its reply would come among the
    // server's, and the last valid reply wins about half the time.
    for _ in 0..5 {
        let latest = within("latest", link.latest_frame(id))
            .await
            .expect("query")
            .expect("the server's frame");
        assert_eq!(latest.step, 3, "only the server answers");
    }
    // A reset is the next status change the server publishes.
    within("reset", client.reset(id)).await.expect("resets");
    let status = within("status", statuses.recv()).await.expect("status");
    assert_eq!(
        (status.step, status.reason.as_str()),
        (0, "reset"),
        "the server's status, not the forged FAULTED one"
    );
    assert_ne!(status.state, v1::SessionState::Faulted as i32);
    assert_eq!(frames.dropped().total(), 0, "nothing forged arrived");
    assert_eq!(statuses.dropped().total(), 0, "nothing forged arrived");
    answering.abort();
    link.close().await;
}

/// A server with tokens seals each session's frames, status changes and
/// latest-frame replies with a key that only the callers who may see the
/// session receive (`Session.seal_key`). A stranger subscribed to every
/// session's frames by wildcard receives ciphertext that decodes as no
/// frame; a subscriber without the key drops every payload; the
/// observer's subscriber opens them, and drops a recorded frame played
/// again and a plain frame forged in the session's name (behind
/// `--zenoh-publishers any`, where a peer can put them).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sealed_payloads_open_only_for_those_who_may_see_the_session() {
    let dir = meshless_tests::TempDir::new("sealed");
    let tokens = dir.0.join("tokens");
    std::fs::write(
        &tokens,
        "alice alice-token-0123456789\nbob bob-token-0123456789ab\n",
    )
    .expect("tokens file");
    let tokens = tokens.to_str().expect("utf-8");
    let server = ServerProcess::spawn(&["--tokens-file", tokens, OPEN[0], OPEN[1]])
        .await
        .expect("server starts");
    let as_user = |token: &str| meshless_client::Identity {
        token: Some(token.into()),
        ..Default::default()
    };
    let alice = server
        .client_as(&as_user("alice-token-0123456789"))
        .await
        .expect("alice");
    let bob = server
        .client_as(&as_user("bob-token-0123456789ab"))
        .await
        .expect("bob");
    let info = within("info", alice.server_info()).await.expect("info");
    assert!(info.zenoh_sealed, "a server with tokens seals by default");
    let session = within(
        "create",
        alice.create_session_toml_with_observers(&small_scene(), vec!["bob".into()]),
    )
    .await
    .expect("session");
    assert_eq!(session.seal_key.len(), 32, "an AES-256 key");
    let seen_by_bob = within("bob gets it", bob.get_session(&session.id))
        .await
        .expect("bob observes");
    assert_eq!(seen_by_bob.seal_key, session.seal_key);
    let (id, particles) = (session.id.as_str(), session.particle_count as usize);

    let link = within("zenoh connect", ZenohLink::connect(&info.zenoh_locators))
        .await
        .expect("zenoh link");
    let frames = within("subscribe", link.frames(&seen_by_bob))
        .await
        .expect("frames");
    let statuses = within("subscribe", link.statuses(&seen_by_bob))
        .await
        .expect("statuses");
    let keyless = within("subscribe without the key", link.frames(id))
        .await
        .expect("frames");
    let latest = within("latest", link.latest_frame(&seen_by_bob))
        .await
        .expect("query")
        .expect("the sealed latest reply opens");
    assert_eq!(latest.step, 0);
    assert!(
        within("latest without the key", link.latest_frame(id))
            .await
            .expect("query")
            .is_none(),
        "the latest reply is sealed too"
    );

    let peer = hostile_peer(&info.zenoh_locators).await;
    let stranger = within(
        "wildcard subscriber",
        peer.declare_subscriber("meshless/v1/sessions/*/frames")
            .into_future(),
    )
    .await
    .expect("zenoh lets any peer subscribe");
    // The stranger's subscription reaches the server before the fence
    // query's answer comes back.
    put_all(&peer, &session.zenoh_key_prefix, Vec::new()).await;

    within("step", alice.step(id, 2)).await.expect("steps");
    real_frame(&frames, id, 1, particles).await;
    real_frame(&frames, id, 2, particles).await;
    let mut captured = Vec::new();
    for _ in 0..2 {
        let sample = within("the stranger's sample", stranger.recv_async())
            .await
            .expect("a sample");
        let payload = sample.payload().to_bytes().into_owned();
        if let Ok(frame) = v1::Frame::decode(&payload[..]) {
            assert!(
                frame.header.is_none_or(|h| h.session_id != id),
                "the stranger reads no frame of the session"
            );
        }
        captured.push(payload);
    }
    let status = within("status", statuses.recv()).await.expect("status");
    assert_eq!(status.session_id, id, "statuses open for the observer");
    // The keyless subscriber counts its drops as `recv` meets them, and
    // never returns one of these frames.
    within("the keyless subscriber's drops", async {
        while keyless.dropped().total() < 2 {
            let pass = tokio::time::timeout(std::time::Duration::from_millis(10), keyless.recv());
            assert!(pass.await.is_err(), "no frame opens without the key");
        }
    })
    .await;
    let dropped = keyless.dropped();
    assert_eq!(dropped.total(), dropped.undecodable + dropped.malformed);

    let prefix = &session.zenoh_key_prefix;
    put_all(
        &peer,
        prefix,
        vec![
            (format!("{prefix}/frames"), captured[0].clone()),
            (
                format!("{prefix}/frames"),
                forged_frame(id, 999_999).encode_to_vec(),
            ),
        ],
    )
    .await;
    within("step", alice.step(id, 1)).await.expect("steps");
    real_frame(&frames, id, 3, particles).await;
    let dropped = frames.dropped();
    assert_eq!(
        (dropped.replayed, dropped.not_authentic, dropped.total()),
        (1, 1, 2),
        "{dropped:?}"
    );
    link.close().await;
}

/// A recorded sealed frame played to a subscriber that started after the
/// session moved on: a fresh subscription has taken no counter yet, so
/// it learns the session's latest from the sealed answer to its
/// latest-frame query (which only the server can seal) and refuses
/// anything sealed before it. Behind `--zenoh-publishers any`, where a
/// peer can put the recording.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fresh_subscriber_refuses_a_frame_recorded_before_it_started() {
    let dir = meshless_tests::TempDir::new("replay-fresh");
    let tokens = dir.0.join("tokens");
    std::fs::write(&tokens, "alice alice-token-0123456789\n").expect("tokens file");
    let tokens = tokens.to_str().expect("utf-8");
    let server = ServerProcess::spawn(&["--tokens-file", tokens, OPEN[0], OPEN[1]])
        .await
        .expect("server starts");
    let alice = server
        .client_as(&meshless_client::Identity {
            token: Some("alice-token-0123456789".into()),
            ..Default::default()
        })
        .await
        .expect("alice");
    let info = within("info", alice.server_info()).await.expect("info");
    let session = within("create", alice.create_session_toml(&small_scene()))
        .await
        .expect("session");
    let (id, particles) = (session.id.as_str(), session.particle_count as usize);
    let prefix = &session.zenoh_key_prefix;

    // A stranger records the session's first frame, sealed as it is.
    let peer = hostile_peer(&info.zenoh_locators).await;
    let recorder = within(
        "recording subscriber",
        peer.declare_subscriber(format!("{prefix}/frames"))
            .into_future(),
    )
    .await
    .expect("zenoh lets any peer subscribe");
    put_all(&peer, prefix, Vec::new()).await;
    within("step", alice.step(id, 1)).await.expect("steps");
    let recorded = within("the recorded frame", recorder.recv_async())
        .await
        .expect("a sample")
        .payload()
        .to_bytes()
        .into_owned();
    within("step", alice.step(id, 2)).await.expect("steps");

    // The session is at step 3 when the subscriber starts.
    let link = within("zenoh connect", ZenohLink::connect(&info.zenoh_locators))
        .await
        .expect("zenoh link");
    let frames = within("subscribe", link.frames(&session))
        .await
        .expect("frames");
    put_all(&peer, prefix, vec![(format!("{prefix}/frames"), recorded)]).await;
    within("step", alice.step(id, 1)).await.expect("steps");
    real_frame(&frames, id, 4, particles).await;
    let dropped = frames.dropped();
    assert_eq!(
        (dropped.replayed, dropped.total()),
        (1, 1),
        "the recording of step 1 is refused: {dropped:?}"
    );
    link.close().await;
}
