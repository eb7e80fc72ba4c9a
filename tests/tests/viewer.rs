//! The browser viewer's listener (`--http-addr`) of the real
//! `meshless-server` binary, over real TCP with a real HTTP/1.1 client
//! (`ureq`), as a browser reaches it: the page and its files with their
//! media types and headers, every method of the service as gRPC-web
//! behind the same token check and access rules as the gRPC port (walked
//! method by method, from the `.proto` itself, as nobody, a forger, a
//! stranger and an observer), and `NextFrame`, the poll the page reads
//! frames by.

use meshless_client::{Identity, v1};
use meshless_tests::{ServerProcess, TempDir, small_scene, within};
use prost::Message;
use std::io::Read;
use std::time::Duration;

const OWNER: &str = "alice-token-0123456789";
const OBSERVER: &str = "bob-token-0123456789ab";
const STRANGER: &str = "carol-token-0123456789";
/// A well-formed token that no principal holds.
const FORGED: &str = "alice-token-0123456788";

/// The service's definition: its `rpc` lines are the methods walked.
const PROTO: &str = include_str!("../../proto/meshless/v1/simulation.proto");

/// The gRPC codes the tests name.
const OK: i32 = 0;
const INVALID_ARGUMENT: i32 = 3;
const NOT_FOUND: i32 = 5;
const PERMISSION_DENIED: i32 = 7;
const UNAUTHENTICATED: i32 = 16;

/// A blocking HTTP call's limit: under [`meshless_tests::TIMEOUT`], so a
/// hang fails with ureq's error, which names the call, before `within`
/// fails with its own.
const HTTP_TIMEOUT: Duration = Duration::from_secs(20);

/// Most bytes of a response body read.
const MAX_BODY: u64 = 64 << 20;

/// A server with tokens for alice (the owner), bob (the observer) and
/// carol (a stranger), and the viewer's listener; with the directory that
/// holds its tokens file, removed when dropped.
async fn server_with_viewer(name: &str) -> (ServerProcess, TempDir) {
    let dir = TempDir::new(name);
    let tokens = dir.0.join("tokens");
    std::fs::write(
        &tokens,
        format!("alice {OWNER}\nbob {OBSERVER}\ncarol {STRANGER}\n"),
    )
    .expect("tokens file");
    let server = ServerProcess::spawn(&[
        "--tokens-file",
        tokens.to_str().expect("utf-8"),
        "--http-addr",
        "127.0.0.1:0",
    ])
    .await
    .expect("server starts");
    assert!(server.http_addr.is_some(), "the ready line names http=");
    (server, dir)
}

fn identity(token: &str) -> Identity {
    Identity {
        token: Some(token.into()),
        client_id: None,
        take_over: false,
    }
}

/// An HTTP client that fails a call taking longer than [`HTTP_TIMEOUT`]
/// and hands back 4xx and 5xx answers instead of failing on them.
fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .timeout_global(Some(HTTP_TIMEOUT))
        .http_status_as_error(false)
        .build()
        .into()
}

/// One GET's status, headers and body text.
#[derive(Debug)]
struct Page {
    status: u16,
    headers: ureq::http::HeaderMap,
    text: String,
}

impl Page {
    fn header(&self, name: &str) -> &str {
        self.headers
            .get(name)
            .and_then(|v| v.to_str().ok())
            .unwrap_or_default()
    }
}

/// `GET http://{addr}{path}` with no token.
async fn get(addr: &str, path: &str) -> Page {
    let url = format!("http://{addr}{path}");
    within(
        &format!("GET {path}"),
        tokio::task::spawn_blocking(move || {
            let mut response = agent()
                .get(&url)
                .call()
                .unwrap_or_else(|e| panic!("GET {url}: {e}"));
            let text = response
                .body_mut()
                .with_config()
                .limit(MAX_BODY)
                .read_to_string()
                .unwrap_or_else(|e| panic!("GET {url}: the body: {e}"));
            let (parts, _) = response.into_parts();
            Page {
                status: parts.status.as_u16(),
                headers: parts.headers,
                text,
            }
        }),
    )
    .await
    .expect("the GET ran")
}

