//! Who may call, what they may do to whose sessions, and which files a
//! scene may make the server read: a real `meshless-server` process, real
//! gRPC over TCP.
//!
//! Guards issue 13's findings that any client could list, drive and delete
//! any other client's sessions, and that a scene could make the server open
//! any readable file on its host (by absolute path or `..`), hang on a FIFO,
//! run out of memory on a link to `/dev/zero`, and tell missing files from
//! unreadable ones in its errors.

use meshless_client::{ClientError, Identity, v1};
use meshless_tests::{
    ServerProcess, TempDir, binary, hostile_mesh_dir, mesh_obstacle, shipped_mesh, small_scene,
    within,
};
use std::path::Path;
use tonic::Code;

const ALICE: &str = "alice-token-0123456789";
const BOB: &str = "bob-token-0123456789ab";
const CAROL: &str = "carol-token-0123456789";

fn identity(token: &str, client_id: Option<&str>, take_over: bool) -> Identity {
    Identity {
        token: Some(token.into()),
        client_id: client_id.map(Into::into),
        take_over,
    }
}

#[track_caller]
fn expect_code<T: std::fmt::Debug>(result: Result<T, ClientError>, code: Code, mentions: &str) {
    match result {
        Ok(value) => panic!("expected {code:?} mentioning {mentions:?}, got {value:?}"),
        Err(err) => {
            assert_eq!(err.code(), Some(code), "{err}");
            assert!(
                err.to_string().contains(mentions),
                "{err} should mention {mentions:?}"
            );
        }
    }
}

fn step_of(session: &v1::Session) -> u64 {
    session.status.as_ref().expect("status").step
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn strangers_are_refused_observers_only_read_one_controller_drives() {
    let dir = TempDir::new("tokens");
    let tokens = dir.0.join("tokens");
    std::fs::write(
        &tokens,
        format!("# principals\nalice {ALICE}\nbob {BOB}\ncarol {CAROL}\n"),
    )
    .expect("tokens file");
    let server = ServerProcess::spawn(&["--tokens-file", tokens.to_str().expect("utf-8")])
        .await
        .expect("server starts");

    // No token, or a wrong one: UNAUTHENTICATED, before anything happens.
    let nobody = server.client().await.expect("connects");
    expect_code(
        within("info", nobody.server_info()).await,
        Code::Unauthenticated,
        "token",
    );
    expect_code(
        within("create", nobody.create_session_toml(&small_scene())).await,
        Code::Unauthenticated,
        "token",
    );
    let forger = server
        .client_as(&identity("alice-token-0123456788", None, false))
        .await
        .expect("connects");
    expect_code(
        within("list", forger.list_sessions()).await,
        Code::Unauthenticated,
        "token",
    );

    // Alice owns a session Bob may watch; Carol is a stranger.
    let alice = server
        .client_as(&identity(ALICE, Some("laptop"), false))
        .await
        .expect("connects");
    let session = within(
        "create",
        alice.create_session_toml_with_observers(&small_scene(), vec!["bob".into()]),
    )
    .await
    .expect("alice creates");
    assert_eq!(session.owner, "alice");
    assert_eq!(session.observers, ["bob"]);
    let id = session.id.clone();
    within("step", alice.step(&id, 2))
        .await
        .expect("alice steps");

    let bob = server
        .client_as(&identity(BOB, None, false))
        .await
        .expect("connects");
    let carol = server
        .client_as(&identity(CAROL, None, true))
        .await
        .expect("connects");

    // Bob reads: get, list, latest frame, constraints, status stream.
    let seen = within("get", bob.get_session(&id)).await.expect("bob sees");
    assert_eq!(step_of(&seen), 2);
    let listed = within("list", bob.list_sessions()).await.expect("list");
    assert_eq!(listed.iter().map(|s| &s.id).collect::<Vec<_>>(), [&id]);
    within("latest", bob.latest_frame(&id))
        .await
        .expect("bob reads frames");
    within("constraints", bob.list_constraints(&id))
        .await
        .expect("bob reads constraints");
    // ...but drives nothing.
    expect_code(
        within("step", bob.step(&id, 1)).await,
        Code::PermissionDenied,
        "step",
    );
    expect_code(
        within("run", bob.run_until(&id, 1.0, None)).await,
        Code::PermissionDenied,
        "run",
    );
    expect_code(
        within("reset", bob.reset(&id)).await,
        Code::PermissionDenied,
        "reset",
    );
    expect_code(
        within("delete", bob.delete_session(&id)).await,
        Code::PermissionDenied,
        "delete",
    );
    expect_code(
        within("edit", bob.edit_constraints(&id, Vec::new())).await,
        Code::PermissionDenied,
        "constraints",
    );

    // Carol neither sees nor drives, even asking to take over.
    expect_code(
        within("get", carol.get_session(&id)).await,
        Code::PermissionDenied,
        "see",
    );
    expect_code(
        within("latest", carol.latest_frame(&id)).await,
        Code::PermissionDenied,
        "see",
    );
    expect_code(
        within("step", carol.step(&id, 1)).await,
        Code::PermissionDenied,
        "step",
    );
    expect_code(
        within("delete", carol.delete_session(&id)).await,
        Code::PermissionDenied,
        "delete",
    );
    assert!(
        within("list", carol.list_sessions())
            .await
            .expect("list")
            .is_empty()
    );

    // A second client instance of Alice is refused until it takes over.
    let notebook = server
        .client_as(&identity(ALICE, Some("notebook"), false))
        .await
        .expect("connects");
    expect_code(
        within("step", notebook.step(&id, 1)).await,
        Code::Aborted,
        "alice/laptop",
    );
    let taking = server
        .client_as(&identity(ALICE, Some("notebook"), true))
        .await
        .expect("connects");
    let taken = within("step", taking.step(&id, 1))
        .await
        .expect("takes over");
    assert_eq!(step_of(&taken), 3);
    within("step", notebook.step(&id, 1))
        .await
        .expect("the notebook drives now");
    expect_code(
        within("step", alice.step(&id, 1)).await,
        Code::Aborted,
        "alice/notebook",
    );

    // Every refusal left the session as it was.
    let after = within("get", alice.get_session(&id)).await.expect("get");
    assert_eq!(step_of(&after), 4);
    within("delete", notebook.delete_session(&id))
        .await
        .expect("the controller deletes");
    server.terminate().await.expect("stops");
}

#[tokio::test]
async fn a_server_reachable_from_other_hosts_will_not_run_without_tokens() {
    let output = within(
        "server exit",
        tokio::process::Command::new(binary("meshless-server").expect("built"))
            .args([
                "--grpc-addr",
                "0.0.0.0:0",
                "--zenoh-listen",
                "tcp/127.0.0.1:0",
            ])
            .output(),
    )
    .await
    .expect("runs");
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("--tokens-file"), "{stderr}");
}

