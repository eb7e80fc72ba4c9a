//! The `meshless` command line as a user runs it: an embedded run that
//! writes files ParaView opens, session commands against a real server,
//! and bad input that ends in a clear message and a failing exit code.

use meshless_tests::{ServerProcess, binary, small_scene, within};
use std::path::PathBuf;
use std::process::Stdio;
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::Command;

/// A fresh folder under the system temp dir, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("meshless-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        Self(dir)
    }
}

impl TempDir {
    /// Writes `text` to `name` in the folder and returns its path.
    fn file(&self, name: &str, text: &str) -> PathBuf {
        let path = self.0.join(name);
        std::fs::write(&path, text).expect("a file in the temp dir");
        path
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

async fn meshless(args: &[&str]) -> std::process::Output {
    let mut command = Command::new(binary("meshless").expect("built"));
    command.args(args).env("MESHLESS_LOG", "error");
    within(&format!("meshless {}", args.join(" ")), command.output())
        .await
        .expect("runs")
}

/// Runs `meshless` and returns its stdout, failing with its stderr.
async fn meshless_ok(args: &[&str]) -> String {
    let output = meshless(args).await;
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// The names of the files in `dir`, sorted.
fn listing(dir: &std::path::Path) -> Vec<String> {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .expect("output folder")
        .map(|e| e.expect("entry").file_name().into_string().expect("utf-8"))
        .collect();
    files.sort();
    files
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn run_writes_a_vtk_series() {
    let dir = TempDir::new("run");
    let scene = dir.file("small.toml", &small_scene());
    let out = dir.0.join("frames");
    let stdout = meshless_ok(&[
        "run",
        scene.to_str().expect("utf-8"),
        "--until",
        "0.05",
        "--output",
        out.to_str().expect("utf-8"),
    ])
    .await;
    assert!(stdout.contains("particles         125"), "{stdout}");
    let files = listing(&out);
    let expected: Vec<_> = (0..=5).map(|s| format!("frame_{s:06}.vtk")).collect();
    assert_eq!(files, expected);
    let first = std::fs::read(out.join("frame_000005.vtk")).expect("frame file");
    assert!(first.starts_with(b"# vtk DataFile Version 3.0\n"));
    assert!(first.windows(16).any(|w| w == b"POINTS 125 float"));
}

/// A scene that asks for a surface gets a mesh file beside each frame, in
/// the format `--surface-format` names.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn run_writes_surfaces_beside_the_frames() {
    let dir = TempDir::new("surface");
    let scene = dir.file(
        "surface.toml",
        &small_scene().replace("[output]", "[output]\nsurface = { cell = 0.02 }"),
    );
    let out = dir.0.join("frames");
    let stdout = meshless_ok(&[
        "run",
        scene.to_str().expect("utf-8"),
        "--until",
        "0.02",
        "--format",
        "ply",
        "--surface-format",
        "ply",
        "--output",
        out.to_str().expect("utf-8"),
    ])
    .await;
    assert!(stdout.contains("surface_*.ply  (3 files)"), "{stdout}");
    let files = listing(&out);
    let mut expected: Vec<_> = (0..=2).map(|s| format!("frame_{s:06}.ply")).collect();
    expected.extend((0..=2).map(|s| format!("surface_{s:06}.ply")));
    assert_eq!(files, expected);
    let mesh = std::fs::read(out.join("surface_000002.ply")).expect("surface file");
    assert!(mesh.starts_with(b"ply\nformat binary_little_endian 1.0\n"));
    assert!(mesh.windows(13).any(|w| w == b"element face "));
}

/// The shipped brittle beam runs embedded until it breaks: its crack
/// faces land beside the frames from the frame its first crack starts in,
/// as OBJ with a normal per vertex, and each PLY frame carries the
/// fragment labels.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn run_writes_the_crack_faces_of_a_breaking_solid() {
    let dir = TempDir::new("cracks");
    let scene = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/brittle_beam.toml");
    let out = dir.0.join("frames");
    let stdout = meshless_ok(&[
        "run",
        scene.to_str().expect("utf-8"),
        "--until",
        "0.2",
        "--format",
        "ply",
        "--output",
        out.to_str().expect("utf-8"),
    ])
    .await;
    assert!(stdout.contains("cracks*_*.obj"), "{stdout}");
    let files = listing(&out);
    let cracks: Vec<_> = files.iter().filter(|f| f.starts_with("cracks0_")).collect();
    assert!(!cracks.is_empty(), "{files:?}");
    let last = cracks.last().expect("a crack file");
    let obj = std::fs::read_to_string(out.join(last)).expect("crack file");
    let lines = |tag: &str| obj.lines().filter(|l| l.starts_with(tag)).count();
    assert!(
        lines("v ") > 0 && lines("vn ") == lines("v ") && lines("f ") > 0,
        "{last}"
    );
    let ply = std::fs::read(out.join("frame_000100.ply")).expect("the last frame");
    assert!(
        ply.windows(22).any(|w| w == b"property float fragmen"),
        "no fragment field"
    );
}

/// The number of points a PLY frame holds, from its header.
fn ply_points(ply: &[u8]) -> usize {
    let header = String::from_utf8_lossy(&ply[..ply.len().min(2048)]);
    header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .and_then(|n| n.trim().parse().ok())
        .expect("a vertex element")
}

/// The shipped ductile bar runs embedded past its tear: its frames grow
/// as resampling splits the particles beside the tear, each PLY holding
/// every particle of its step.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn run_writes_frames_that_grow_as_a_solid_resamples() {
    let dir = TempDir::new("ductile");
    let scene = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/ductile_spin.toml");
    let out = dir.0.join("frames");
    meshless_ok(&[
        "run",
        scene.to_str().expect("utf-8"),
        "--until",
        "0.14",
        "--format",
        "ply",
        "--output",
        out.to_str().expect("utf-8"),
    ])
    .await;
    let count = |name: &str| ply_points(&std::fs::read(out.join(name)).expect("a frame"));
    let (first, last) = (count("frame_000000.ply"), count("frame_000070.ply"));
    assert_eq!(first, 300, "the bar as built");
    assert!(last > first, "no particle split: {first} -> {last}");
}

/// The shipped jelly drop (an elastic solid and a static ball, no fluid)
/// runs embedded: the summary counts the solid's particles, the PLY
/// frames hold every one of them, finite, and the solid's embedded
/// surface lands beside each frame as an OBJ with a normal per vertex.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn run_writes_the_particles_of_a_shipped_solid_scene() {
    let dir = TempDir::new("solid");
    let scene = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/jelly_drop.toml");
    let out = dir.0.join("frames");
    let stdout = meshless_ok(&[
        "run",
        scene.to_str().expect("utf-8"),
        "--until",
        "0.05",
        "--format",
        "ply",
        "--output",
        out.to_str().expect("utf-8"),
    ])
    .await;
    assert!(
        stdout.contains("particles         216  (0 fluid, 216 in 1 solid)"),
        "{stdout}"
    );
    assert!(stdout.contains("solid*_*.obj  (6 files"), "{stdout}");
    let mut expected: Vec<_> = (0..=5).map(|s| format!("frame_{s:06}.ply")).collect();
    expected.extend((0..=5).map(|s| format!("solid0_{s:06}.obj")));
    assert_eq!(listing(&out), expected);
    let mut counts = Vec::new();
    for step in [0, 5] {
        let obj = std::fs::read_to_string(out.join(format!("solid0_{step:06}.obj")))
            .expect("surface file");
        let lines = |tag: &str| obj.lines().filter(|l| l.starts_with(tag)).count();
        let (v, vn, f) = (lines("v "), lines("vn "), lines("f "));
        // A closed surface of the sphere's topology: V - E + F = 2 with
        // E = 3F / 2.
        assert!(
            v > 216 && vn == v && f == 2 * v - 4,
            "step {step}: {v} {vn} {f}"
        );
        let face = obj.lines().find(|l| l.starts_with("f ")).expect("a face");
        assert!(
            face.split_whitespace().skip(1).all(|w| {
                let (a, b) = w.split_once("//").expect("v//vn");
                a == b
            }),
            "{face}"
        );
        counts.push((v, f));
    }
    assert_eq!(counts[0], counts[1], "the surface keeps its mesh");
    let ply = std::fs::read(out.join("frame_000005.ply")).expect("frame file");
    let header = b"end_header\n";
    let body = ply
        .windows(header.len())
        .position(|w| w == header)
        .expect("a PLY header")
        + header.len();
    assert!(ply.windows(18).any(|w| w == b"element vertex 216"));
    let floats: Vec<f32> = ply[body..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    assert_eq!(floats.len(), 216 * 6, "position and velocity per particle");
    assert!(floats.iter().all(|v| v.is_finite()));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bad_scene_file_fails_with_the_field_named() {
    let dir = TempDir::new("bad");
    let scene = dir.file(
        "bad.toml",
        &small_scene().replace("spacing = 0.04", "spacing = 0.0"),
    );
    let output = meshless(&["run", scene.to_str().expect("utf-8")]).await;
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("systems[0].spacing"), "{stderr}");
}

/// A value of the wrong type names its field (it used to say only
/// "invalid type: string" at the start of the system's table).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_wrongly_typed_value_names_its_field() {
    let dir = TempDir::new("typed");
    let scene = dir.file(
        "typed.toml",
        &small_scene().replace("spacing = 0.04", "spacing = \"0.04\""),
    );
    let output = meshless(&["run", scene.to_str().expect("utf-8")]).await;
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("`spacing`") && stderr.contains("invalid type: string"),
        "{stderr}"
    );
}

