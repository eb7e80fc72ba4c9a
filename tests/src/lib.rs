//! Harness for the end-to-end tests: the real `meshless-server` binary on
//! free loopback ports, and timeouts around every wait.

use anyhow::{Context, Result, bail};
use meshless_client::{Client, ClientError};
use std::future::Future;
use std::path::PathBuf;
use std::process::{ExitStatus, Stdio};
use std::time::Duration;
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::{Child, Command};

pub mod pki;
pub mod raw_h2;

/// Upper bound on any single wait in a test.
pub const TIMEOUT: Duration = Duration::from_secs(30);

/// Awaits `future`, failing the test with `what` if it takes longer than
/// [`TIMEOUT`].
pub async fn within<T>(what: &str, future: impl Future<Output = T>) -> T {
    match tokio::time::timeout(TIMEOUT, future).await {
        Ok(value) => value,
        Err(_) => panic!("timed out after {TIMEOUT:?} waiting for {what}"),
    }
}

/// A fixture scene shared by the Rust and Python tests:
/// `tests/fixtures/NAME.toml`, as TOML text.
///
/// # Panics
/// When the fixture is missing: a broken checkout, not a test result.
pub fn fixture(name: &str) -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(format!("{name}.toml"));
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A small fluid scene (125 particles) as TOML, frames every step
/// (`tests/fixtures/small_tank.toml`).
pub fn small_scene() -> String {
    fixture("small_tank")
}

/// A small elastic solid (a 0.2 x 0.2 x 0.4 m box, 128 particles, centred
/// at (0.5, 0.5, 0.5)) as TOML, frames every step: the object of the
/// design tests (`tests/fixtures/small_column.toml`).
pub fn small_solid_scene() -> String {
    fixture("small_column")
}

/// The gRPC status of a refused call.
///
/// # Panics
/// When the call failed some other way (a transport or decoding error).
pub fn rpc_status(error: ClientError) -> tonic::Status {
    match error {
        ClientError::Rpc(status) => status,
        other => panic!("expected a gRPC status, got {other}"),
    }
}

/// A small modal EFG cantilever (12 modes), clamped at x = 0, frames every
/// step (`tests/fixtures/small_modal.toml`).
pub fn small_modal_scene() -> String {
    fixture("small_modal")
}

/// A small thin shell: a 40 x 20 cm plate clamped along x = 0, frames
/// every step (`tests/fixtures/small_shell.toml`).
pub fn small_shell_scene() -> String {
    fixture("small_shell")
}

/// Where cargo put one of the workspace's binaries (`meshless-server`,
/// `meshless`): beside this test executable's `deps/` folder.
///
/// # Errors
/// When the binary has not been built.
pub fn binary(name: &str) -> Result<PathBuf> {
    let exe = std::env::current_exe()?;
    let profile_dir = exe
        .parent()
        .and_then(|deps| deps.parent())
        .context("test executable has no target folder")?;
    let binary = profile_dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    if !binary.exists() {
        bail!(
            "{} does not exist: build the binaries first with `cargo build --workspace --bins` \
             (scripts/test does)",
            binary.display()
        );
    }
    Ok(binary)
}

/// How to start a server beyond its flags.
#[derive(Debug, Default, Clone)]
pub struct Launch<'a> {
    /// Environment variables (settings as `MESHLESS_*`, which a server
    /// that lacks a setting ignores, so a test runs unchanged against an
    /// older binary).
    pub env: &'a [(&'a str, &'a str)],
    /// The server's limit on open file descriptors (`ulimit -n`).
    pub fd_limit: Option<u32>,
    /// A file for the server's log (stderr), for a test that reads what
    /// it said; by default the test's own stderr.
    pub log: Option<&'a std::path::Path>,
}