/// A scene of the small tank with a static mesh body whose shape is
/// `shape` (a TOML inline table).
fn mesh_scene(shape: &str) -> String {
    format!(
        "{}\n[[systems]]\nkind = \"rigid_body\"\nshape = {shape}\nposition = [0.35, 0.1, 0.25]\n",
        small_scene()
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scenes_read_only_the_mesh_directory_and_nothing_of_the_host() {
    let dir = hostile_mesh_dir("mesh-dir");
    let meshes = dir.0.join("meshes");
    let server = ServerProcess::spawn(&["--mesh-dir", meshes.to_str().expect("utf-8")])
        .await
        .expect("server starts");
    let client = server.client().await.expect("client");
    let shape = |path: &str| format!("{{ type = \"mesh\", path = {path:?}, scale = 0.05 }}");

    let ball = within(
        "create",
        client.create_session_toml(&mesh_scene(&shape("ball.obj"))),
    )
    .await
    .expect("a mesh of the directory");
    let secret = dir.0.join("secret.obj");
    let host = dir.0.to_str().expect("utf-8");
    for path in [
        secret.to_str().expect("utf-8"),
        "../secret.obj",
        "out.obj",
        "zero.obj",
        "fifo.obj",
        "missing.obj",
        "/etc/passwd.obj",
    ] {
        let result = within(path, client.create_session_toml(&mesh_scene(&shape(path)))).await;
        let Err(err) = result else {
            panic!("{path} was read");
        };
        assert_eq!(err.code(), Some(Code::InvalidArgument), "{path}: {err}");
        let message = err.to_string();
        assert!(
            message.contains("systems[1].shape.path"),
            "{path}: {message}"
        );
        assert!(
            !message.contains(host),
            "{path} disclosed the host: {message}"
        );
    }

    // An obstacle's mesh is read under the same rules, and a refused
    // edit changes nothing.
    let err = within(
        "edit",
        client.edit_constraints(&ball.id, vec![mesh_obstacle("wall", "../secret.obj")]),
    )
    .await
    .expect_err("outside the directory");
    assert_eq!(err.code(), Some(Code::InvalidArgument), "{err}");
    assert!(err.to_string().contains("wall"), "{err}");
    assert!(
        within("list", client.list_constraints(&ball.id))
            .await
            .expect("list")
            .is_empty()
    );
    server.terminate().await.expect("stops");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_a_mesh_directory_meshes_travel_in_the_request() {
    let server = ServerProcess::spawn(&["--max-mesh-mb", "1"])
        .await
        .expect("server starts");
    let client = server.client().await.expect("client");
    let ball = shipped_mesh("icosphere.obj");
    let path = ball.to_str().expect("utf-8");
    let err = within(
        "create",
        client.create_session_toml(&mesh_scene(&format!(
            "{{ type = \"mesh\", path = {path:?} }}"
        ))),
    )
    .await
    .expect_err("no files at all");
    assert_eq!(err.code(), Some(Code::InvalidArgument), "{err}");
    assert!(err.to_string().contains("reads no mesh files"), "{err}");

    // The same mesh sent as bytes builds; the echo leaves them out.
    let bytes = std::fs::read(&ball).expect("mesh");
    let inline = |content: Vec<u8>| v1::Shape {
        kind: Some(v1::shape::Kind::Mesh(v1::MeshShape {
            path: "ball.obj".into(),
            scale: Some(0.05),
            data: Some(v1::MeshData {
                format: v1::MeshFormat::Obj as i32,
                content,
                length: 0,
            }),
        })),
    };
    let mut spec = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("plain")
        .scene
        .expect("echo");
    spec.systems.push(v1::SystemSpec {
        kind: Some(v1::system_spec::Kind::RigidBody(v1::RigidBodySpec {
            shape: Some(inline(bytes.clone())),
            position: Some(v1::Vec3 {
                x: 0.35,
                y: 0.1,
                z: 0.25,
            }),
            ..Default::default()
        })),
    });
    let session = within("create", client.create_session(spec.clone()))
        .await
        .expect("inline mesh");
    let echo = session.scene.expect("echo");
    let Some(v1::system_spec::Kind::RigidBody(body)) = &echo.systems[1].kind else {
        panic!("a body");
    };
    let Some(v1::shape::Kind::Mesh(mesh)) = body.shape.as_ref().and_then(|s| s.kind.as_ref())
    else {
        panic!("a mesh");
    };
    let data = mesh.data.as_ref().expect("data");
    assert!(data.content.is_empty(), "the echo carries the mesh back");
    assert_eq!(data.length, bytes.len() as u64);

    // Over the mesh limit: INVALID_ARGUMENT naming the limit.
    let mut big = spec.clone();
    if let Some(v1::system_spec::Kind::RigidBody(body)) = &mut big.systems[1].kind {
        let mut content = bytes.clone();
        content.resize(2 << 20, b'#');
        body.shape = Some(inline(content));
    }
    let err = within("create", client.create_session(big))
        .await
        .expect_err("too large");
    assert_eq!(err.code(), Some(Code::InvalidArgument), "{err}");
    assert!(err.to_string().contains("systems[1].shape.data"), "{err}");

    // Garbage bytes: a parse error that quotes no more than a short prefix.
    let mut garbage = spec;
    if let Some(v1::system_spec::Kind::RigidBody(body)) = &mut garbage.systems[1].kind {
        body.shape = Some(inline(
            format!("v 0 0 {}\n", "9".repeat(500_000)).into_bytes(),
        ));
    }
    let err = within("create", client.create_session(garbage))
        .await
        .expect_err("garbage");
    assert_eq!(err.code(), Some(Code::InvalidArgument), "{err}");
    assert!(
        err.to_string().len() < 1_000,
        "{} bytes",
        err.to_string().len()
    );

    // The command line reads a scene's meshes and sends them inline.
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/mesh_body.toml");
    let output = within(
        "meshless session create",
        tokio::process::Command::new(binary("meshless").expect("built"))
            .args(["session", "create", scene.to_str().expect("utf-8")])
            .args(["--server", &server.grpc_url])
            .output(),
    )
    .await
    .expect("runs");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(String::from_utf8_lossy(&output.stdout).contains("mesh bodies"));
    server.terminate().await.expect("stops");
}

/// The client reads nothing it was not given either: a scene file's mesh
/// path is resolved beside the scene file.
#[test]
fn clients_resolve_mesh_paths_beside_the_scene_file() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/mesh_body.toml");
    let text = meshless_client::read_scene_file(&scene).expect("inlined");
    assert_eq!(text.matches("base64 = ").count(), 2, "both meshes inline");
}