/// `meshless run … | head -1`: the reader goes away after one line, and
/// the run ends quietly with success instead of panicking on the broken
/// pipe (exit 101).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_closed_pipe_ends_the_run_quietly() {
    let dir = TempDir::new("pipe");
    let scene = dir.file("small.toml", &small_scene());
    let out = dir.0.join("frames");
    let mut child = Command::new(binary("meshless").expect("built"))
        .args([
            "run",
            scene.to_str().expect("utf-8"),
            "--until",
            "0.05",
            "--output",
            out.to_str().expect("utf-8"),
        ])
        .env("MESHLESS_LOG", "error")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("starts");
    // Close the read end at once: every line the summary writes meets a
    // closed pipe.
    drop(child.stdout.take());
    let output = within("meshless run into a closed pipe", child.wait_with_output())
        .await
        .expect("ends");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{:?}: {stderr}", output.status);
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// A run whose first step faults still leaves the initial frame on disk
/// (the frame writer is joined on the error path too), says why it
/// stopped and fails.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_run_that_faults_at_once_keeps_its_first_frames() {
    let dir = TempDir::new("fault");
    // A stiffness the single sub-step cannot follow: the first step blows
    // up.
    let scene = dir.file(
        "fault.toml",
        &small_scene()
            .replace("[time]", "[time]\nmax_substeps = 1")
            .replace("stiffness = ", "stiffness = 1e12 #"),
    );
    let out = dir.0.join("frames");
    let output = meshless(&[
        "run",
        scene.to_str().expect("utf-8"),
        "--until",
        "0.05",
        "--output",
        out.to_str().expect("utf-8"),
    ])
    .await;
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(stderr.contains("step 1"), "{stderr}");
    let files = listing(&out);
    assert!(
        files.contains(&"frame_000000.vtk".to_owned()),
        "the initial frame is on disk: {files:?}"
    );
}