/// A `meshless-server` child process, killed when dropped.
#[derive(Debug)]
pub struct ServerProcess {
    child: Child,
    /// `http://127.0.0.1:PORT` (a server with TLS answers on the same
    /// port as `https://localhost:PORT`).
    pub grpc_url: String,
    /// The zenoh endpoints it listens on.
    pub zenoh: Vec<String>,
    /// `http://ADDR/metrics`, when it serves metrics (`--metrics-addr`).
    pub metrics_url: Option<String>,
    /// `ADDR` (`127.0.0.1:PORT`) of the browser viewer's listener, when it
    /// serves one (`--http-addr`).
    pub http_addr: Option<String>,
}

impl ServerProcess {
    /// Starts the server on free ports with extra flags, and waits for its
    /// ready line.
    ///
    /// # Errors
    /// When the binary is missing or the server does not come up.
    pub async fn spawn(extra_args: &[&str]) -> Result<Self> {
        Self::spawn_listening("tcp/127.0.0.1:0", extra_args).await
    }

    /// [`ServerProcess::spawn`] with zenoh listening on `zenoh_listen`
    /// alone (e.g. `tls/127.0.0.1:0`).
    ///
    /// # Errors
    /// As [`ServerProcess::spawn`].
    pub async fn spawn_listening(zenoh_listen: &str, extra_args: &[&str]) -> Result<Self> {
        Self::launch(zenoh_listen, extra_args, &Launch::default()).await
    }

    /// [`ServerProcess::spawn`] with `launch`'s environment and limits.
    ///
    /// # Errors
    /// As [`ServerProcess::spawn`].
    pub async fn spawn_launched(extra_args: &[&str], launch: &Launch<'_>) -> Result<Self> {
        Self::launch("tcp/127.0.0.1:0", extra_args, launch).await
    }

    /// [`ServerProcess::spawn`] with its log (stderr, warnings and up)
    /// written to the file `log`, for a test that reads what it said.
    ///
    /// # Errors
    /// As [`ServerProcess::spawn`], and a log file that cannot be made.
    pub async fn spawn_logging(extra_args: &[&str], log: &std::path::Path) -> Result<Self> {
        let launch = Launch {
            log: Some(log),
            ..Launch::default()
        };
        Self::launch("tcp/127.0.0.1:0", extra_args, &launch).await
    }