/// What a gRPC-web call answered.
#[derive(Debug)]
struct Answer {
    /// The HTTP status of the response.
    http: u16,
    /// `grpc-status`, from the trailers frame or (an answer refused
    /// before any message: trailers-only) from the response's headers;
    /// `None` for a stream left open after its first message.
    code: Option<i32>,
    /// `grpc-message`, percent-decoded.
    message: String,
    /// The messages of the data frames, in order.
    messages: Vec<Vec<u8>>,
}

impl Answer {
    /// Whether the call succeeded: OK, or a stream that was still
    /// sending when it was left.
    fn succeeded(&self) -> bool {
        match self.code {
            Some(code) => code == OK,
            None => !self.messages.is_empty(),
        }
    }

    /// The only (or first) message, decoded as `M`.
    fn decode<M: Message + Default>(&self, method: &str) -> M {
        let bytes = self
            .messages
            .first()
            .unwrap_or_else(|| panic!("{method} answered no message: {self:?}"));
        M::decode(bytes.as_slice()).unwrap_or_else(|e| panic!("{method}'s answer: {e}"))
    }
}

/// `grpc-message`'s percent-encoding (gRPC's HTTP/2 protocol, "Responses")
/// undone.
fn percent_decoded(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let escaped = (bytes[i] == b'%')
            .then(|| text.get(i + 1..i + 3))
            .flatten()
            .and_then(|hex| u8::from_str_radix(hex, 16).ok());
        match escaped {
            Some(byte) => {
                out.push(byte);
                i += 3;
            }
            None => {
                out.push(bytes[i]);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The gRPC-web call `method` with the message `request`, as the page
/// makes it (`codec.js`): one POST over HTTP/1.1, the message in one
/// frame (flag 0, big-endian length), the token, if any, as `Bearer`. A
/// stream is read until its trailers, or left after its first message
/// when `streaming` (a status watch never ends).
fn call_blocking(
    addr: &str,
    method: &str,
    token: Option<&str>,
    request: &[u8],
    streaming: bool,
) -> Answer {
    let mut body = Vec::with_capacity(5 + request.len());
    body.push(0);
    body.extend_from_slice(&u32::try_from(request.len()).expect("small").to_be_bytes());
    body.extend_from_slice(request);
    let mut post = agent()
        .post(format!("http://{addr}/meshless.v1.Simulation/{method}"))
        .header("content-type", "application/grpc-web+proto")
        .header("accept", "application/grpc-web+proto")
        .header("x-grpc-web", "1");
    if let Some(token) = token {
        post = post.header("authorization", format!("Bearer {token}"));
    }
    let mut response = post
        .send(&body[..])
        .unwrap_or_else(|e| panic!("POST {method}: {e}"));
    let http = response.status().as_u16();
    let header = |name: &str| {
        response
            .headers()
            .get(name)
            .and_then(|v| v.to_str().ok())
            .map(str::to_owned)
    };
    if let Some(code) = header("grpc-status") {
        // Trailers-only: refused before any message.
        return Answer {
            http,
            code: Some(
                code.parse()
                    .unwrap_or_else(|_| panic!("{method}: grpc-status {code}")),
            ),
            message: percent_decoded(&header("grpc-message").unwrap_or_default()),
            messages: Vec::new(),
        };
    }
    let mut reader = response.body_mut().with_config().limit(MAX_BODY).reader();
    let mut messages = Vec::new();
    loop {
        if streaming && !messages.is_empty() {
            return Answer {
                http,
                code: None,
                message: String::new(),
                messages,
            };
        }
        let mut head = [0u8; 5];
        reader
            .read_exact(&mut head)
            .unwrap_or_else(|e| panic!("{method}: the body ended before its trailers: {e}"));
        let length = u32::from_be_bytes([head[1], head[2], head[3], head[4]]) as usize;
        let mut payload = vec![0; length];
        reader
            .read_exact(&mut payload)
            .unwrap_or_else(|e| panic!("{method}: a frame of {length} bytes cut short: {e}"));
        if head[0] & 0x80 != 0 {
            let trailers = String::from_utf8_lossy(&payload).into_owned();
            let field = |name: &str| {
                trailers.split("\r\n").find_map(|line| {
                    let (key, value) = line.split_once(':')?;
                    key.trim()
                        .eq_ignore_ascii_case(name)
                        .then(|| value.trim().to_owned())
                })
            };
            let code = field("grpc-status")
                .unwrap_or_else(|| panic!("{method}: trailers without grpc-status: {trailers:?}"));
            return Answer {
                http,
                code: Some(
                    code.parse()
                        .unwrap_or_else(|_| panic!("{method}: grpc-status {code}")),
                ),
                message: percent_decoded(&field("grpc-message").unwrap_or_default()),
                messages,
            };
        }
        assert_eq!(head[0], 0, "{method}: a frame flagged {:#04x}", head[0]);
        messages.push(payload);
    }
}

/// [`call_blocking`] off the runtime, within the tests' timeout.
async fn call(
    addr: &str,
    method: &str,
    token: Option<&str>,
    request: Vec<u8>,
    streaming: bool,
) -> Answer {
    let (addr, what) = (addr.to_owned(), format!("gRPC-web {method}"));
    let method = method.to_owned();
    let token = token.map(str::to_owned);
    within(
        &what,
        tokio::task::spawn_blocking(move || {
            call_blocking(&addr, &method, token.as_deref(), &request, streaming)
        }),
    )
    .await
    .expect("the call ran")
}

/// Every `rpc` of the service, with whether it streams its answers.
fn rpcs() -> Vec<(String, bool)> {
    let methods: Vec<_> = PROTO
        .lines()
        .filter_map(|line| line.trim().strip_prefix("rpc "))
        .map(|rest| {
            let name = rest.split('(').next().expect("a name").trim().to_owned();
            (name, rest.contains("returns (stream "))
        })
        .collect();
    assert!(methods.len() >= 20, "the proto's rpc lines: {methods:?}");
    methods
}

/// What a method may do for a caller that is not the session's owner.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Rule {
    /// Not about a session: any authenticated caller (GetServerInfo).
    Open,
    /// Not about a session, and the request walked is refused as
    /// invalid, so nothing is made (CreateSession without a scene).
    Invalid,
    /// Reads a session: observers may call it.
    Read,
    /// Drives a session: its owner alone.
    Drive,
}

/// The request walked for `method`, against the owner's session `id`
/// (`snapshot`: a snapshot of that session, which Restore would write
/// back), and who may call it. Every request is one the owner could make
/// with success (or, for CreateSession, one refused as invalid for
/// anyone), so a refusal below is the access rule's, not the request's.
///
/// # Panics
/// For a method this walk does not know: a new `rpc` must say here what
/// it takes and who may call it.
fn walked(method: &str, id: &str, snapshot: &[u8]) -> (Vec<u8>, Rule) {
    let session = v1::SessionRef {
        session_id: id.into(),
    }
    .encode_to_vec();
    match method {
        "GetServerInfo" => (v1::GetServerInfoRequest {}.encode_to_vec(), Rule::Open),
        // No scene: INVALID_ARGUMENT for every authenticated caller, so the
        // walk leaves no session of its own behind.
        "CreateSession" => (
            v1::CreateSessionRequest::default().encode_to_vec(),
            Rule::Invalid,
        ),
        "ListSessions" => (v1::ListSessionsRequest {}.encode_to_vec(), Rule::Read),
        "GetSession" | "WatchStatus" | "GetLatestFrame" | "ListConstraints" | "GetDesign" => {
            (session, Rule::Read)
        }
        // wait_ms 0: answers at once.
        "NextFrame" => (
            v1::NextFrameRequest {
                session_id: id.into(),
                after: 0,
                wait_ms: 0,
            }
            .encode_to_vec(),
            Rule::Read,
        ),
        "DeleteSession" | "Pause" | "Resume" | "Reset" | "CancelOptimize" | "Snapshot" => {
            (session, Rule::Drive)
        }
        "Step" => (
            v1::StepRequest {
                session_id: id.into(),
                steps: 1,
            }
            .encode_to_vec(),
            Rule::Drive,
        ),
        "Run" => (
            v1::RunRequest {
                session_id: id.into(),
                until: Some(v1::run_request::Until::Forever(true)),
                realtime_factor: None,
            }
            .encode_to_vec(),
            Rule::Drive,
        ),
        // Would clear the owner's obstacle.
        "EditConstraints" => (
            v1::EditConstraintsRequest {
                session_id: id.into(),
                edits: vec![v1::ConstraintEdit {
                    edit: Some(v1::constraint_edit::Edit::Clear(v1::ClearConstraints {})),
                }],
            }
            .encode_to_vec(),
            Rule::Drive,
        ),
        // The session is checked before the problem is.
        "Optimize" => (
            v1::OptimizeRequest {
                session_id: id.into(),
                ..Default::default()
            }
            .encode_to_vec(),
            Rule::Drive,
        ),
        "SimulateSteps" => (
            v1::SimulateStepsRequest {
                session_id: id.into(),
                steps: 1,
                progress_interval: 0.0,
            }
            .encode_to_vec(),
            Rule::Drive,
        ),
        // The owner's own snapshot, of an earlier step, into its session.
        "Restore" => (
            v1::RestoreRequest {
                data: snapshot.to_vec(),
                session_id: id.into(),
                observers: None,
            }
            .encode_to_vec(),
            Rule::Drive,
        ),
        "ChangeParticles" => (
            v1::ChangeParticlesRequest {
                session_id: id.into(),
                system: 0,
                remove: vec![0],
                insert_positions: Vec::new(),
                insert_velocities: Vec::new(),
            }
            .encode_to_vec(),
            Rule::Drive,
        ),
        other => panic!(
            "rpc {other} is not walked: say in tests/tests/viewer.rs what it takes and who may \
             call it"
        ),
    }
}

fn sphere_obstacle(name: &str) -> v1::ConstraintEdit {
    v1::ConstraintEdit {
        edit: Some(v1::constraint_edit::Edit::Add(v1::Constraint {
            name: name.into(),
            kind: Some(v1::constraint::Kind::Obstacle(v1::ObstacleConstraint {
                shape: Some(v1::Shape {
                    kind: Some(v1::shape::Kind::Sphere(v1::SphereShape { radius: 0.03 })),
                }),
                orientation: None,
                path: vec![v1::Waypoint {
                    time: 0.0,
                    position: Some(v1::Vec3 {
                        x: 0.4,
                        y: 0.4,
                        z: 0.4,
                    }),
                }],
            })),
        })),
    }
}

#[tokio::test]
async fn the_page_and_its_files_are_served_with_their_types() {
    let (server, _dir) = server_with_viewer("viewer-files").await;
    let addr = server.http_addr.clone().expect("a viewer address");
    // Public without a token: the same text in every copy of the binary.
    for (path, media_type) in [
        ("/", "text/html"),
        ("/index.html", "text/html"),
        ("/viewer.js", "text/javascript"),
        ("/codec.js", "text/javascript"),
        ("/render.js", "text/javascript"),
        ("/plot.js", "text/javascript"),
        ("/viewer.css", "text/css"),
        ("/schema.json", "application/json"),
        ("/scenes.json", "application/json"),
    ] {
        let page = get(&addr, path).await;
        assert_eq!(page.status, 200, "GET {path}: {page:?}");
        assert!(
            page.header("content-type").starts_with(media_type),
            "GET {path}: content-type {:?}, expected {media_type}",
            page.header("content-type")
        );
        assert_eq!(
            page.header("x-content-type-options"),
            "nosniff",
            "GET {path}"
        );
        assert!(!page.text.is_empty(), "GET {path}: an empty body");
        if media_type == "text/html" {
            let policy = page.header("content-security-policy");
            assert!(
                policy.contains("default-src 'self'"),
                "GET {path}: content-security-policy {policy:?}"
            );
            assert!(
                page.text.contains("viewer.js"),
                "GET {path}: the page loads its script"
            );
        }
    }

    let schema: serde_json::Value =
        serde_json::from_str(&get(&addr, "/schema.json").await.text).expect("the schema is JSON");
    let methods = schema["methods"].as_object().expect("methods");
    assert_eq!(
        methods["NextFrame"]["input"], "meshless.v1.NextFrameRequest",
        "{schema}"
    );
    // Every rpc of the proto, and nothing else.
    let mut listed: Vec<_> = methods.keys().cloned().collect();
    let mut declared: Vec<_> = rpcs().into_iter().map(|(name, _)| name).collect();
    listed.sort();
    declared.sort();
    assert_eq!(listed, declared);
    let scenes: serde_json::Value =
        serde_json::from_str(&get(&addr, "/scenes.json").await.text).expect("the scenes are JSON");
    let scenes = scenes.as_array().expect("a list");
    assert!(
        scenes.iter().any(|s| s["name"] == "dam_break"
            && s["toml"]
                .as_str()
                .is_some_and(|t| t.contains("[[systems]]"))),
        "{scenes:?}"
    );

    // Anything else is a 404 that echoes nothing of the request.
    for path in [
        "/no-such-file-3f9c2a",
        "/scenes/no-such-file-3f9c2a.toml",
        "/%2e%2e/no-such-file-3f9c2a",
    ] {
        let page = get(&addr, path).await;
        assert_eq!(page.status, 404, "GET {path}: {page:?}");
        assert!(
            !page.text.contains("3f9c2a"),
            "GET {path}: the 404 echoes the path: {:?}",
            page.text
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_method_over_grpc_web_keeps_the_access_rules() {
    let (server, _dir) = server_with_viewer("viewer-walk").await;
    let addr = server.http_addr.clone().expect("a viewer address");
    let owner = server.client_as(&identity(OWNER)).await.expect("connects");

    // Alice's session, which Bob may watch: stepped, a snapshot of step
    // 2 (which a Restore would bring back), an obstacle (which a
    // constraint edit would clear).
    let session = within(
        "create",
        owner.create_session_toml_with_observers(&small_scene(), vec!["bob".into()]),
    )
    .await
    .expect("alice creates");
    let id = session.id.clone();
    within("step", owner.step(&id, 2)).await.expect("steps");
    let snapshot = within("snapshot", owner.snapshot(&id))
        .await
        .expect("a snapshot")
        .data;
    within("step", owner.step(&id, 1)).await.expect("steps");
    within(
        "obstacle",
        owner.edit_constraints(&id, vec![sphere_obstacle("ball")]),
    )
    .await
    .expect("an obstacle");
    let before = within("get", owner.get_session(&id)).await.expect("get");
    let before_status = before.status.clone().expect("a status");
    assert_eq!(before_status.step, 3);

    let methods = rpcs();
    // Nobody and a forger: UNAUTHENTICATED for every method, whatever its
    // body (here an empty one, which any new rpc takes too), before
    // anything happens.
    for (method, streaming) in &methods {
        for (who, token) in [("nobody", None), ("a forger", Some(FORGED))] {
            let answer = call(&addr, method, token, Vec::new(), *streaming).await;
            assert_eq!(
                answer.code,
                Some(UNAUTHENTICATED),
                "{method} as {who}: {answer:?}"
            );
            assert!(
                answer.messages.is_empty(),
                "{method} as {who} answered a message: {answer:?}"
            );
            assert!(
                answer.message.contains("token"),
                "{method} as {who}: {answer:?}"
            );
        }
    }

    for (method, streaming) in &methods {
        let (request, rule) = walked(method, &id, &snapshot);

        // Carol, a stranger, gets nothing of Alice's session.
        let answer = call(&addr, method, Some(STRANGER), request.clone(), *streaming).await;
        match (method.as_str(), rule) {
            // Versions and limits: the same for every caller.
            (_, Rule::Open) => assert!(answer.succeeded(), "{method} as carol: {answer:?}"),
            (_, Rule::Invalid) => assert_eq!(
                answer.code,
                Some(INVALID_ARGUMENT),
                "{method} as carol: {answer:?}"
            ),
            // The list is answered, without Alice's session.
            ("ListSessions", _) => {
                assert_eq!(answer.code, Some(OK), "{method} as carol: {answer:?}");
                let listed: v1::ListSessionsResponse = answer.decode(method);
                assert!(
                    listed
                        .sessions
                        .iter()
                        .all(|s| s.id != id && s.owner != "alice"),
                    "carol lists alice's session: {listed:?}"
                );
            }
            // Anything about the session: refused, or not found (which
            // tells no more), and no message.
            (_, Rule::Read | Rule::Drive) => {
                assert!(
                    matches!(answer.code, Some(PERMISSION_DENIED | NOT_FOUND)),
                    "{method} as carol: {answer:?}"
                );
                assert!(answer.messages.is_empty(), "{method} as carol: {answer:?}");
            }
        }

        // Bob, an observer, reads but drives nothing.
        let answer = call(&addr, method, Some(OBSERVER), request, *streaming).await;
        match (method.as_str(), rule) {
            (_, Rule::Open) => assert!(answer.succeeded(), "{method} as bob: {answer:?}"),
            (_, Rule::Invalid) => assert_eq!(
                answer.code,
                Some(INVALID_ARGUMENT),
                "{method} as bob: {answer:?}"
            ),
            ("ListSessions", _) => {
                assert_eq!(answer.code, Some(OK), "{method} as bob: {answer:?}");
                let listed: v1::ListSessionsResponse = answer.decode(method);
                assert_eq!(
                    listed.sessions.iter().map(|s| &s.id).collect::<Vec<_>>(),
                    [&id],
                    "bob lists the session he observes"
                );
            }
            ("GetSession", _) => {
                assert_eq!(answer.code, Some(OK), "{method} as bob: {answer:?}");
                let seen: v1::Session = answer.decode(method);
                assert_eq!(
                    (seen.id.as_str(), seen.owner.as_str()),
                    (id.as_str(), "alice")
                );
            }
            // The current status, first; the stream goes on until the
            // session is deleted.
            ("WatchStatus", _) => {
                assert!(answer.succeeded(), "{method} as bob: {answer:?}");
                let status: v1::SessionStatus = answer.decode(method);
                assert_eq!(status.session_id, id);
                assert_eq!(status.step, 3);
            }
            ("GetLatestFrame", _) => {
                assert_eq!(answer.code, Some(OK), "{method} as bob: {answer:?}");
                let frame: v1::Frame = answer.decode(method);
                let header = frame.header.expect("a header");
                assert_eq!((header.session_id.as_str(), header.step), (id.as_str(), 3));
            }
            ("NextFrame", _) => {
                assert_eq!(answer.code, Some(OK), "{method} as bob: {answer:?}");
                let next: v1::NextFrameResponse = answer.decode(method);
                assert!(next.number >= 1, "{next:?}");
                let frame = v1::Frame::decode(next.frame).expect("a frame");
                assert_eq!(frame.header.expect("a header").session_id, id);
            }
            ("ListConstraints", _) => {
                assert_eq!(answer.code, Some(OK), "{method} as bob: {answer:?}");
                let list: v1::ConstraintList = answer.decode(method);
                let names: Vec<_> = list.constraints.iter().map(|c| c.name.as_str()).collect();
                assert_eq!(names, ["ball"]);
            }
            // No design yet: NOT_FOUND, which is what alice gets too.
            ("GetDesign", _) => {
                assert_eq!(answer.code, Some(NOT_FOUND), "{method} as bob: {answer:?}")
            }
            (_, Rule::Read) => panic!("{method} is a read the walk does not check"),
            (_, Rule::Drive) => {
                assert_eq!(
                    answer.code,
                    Some(PERMISSION_DENIED),
                    "{method} as bob: {answer:?}"
                );
                assert!(answer.messages.is_empty(), "{method} as bob: {answer:?}");
            }
        }
    }

    // Alice's session is as it was: same step and state, same obstacle,
    // still there (a Delete, Reset, Restore, Run, Step or edit that got
    // through would show).
    let after = within("get", owner.get_session(&id))
        .await
        .expect("the session is still there");
    assert_eq!(after.status, Some(before_status));
    let constraints = within("constraints", owner.list_constraints(&id))
        .await
        .expect("constraints");
    assert_eq!(
        constraints
            .iter()
            .map(|c| c.name.as_str())
            .collect::<Vec<_>>(),
        ["ball"]
    );
    let listed = within("list", owner.list_sessions()).await.expect("list");
    assert_eq!(listed.iter().map(|s| &s.id).collect::<Vec<_>>(), [&id]);
}

/// One NextFrame poll over gRPC-web as `token`.
async fn poll(addr: &str, token: &str, id: &str, after: u64, wait_ms: u32) -> Answer {
    let request = v1::NextFrameRequest {
        session_id: id.into(),
        after,
        wait_ms,
    };
    call(
        addr,
        "NextFrame",
        Some(token),
        request.encode_to_vec(),
        false,
    )
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn next_frame_answers_each_new_frame_once() {
    let (server, _dir) = server_with_viewer("viewer-next").await;
    let addr = server.http_addr.clone().expect("a viewer address");
    let owner = server.client_as(&identity(OWNER)).await.expect("connects");
    let session = within("create", owner.create_session_toml(&small_scene()))
        .await
        .expect("created");
    let id = session.id.clone();

    // The first poll answers the latest frame at once.
    let first = poll(&addr, OWNER, &id, 0, 0).await;
    assert_eq!(first.code, Some(OK), "{first:?}");
    assert_eq!(first.http, 200, "{first:?}");
    let first: v1::NextFrameResponse = first.decode("NextFrame");
    assert!(first.number >= 1, "{first:?}");
    let frame = v1::Frame::decode(first.frame).expect("the frame decodes");
    let header = frame.header.expect("a header");
    assert_eq!(header.session_id, id);
    assert_eq!(header.step, 0);
    assert_eq!(header.particle_count, session.particle_count);
    assert!(!frame.fields.is_empty(), "a frame with no fields");

    // Nothing newer on an idle session: the wait ends empty, with the
    // number asked about.
    let idle = poll(&addr, OWNER, &id, first.number, 200).await;
    assert_eq!(idle.code, Some(OK), "{idle:?}");
    let idle: v1::NextFrameResponse = idle.decode("NextFrame");
    assert_eq!(idle.number, first.number);
    assert!(idle.frame.is_empty(), "{} bytes", idle.frame.len());

    // A step makes a newer frame, which the next poll answers.
    within("step", owner.step(&id, 1)).await.expect("steps");
    let next = poll(&addr, OWNER, &id, first.number, 5_000).await;
    assert_eq!(next.code, Some(OK), "{next:?}");
    let next: v1::NextFrameResponse = next.decode("NextFrame");
    assert!(
        next.number > first.number,
        "{} after {}",
        next.number,
        first.number
    );
    let frame = v1::Frame::decode(next.frame).expect("the frame decodes");
    let header = frame.header.expect("a header");
    assert_eq!((header.session_id.as_str(), header.step), (id.as_str(), 1));

    // A wait over a minute is refused by name.
    let long = poll(&addr, OWNER, &id, next.number, 60_001).await;
    assert_eq!(long.code, Some(INVALID_ARGUMENT), "{long:?}");
    assert!(long.message.contains("wait_ms"), "{long:?}");
}

/// The status code of one raw HTTP/1.1 request to `addr` whose `Host`
/// header is `host`, as a browser sends it for a page reached by that
/// name.
fn status_for_host(addr: &str, host: &str, request: &str) -> u16 {
    use std::io::Write;
    let mut stream = std::net::TcpStream::connect(addr).expect("connects");
    stream
        .set_read_timeout(Some(HTTP_TIMEOUT))
        .expect("a read timeout");
    let request = request.replace("{host}", host);
    stream.write_all(request.as_bytes()).expect("sends");
    let mut head = [0u8; 12];
    stream.read_exact(&mut head).expect("a status line");
    let line = String::from_utf8_lossy(&head).into_owned();
    line[9..12]
        .parse()
        .unwrap_or_else(|_| panic!("a status line: {line:?}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_server_without_tokens_answers_its_viewer_only_at_loopback_names() {
    // Every caller of a server without tokens drives every session: a
    // page of another site whose name resolves to 127.0.0.1 (DNS
    // rebinding) must not be answered as this server's own page is.
    let server = ServerProcess::spawn(&["--http-addr", "127.0.0.1:0"])
        .await
        .expect("server starts");
    let addr = server.http_addr.clone().expect("a viewer address");
    let port = addr.rsplit_once(':').expect("a port").1.to_owned();
    let page = "GET / HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n";
    // ListSessions with an empty request message.
    let call = "POST /meshless.v1.Simulation/ListSessions HTTP/1.1\r\nHost: {host}\r\n\
                content-type: application/grpc-web+proto\r\ncontent-length: 5\r\n\
                Connection: close\r\n\r\n\0\0\0\0\0";
    let statuses = |host: String| {
        let addr = addr.clone();
        async move {
            within(
                "raw requests",
                tokio::task::spawn_blocking(move || {
                    (
                        status_for_host(&addr, &host, page),
                        status_for_host(&addr, &host, call),
                    )
                }),
            )
            .await
            .expect("ran")
        }
    };
    for host in [
        format!("127.0.0.1:{port}"),
        format!("localhost:{port}"),
        format!("[::1]:{port}"),
    ] {
        assert_eq!(statuses(host.clone()).await, (200, 200), "{host}");
    }
    for host in [format!("evil.example:{port}"), "evil.example".to_owned()] {
        assert_eq!(statuses(host.clone()).await, (403, 403), "{host}");
    }
}

/// Field `field` (numbered from 1, as proc(5) does) of a
/// `/proc/.../stat`; the second, the thread's name in parentheses, may
/// hold spaces.
#[cfg(target_os = "linux")]
fn stat_field(stat: &std::path::Path, field: usize) -> Option<i64> {
    let stat = std::fs::read_to_string(stat).ok()?;
    let fields = &stat[stat.rfind(')')? + 2..];
    // From the third field (state) on.
    fields.split_whitespace().nth(field - 3)?.parse().ok()
}

/// proc(5): the scheduling policy is a thread's 41st field.
#[cfg(target_os = "linux")]
const POLICY: usize = 41;

/// sched(7)'s usual policy.
#[cfg(target_os = "linux")]
const SCHED_OTHER: i64 = 0;

/// sched(7)'s policy for work that runs only when nothing else would.
#[cfg(target_os = "linux")]
const SCHED_IDLE: i64 = 5;

/// The scheduling policy of each of `pid`'s threads named `name`.
#[cfg(target_os = "linux")]
fn thread_policies(pid: u32, name: &str) -> Vec<i64> {
    let tasks = std::fs::read_dir(format!("/proc/{pid}/task")).expect("the server's threads");
    tasks
        .filter_map(|task| {
            let dir = task.ok()?.path();
            // A thread that ended since it was listed has no files.
            let comm = std::fs::read_to_string(dir.join("comm")).ok()?;
            (comm.trim() == name).then(|| stat_field(&dir.join("stat"), POLICY))?
        })
        .collect()
}

/// The viewer is served from a thread of its own that by default runs
/// only on CPU time the simulations leave (`SCHED_IDLE`); the page still
/// works through it.
#[cfg(target_os = "linux")]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_viewer_runs_on_its_own_thread_below_the_simulations() {
    let server = ServerProcess::spawn(&["--http-addr", "127.0.0.1:0"])
        .await
        .expect("server starts");
    let pid = server.pid().expect("a running server");
    let main = stat_field(std::path::Path::new(&format!("/proc/{pid}/stat")), POLICY);
    assert_eq!(
        main,
        Some(SCHED_OTHER),
        "the server itself is scheduled as usual"
    );
    assert_eq!(
        thread_policies(pid, "meshless-viewer"),
        vec![SCHED_IDLE],
        "one viewer thread, on idle CPU time"
    );
    let addr = server.http_addr.clone().expect("http=");
    let page = get(&addr, "/").await;
    assert_eq!(page.status, 200, "the page is served from that thread");
}