/// A run of capped steps warns in its summary; a solid-only run reports
/// its Newton work as the implicit solids', not as a pressure solver's.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn run_summaries_warn_of_capped_steps_and_name_solver_work() {
    let dir = TempDir::new("summary");
    let capped = dir.file(
        "capped.toml",
        &small_scene().replace("[time]", "[time]\nmax_substeps = 1"),
    );
    let out = dir.0.join("frames");
    let stdout = meshless_ok(&[
        "run",
        capped.to_str().expect("utf-8"),
        "--until",
        "0.02",
        "--output",
        out.to_str().expect("utf-8"),
    ])
    .await;
    assert!(
        stdout.contains("WARNING") && stdout.contains("hit time.max_substeps"),
        "{stdout}"
    );
    let solid = dir.file(
        "solid.toml",
        &meshless_tests::small_solid_scene()
            .replace("[[systems]]", "[[systems]]\nintegrator = \"implicit\""),
    );
    let stdout = meshless_ok(&[
        "run",
        solid.to_str().expect("utf-8"),
        "--until",
        "0.02",
        "--output",
        out.to_str().expect("utf-8"),
    ])
    .await;
    assert!(stdout.contains("implicit solids"), "{stdout}");
    assert!(stdout.contains("energy            kinetic"), "{stdout}");
    assert!(!stdout.contains("pressure solver"), "{stdout}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn session_commands_drive_a_server() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let dir = TempDir::new("session");
    let scene = dir.file("small.toml", &small_scene());
    let url = server.grpc_url.clone();
    let with_server = |args: &[&str]| {
        let mut all: Vec<String> = args.iter().map(|a| (*a).to_owned()).collect();
        all.extend(["--server".to_owned(), url.clone()]);
        all
    };

    let created = meshless(&[
        "session",
        "create",
        scene.to_str().expect("utf-8"),
        "--server",
        &url,
    ])
    .await;
    assert!(
        created.status.success(),
        "{}",
        String::from_utf8_lossy(&created.stderr)
    );
    let stdout = String::from_utf8_lossy(&created.stdout);
    let id = stdout.split_whitespace().next().expect("an id").to_owned();
    assert!(stdout.contains("idle at step 0"), "{stdout}");

    let args = with_server(&["session", "step", &id, "-n", "4"]);
    let stepped = meshless(&args.iter().map(String::as_str).collect::<Vec<_>>()).await;
    assert!(stepped.status.success());
    assert!(String::from_utf8_lossy(&stepped.stdout).contains("paused at step 4"));

    let args = with_server(&["session", "list"]);
    let listed = meshless(&args.iter().map(String::as_str).collect::<Vec<_>>()).await;
    assert!(String::from_utf8_lossy(&listed.stdout).contains(&id));

    let args = with_server(&["session", "delete", &id]);
    let deleted = meshless(&args.iter().map(String::as_str).collect::<Vec<_>>()).await;
    assert!(deleted.status.success());

    let args = with_server(&["session", "get", &id]);
    let missing = meshless(&args.iter().map(String::as_str).collect::<Vec<_>>()).await;
    assert!(!missing.status.success());
    let stderr = String::from_utf8_lossy(&missing.stderr);
    assert!(
        stderr.contains("NotFound")
            || stderr.contains("not found")
            || stderr.contains("no session"),
        "{stderr}"
    );
}