    async fn launch(zenoh_listen: &str, extra_args: &[&str], launch: &Launch<'_>) -> Result<Self> {
        let server = binary("meshless-server")?;
        let stderr = match launch.log {
            Some(log) => {
                Stdio::from(std::fs::File::create(log).context("cannot create the log file")?)
            }
            None => Stdio::inherit(),
        };
        let mut command = match launch.fd_limit {
            // The shell lowers its own limit, then becomes the server.
            Some(limit) => {
                let mut shell = Command::new("sh");
                shell
                    .arg("-c")
                    .arg(format!("ulimit -n {limit} && exec \"$0\" \"$@\""))
                    .arg(server);
                shell
            }
            None => Command::new(server),
        };
        let mut child = command
            .args(["--grpc-addr", "127.0.0.1:0", "--zenoh-listen", zenoh_listen])
            .args(extra_args)
            .envs(launch.env.iter().copied())
            .env("MESHLESS_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(stderr)
            .kill_on_drop(true)
            .spawn()
            .context("cannot start meshless-server")?;
        let stdout = child.stdout.take().context("no stdout")?;
        let mut lines = BufReader::new(stdout).lines();
        let ready = tokio::time::timeout(TIMEOUT, async {
            while let Some(line) = lines.next_line().await? {
                if let Some(rest) = line.strip_prefix("meshless-server ready ") {
                    return Ok::<_, std::io::Error>(Some(rest.to_owned()));
                }
            }
            Ok(None)
        })
        .await
        .context("the server did not print its ready line in time")??
        .context("the server exited before it was ready")?;
        // Keep draining stdout so the child never blocks on a full pipe.
        tokio::spawn(async move { while let Ok(Some(_)) = lines.next_line().await {} });
        let mut grpc_url = None;
        let mut zenoh = Vec::new();
        let mut metrics_url = None;
        let mut http_addr = None;
        for part in ready.split_whitespace() {
            if let Some(addr) = part.strip_prefix("grpc=") {
                grpc_url = Some(format!("http://{addr}"));
            } else if let Some(endpoints) = part.strip_prefix("zenoh=") {
                zenoh = endpoints.split(',').map(str::to_owned).collect();
            } else if let Some(addr) = part.strip_prefix("metrics=") {
                metrics_url = Some(format!("http://{addr}/metrics"));
            } else if let Some(addr) = part.strip_prefix("http=") {
                http_addr = Some(addr.to_owned());
            }
        }
        Ok(Self {
            child,
            grpc_url: grpc_url.context("ready line without grpc=")?,
            zenoh,
            metrics_url,
            http_addr,
        })
    }

    /// A gRPC client of this server.
    ///
    /// # Errors
    /// When the connection fails.
    pub async fn client(&self) -> Result<Client> {
        Ok(within("gRPC connect", Client::connect(&self.grpc_url)).await?)
    }

    /// The server's process id, while it runs.
    pub fn pid(&self) -> Option<u32> {
        self.child.id()
    }

    /// A gRPC client of this server that calls as `identity`.
    ///
    /// # Errors
    /// When the connection fails.
    pub async fn client_as(&self, identity: &meshless_client::Identity) -> Result<Client> {
        Ok(within("gRPC connect", Client::connect_as(&self.grpc_url, identity)).await?)
    }

    /// Kills the process with SIGKILL (no shutdown of any kind: a crash)
    /// and waits for it to be gone.
    ///
    /// # Errors
    /// When the process cannot be killed.
    pub async fn kill(mut self) -> Result<ExitStatus> {
        within("server kill", self.child.kill()).await?;
        Ok(within("server exit after SIGKILL", self.child.wait()).await?)
    }

    /// Sends SIGTERM and waits for the process to exit.
    ///
    /// # Errors
    /// When the signal cannot be sent or the process does not exit.
    pub async fn terminate(mut self) -> Result<ExitStatus> {
        let pid = self.child.id().context("the server already exited")?;
        let sent = Command::new("kill")
            .args(["-TERM", &pid.to_string()])
            .status()
            .await?;
        if !sent.success() {
            bail!("kill -TERM {pid} failed");
        }
        Ok(within("server exit after SIGTERM", self.child.wait()).await?)
    }
}

/// Resident memory of process `pid`, bytes (`VmRSS`).
///
/// # Panics
/// When the process has no `/proc` entry (it is gone).
pub fn resident_bytes(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("proc status");
    let line = status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))
        .expect("VmRSS");
    let kib: u64 = line
        .split_whitespace()
        .nth(1)
        .and_then(|v| v.parse().ok())
        .expect("a number");
    kib * 1024
}