/// `--route` sends a call that names a session to the server its id
/// names: a server named `localhost` reached through the template
/// `http://{server}:PORT`; an id that names no server is refused before
/// any call, saying what to do instead.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn route_reaches_the_server_a_session_id_names() {
    let server = ServerProcess::spawn(&["--server-name", "localhost"])
        .await
        .expect("server starts");
    let client = server.client().await.expect("client");
    let info = within("server info", client.server_info())
        .await
        .expect("info");
    assert_eq!(info.server_name, "localhost");
    assert_eq!(info.zenoh_routers, 0, "a peer with no router");
    let session = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("created");
    assert_eq!(
        meshless_client::server_of(&session.id),
        Some("localhost"),
        "{}",
        session.id
    );
    let port = server.grpc_url.rsplit(':').next().expect("a port");
    let route = format!("http://{{server}}:{port}");
    let stepped = meshless_ok(&[
        "session",
        "step",
        &session.id,
        "-n",
        "2",
        "--route",
        &route,
        "--server",
        "http://127.0.0.1:9",
    ])
    .await;
    assert!(stepped.contains("paused at step 2"), "{stepped}");

    let unnamed = meshless(&["session", "get", "0123456789abcdef", "--route", &route]).await;
    assert!(!unnamed.status.success());
    let stderr = String::from_utf8_lossy(&unnamed.stderr);
    assert!(stderr.contains("names no server"), "{stderr}");
}

/// `meshless watch` finds the zenoh endpoint through the server, counts
/// the frames it receives and stops after `--frames`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watch_counts_frames_from_zenoh() {
    let server = ServerProcess::spawn(&[]).await.expect("server starts");
    let client = server.client().await.expect("client");
    let session = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("session");
    let mut watch = Command::new(binary("meshless").expect("built"))
        .args([
            "watch",
            &session.id,
            "--frames",
            "3",
            "--server",
            &server.grpc_url,
        ])
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
    within("step", client.step(&session.id, 3))
        .await
        .expect("steps");
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
    assert!(status.success());
    let last = rest.last().expect("a summary line");
    assert!(last.starts_with("3 frames in"), "{rest:?}");
}

/// The main job, `meshless demo`, end to end on a small scene: embedded
/// server, gRPC control, zenoh frames, files on disk, every frame received.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn demo_runs_the_whole_service_in_process() {
    let dir = TempDir::new("demo");
    let scene = dir.file("small.toml", &small_scene());
    let out = dir.0.join("frames");
    let stdout = meshless_ok(&[
        "demo",
        "--scene",
        scene.to_str().expect("utf-8"),
        "--until",
        "0.1",
        "--format",
        "ply",
        "--output",
        out.to_str().expect("utf-8"),
    ])
    .await;
    assert!(
        stdout.contains("simulated         0.100 s in 10 steps"),
        "{stdout}"
    );
    assert!(stdout.contains("frames received   11 of 11"), "{stdout}");
    let files = std::fs::read_dir(&out).expect("output").count();
    assert_eq!(files, 11);
    let last = std::fs::read(out.join("frame_000010.ply")).expect("last frame");
    assert!(last.starts_with(b"ply\nformat binary_little_endian 1.0\n"));
}

/// `meshless study` sweeps a knob on a dam break, writes one CSV row per
/// value with the front error against Martin & Moyce, and a PNG chart.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn study_writes_error_against_cost() {
    let dir = TempDir::new("study");
    let coarse = include_str!("../../scenes/dam_break.toml")
        .replace("spacing = 0.02", "spacing = 0.04")
        .replace("support_radius = 0.04", "support_radius = 0.08");
    let scene = dir.file("coarse.toml", &coarse);
    meshless_ok(&[
        "study",
        "--knob",
        "cfl",
        "--values",
        "0.4,0.8",
        "--scene",
        scene.to_str().expect("utf-8"),
        "--output",
        dir.0.to_str().expect("utf-8"),
    ])
    .await;
    let csv = std::fs::read_to_string(dir.0.join("study_cfl.csv")).expect("csv");
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows.len(), 3, "{csv}");
    assert!(rows[0].starts_with("knob,value,particles"));
    for row in &rows[1..] {
        let cols: Vec<&str> = row.split(',').collect();
        assert_eq!(cols[2], "735", "{row}");
        let worst: f64 = cols[7].parse().expect("a front error");
        assert!(worst.is_finite() && worst < 0.5, "{row}");
        assert_eq!(cols[9], "ok");
    }
    // A larger Courant number means fewer sub-steps.
    let substeps: Vec<u64> = rows[1..]
        .iter()
        .map(|r| {
            r.split(',')
                .nth(3)
                .and_then(|s| s.parse().ok())
                .expect("sub-steps")
        })
        .collect();
    assert!(substeps[1] < substeps[0], "{substeps:?}");
    let png = std::fs::read(dir.0.join("study_cfl.png")).expect("chart");
    assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"));
}