/// Runs `meshless-server` with `args` (on free ports) and waits, within
/// [`TIMEOUT`], for it to exit: for a start that must fail fast. Returns
/// whether it succeeded and its stderr. A server that hangs instead is
/// killed and fails the test.
///
/// # Panics
/// When the binary is missing or the server does not exit in time.
pub async fn failed_start(args: &[&str]) -> (bool, String) {
    let output = within(
        "the server to exit",
        Command::new(binary("meshless-server").expect("built"))
            .args([
                "--grpc-addr",
                "127.0.0.1:0",
                "--zenoh-listen",
                "tcp/127.0.0.1:0",
            ])
            .args(args)
            .stdin(Stdio::null())
            .kill_on_drop(true)
            .output(),
    )
    .await
    .expect("it runs");
    (
        output.status.success(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

/// `blob` (a snapshot of this build) with its payload altered by `alter`
/// and its checksum recomputed: a forgery, which the checksum (there to
/// catch corruption) cannot tell from a snapshot the server wrote.
///
/// # Panics
/// When `blob` is not a snapshot of this build.
pub fn forge(
    blob: &[u8],
    alter: impl FnOnce(&mut meshless_client::v1::SnapshotPayload),
) -> Vec<u8> {
    let mut payload = meshless_proto::snapshot::decode(blob, usize::MAX).expect("a snapshot");
    alter(&mut payload);
    meshless_proto::snapshot::encode(&payload)
}

/// The fluid of a snapshot's payload, to alter (the first system that is
/// one).
///
/// # Panics
/// When the payload holds no fluid.
pub fn fluid_of(
    payload: &mut meshless_client::v1::SnapshotPayload,
) -> &mut meshless_client::v1::FluidSnapshot {
    use meshless_client::v1::system_snapshot::Kind;
    payload
        .world
        .as_mut()
        .expect("a world")
        .systems
        .iter_mut()
        .find_map(|s| match s.kind.as_mut() {
            Some(Kind::Fluid(fluid)) => Some(fluid),
            _ => None,
        })
        .expect("a fluid")
}

/// Makes a FIFO at `path` (with `mkfifo`).
///
/// # Panics
/// When it cannot be made.
pub fn make_fifo(path: &std::path::Path) {
    let made = std::process::Command::new("mkfifo").arg(path).status();
    assert!(made.is_ok_and(|s| s.success()), "mkfifo {}", path.display());
}

/// A temporary directory, removed when dropped.
#[derive(Debug)]
pub struct TempDir(pub PathBuf);

impl TempDir {
    /// An empty directory `meshless-{name}-{pid}` under the system's
    /// temporary directory.
    ///
    /// # Panics
    /// When it cannot be created.
    pub fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("meshless-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        Self(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A shipped mesh, `scenes/meshes/{name}`.
pub fn shipped_mesh(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes/meshes")
        .join(name)
}

/// A server mesh directory, `{root}/meshes`, laid out as a hostile client
/// would wish: `ball.obj` (a good mesh), and three traps, `out.obj` (a
/// link to `{root}/secret.obj`, outside it), `zero.obj` (a link to
/// `/dev/zero`) and `fifo.obj` (a FIFO).
///
/// # Panics
/// When the files, links or FIFO cannot be made.
pub fn hostile_mesh_dir(name: &str) -> TempDir {
    let dir = TempDir::new(name);
    let meshes = dir.0.join("meshes");
    std::fs::create_dir_all(&meshes).expect("mesh dir");
    let ball = shipped_mesh("icosphere.obj");
    std::fs::copy(&ball, meshes.join("ball.obj")).expect("copy");
    std::fs::copy(&ball, dir.0.join("secret.obj")).expect("copy");
    std::os::unix::fs::symlink(dir.0.join("secret.obj"), meshes.join("out.obj")).expect("link");
    std::os::unix::fs::symlink("/dev/zero", meshes.join("zero.obj")).expect("link");
    let made = std::process::Command::new("mkfifo")
        .arg(meshes.join("fifo.obj"))
        .status();
    assert!(made.is_ok_and(|s| s.success()), "mkfifo");
    dir
}

/// An edit adding obstacle `name` whose shape is the mesh at `path`,
/// standing at the origin.
pub fn mesh_obstacle(name: &str, path: &str) -> meshless_client::v1::ConstraintEdit {
    use meshless_client::v1;
    v1::ConstraintEdit {
        edit: Some(v1::constraint_edit::Edit::Add(v1::Constraint {
            name: name.into(),
            kind: Some(v1::constraint::Kind::Obstacle(v1::ObstacleConstraint {
                shape: Some(v1::Shape {
                    kind: Some(v1::shape::Kind::Mesh(v1::MeshShape {
                        path: path.into(),
                        scale: None,
                        data: None,
                    })),
                }),
                orientation: None,
                path: vec![v1::Waypoint {
                    time: 0.0,
                    position: Some(v1::Vec3 {
                        x: 0.0,
                        y: 0.0,
                        z: 0.0,
                    }),
                }],
            })),
        })),
    }
}