/// `meshless study --knob solid-spacing` sweeps the cantilever: a finer
/// spacing gives a smaller deflection error against Euler–Bernoulli.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn solid_study_writes_the_cantilever_error() {
    let dir = TempDir::new("solid-study");
    meshless_ok(&[
        "study",
        "--knob",
        "solid-spacing",
        "--values",
        "0.025,0.0125",
        "--output",
        dir.0.to_str().expect("utf-8"),
    ])
    .await;
    let csv = std::fs::read_to_string(dir.0.join("study_solid_spacing.csv")).expect("csv");
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|r| r.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 2, "{csv}");
    let errors: Vec<f64> = rows
        .iter()
        .map(|r| {
            assert_eq!(r[9], "ok", "{r:?}");
            r[7].parse::<f64>().expect("an error").abs()
        })
        .collect();
    assert!(errors[1] < errors[0] && errors[1] < 0.2, "{errors:?}");
    let png = std::fs::read(dir.0.join("study_solid_spacing.png")).expect("chart");
    assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"));
}

/// `meshless optimise` on the shipped Figure 13 problem, embedded: the
/// column's designed surface and its design particles are written, and
/// the summary reports a converged solve with every energy term.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn optimise_writes_the_designed_surface() {
    let dir = TempDir::new("optimise");
    let problem = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/design_stretch.toml");
    let out = dir.0.join("design");
    let stdout = meshless_ok(&[
        "optimise",
        problem.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
    ])
    .await;
    assert_eq!(
        listing(&out),
        ["design_0000.obj", "design_particles_0000.vtk"],
        "{stdout}"
    );
    let obj = std::fs::read_to_string(out.join("design_0000.obj")).expect("the surface");
    let top = obj
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .filter_map(|v| v.split_whitespace().nth(2)?.parse::<f64>().ok())
        .fold(f64::MIN, f64::max);
    assert!(
        (top - 3.0).abs() < 0.1,
        "the column's top is lifted from 2 m to 3 m: {top}\n{stdout}"
    );
    for expected in ["converged", "handle", "volume", "total"] {
        assert!(stdout.contains(expected), "{expected} in\n{stdout}");
    }
}

/// `meshless study --knob design-particles` solves the Figure 13 stretch
/// and the passage: the volume is kept, the ball cleared, and each
/// experiment gets its chart.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn design_study_writes_both_experiments() {
    let dir = TempDir::new("design-study");
    meshless_ok(&[
        "study",
        "--knob",
        "design-particles",
        "--values",
        "stretch:120,passage:60",
        "--output",
        dir.0.to_str().expect("utf-8"),
    ])
    .await;
    let csv = std::fs::read_to_string(dir.0.join("study_design_particles.csv")).expect("csv");
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|r| r.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 2, "{csv}");
    let number = |row: &[&str], column: usize| -> f64 {
        row[column]
            .parse()
            .unwrap_or_else(|_| panic!("column {column} of {row:?}"))
    };
    let (stretch, passage) = (&rows[0], &rows[1]);
    assert_eq!((stretch[2], stretch[14]), ("stretch", "ok"), "{csv}");
    assert!(number(stretch, 7).abs() < 0.03, "volume change: {csv}");
    assert!(number(stretch, 8) < 0.1, "handle error: {csv}");
    assert_eq!((passage[2], passage[14]), ("passage", "ok"), "{csv}");
    // Sampling checks 10 times per interval against a 0.1-spacing
    // tolerance; the 201 times measured may find a little more.
    assert!(number(passage, 11) < 0.15, "penetration: {csv}");
    for chart in ["stretch", "passage"] {
        let png = std::fs::read(dir.0.join(format!("study_design_particles_{chart}.png")))
            .expect("chart");
        assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"));
    }
}
