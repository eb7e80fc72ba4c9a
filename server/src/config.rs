//! Server configuration: built-in defaults, then environment variables,
//! then command-line flags (clap resolves the layers), checked at start.

use crate::auth::Tokens;
use meshless_engine::scene::MeshFiles;
use meshless_engine::{Budget, BuildOptions, Cancel};
use std::net::SocketAddr;

/// How the server's zenoh session joins the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ZenohMode {
    /// Listens for and talks to other peers directly (the default: no
    /// router needed).
    Peer,
    /// Talks only through the routers in `--zenoh-connect`.
    Client,
}

impl ZenohMode {
    /// The mode's name as zenoh's `mode` setting spells it.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Peer => "peer",
            Self::Client => "client",
        }
    }
}

/// Who may publish on the session keys (`meshless/v1/sessions/**`)
/// through the server's zenoh session.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ZenohPublishers {
    /// Only the server: zenoh's access control drops every put, delete,
    /// queryable and reply that other peers send on any key, so no peer
    /// can forge a frame, a status or a latest-frame answer (the default).
    Server,
    /// Any peer: for a zenoh network whose router enforces its own access
    /// control, and for tests of the subscribers' own checks.
    Any,
}

/// Whether sessions seal what they put on zenoh (`meshless_proto::seal`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ZenohSealing {
    /// Seal when the server has tokens: sessions then have owners, and
    /// only the callers that may see a session get the key that opens
    /// its frames (the default). Without tokens every caller may see every
    /// session, and sealing would keep nobody out.
    Auto,
    /// Always seal.
    Always,
    /// Never seal: for a zenoh plane that no stranger reaches, to save
    /// the encryption (measured in docs/performance.md).
    Never,
}

/// When the viewer's listener runs (`--http-priority`,
/// `server/src/web/thread.rs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ViewerPriority {
    /// Only on CPU time the simulations leave (Linux's `SCHED_IDLE`): a
    /// busy host's sessions step as fast with pages watching them, and
    /// the pages get the frames the server has time for (the default).
    Idle,
    /// At the simulations' priority: the pages get every frame they can
    /// take, at the cost of the sessions' steps on a busy host.
    Normal,
}

/// Default of `--zenoh-accept-pending`: 4 times zenoh's own 100, so that
/// 300 silent connections (a port scan, a careless or hostile client) no
/// longer fill the queue, yet with `--max-connections` within the usual
/// limit of 1,024 file descriptors (each pending link holds one, and
/// nothing else until bytes arrive). docs/operations.md, "Zenoh limits".
pub const DEFAULT_ZENOH_ACCEPT_PENDING: usize = 400;
/// Default of `--zenoh-accept-timeout-ms`: half zenoh's own 10 s. A zenoh
/// handshake is two round trips (TLS is done before it counts), so this
/// covers a slow link on a loaded host while a silent connection gives
/// its place up twice as soon.
pub const DEFAULT_ZENOH_ACCEPT_TIMEOUT_MS: u64 = 5_000;

/// Default of `--max-particles`.
pub const DEFAULT_MAX_PARTICLES: u64 = 2_000_000;
/// Default of `--max-sessions`.
pub const DEFAULT_MAX_SESSIONS: u32 = 64;
/// Default cap on open gRPC connections: well under the usual limit of
/// 1,024 file descriptors, which zenoh and the sessions share.
pub const DEFAULT_MAX_CONNECTIONS: u32 = 512;
/// Default of `--max-request-mb`: room for a scene with a million
/// hand-placed particles.
pub const DEFAULT_MAX_REQUEST_MB: u32 = 64;
/// Default of `--max-mesh-mb`: a mesh of a few hundred thousand
/// triangles, far more than a body's sampling uses.
pub const DEFAULT_MAX_MESH_MB: u32 = 16;

/// Default of `--max-snapshot-mb`: a fluid of about 900,000 particles
/// (a 149,000-particle one takes 11 MB: docs/performance.md).
pub const DEFAULT_MAX_SNAPSHOT_MB: u32 = 64;
/// Default of `--checkpoint-interval`, seconds.
pub const DEFAULT_CHECKPOINT_INTERVAL: f64 = 60.0;
/// Default of `--handshake-timeout`, seconds: a client makes its first
/// call as soon as it connects, so ten seconds covers a slow link and a
/// TLS handshake.
pub const DEFAULT_HANDSHAKE_TIMEOUT: f64 = 10.0;
/// Default of `--idle-timeout`, seconds: a notebook left alone for five
/// minutes reconnects at its next call, at the cost of one round trip.
pub const DEFAULT_IDLE_TIMEOUT: f64 = 300.0;
/// Default of `--metrics-header-timeout`, seconds.
pub const DEFAULT_METRICS_HEADER_TIMEOUT: f64 = 10.0;

/// Everything the server needs to start.
#[derive(Debug, Clone, clap::Args)]
pub struct ServerConfig {
    /// Address of the gRPC endpoint; port 0 picks a free port.
    #[arg(long, env = "MESHLESS_GRPC_ADDR", default_value = "127.0.0.1:50051")]
    pub grpc_addr: SocketAddr,

    /// This server's name among its replicas: 1 to 40 lowercase letters,
    /// digits and `-`, starting with a letter (a DNS label, so that it can
    /// be the host name clients reach it by). Session ids it makes start
    /// with `NAME-`, so a client routes each call to the replica that holds
    /// the session, and the server announces itself by a zenoh liveliness
    /// token on `meshless/v1/servers/NAME`. Unset: plain ids, no token
    /// (a single server).
    #[arg(long, env = "MESHLESS_SERVER_NAME", value_parser = parse_server_name)]
    pub server_name: Option<String>,

    /// Zenoh mode of the server's session.
    #[arg(long, env = "MESHLESS_ZENOH_MODE", value_enum, default_value = "peer")]
    pub zenoh_mode: ZenohMode,

    /// Zenoh endpoints to listen on (peer mode), comma separated, `tcp/`
    /// or `tls/` (whose certificate `--zenoh-config` names); port 0 picks
    /// a free port.
    #[arg(
        long,
        env = "MESHLESS_ZENOH_LISTEN",
        value_delimiter = ',',
        default_value = "tcp/127.0.0.1:7447"
    )]
    pub zenoh_listen: Vec<String>,

    /// Zenoh endpoints to connect to, e.g. a router at `tcp/zenohd:7447`.
    #[arg(long, env = "MESHLESS_ZENOH_CONNECT", value_delimiter = ',')]
    pub zenoh_connect: Vec<String>,

    /// A zenoh configuration file (JSON5, zenoh's own format) the
    /// server's session starts from: TLS certificates for `tls/`
    /// endpoints, user-password authentication, anything zenoh offers.
    /// The flags above and `--zenoh-publishers` are set over it.
    #[arg(long, env = "MESHLESS_ZENOH_CONFIG")]
    pub zenoh_config: Option<std::path::PathBuf>,

    /// Who may publish on the session keys through the server's zenoh
    /// session.
    #[arg(
        long,
        env = "MESHLESS_ZENOH_PUBLISHERS",
        value_enum,
        default_value = "server"
    )]
    pub zenoh_publishers: ZenohPublishers,

    /// Whether sessions seal their frames, status changes and latest-frame
    /// replies with a key that only the callers who may see them receive
    /// (`Session.seal_key`).
    #[arg(
        long,
        env = "MESHLESS_ZENOH_SEALING",
        value_enum,
        default_value = "auto"
    )]
    pub zenoh_sealing: ZenohSealing,

    /// Most incoming zenoh links in their handshake at once (zenoh's
    /// `transport/unicast/accept_pending`); a link beyond them is closed
    /// at once, so a subscriber is refused while this many connections
    /// stay silent. Set over `--zenoh-config`.
    #[arg(long, env = "MESHLESS_ZENOH_ACCEPT_PENDING", default_value_t = DEFAULT_ZENOH_ACCEPT_PENDING)]
    pub zenoh_accept_pending: usize,

    /// Milliseconds an incoming zenoh link may take over its handshake
    /// before it is closed and gives its place up (zenoh's
    /// `transport/unicast/accept_timeout`). Set over `--zenoh-config`.
    #[arg(long, env = "MESHLESS_ZENOH_ACCEPT_TIMEOUT_MS", default_value_t = DEFAULT_ZENOH_ACCEPT_TIMEOUT_MS)]
    pub zenoh_accept_timeout_ms: u64,

    /// The gRPC endpoint's certificate chain (PEM); with `--tls-key` the
    /// endpoint speaks only TLS (clients use `https://`).
    #[arg(long, env = "MESHLESS_TLS_CERT", requires = "tls_key")]
    pub tls_cert: Option<std::path::PathBuf>,

    /// The private key of `--tls-cert` (PEM).
    #[arg(long, env = "MESHLESS_TLS_KEY", requires = "tls_cert")]
    pub tls_key: Option<std::path::PathBuf>,

    /// A CA (PEM) whose certificate every client must present (mutual
    /// TLS); needs `--tls-cert`.
    #[arg(long, env = "MESHLESS_TLS_CLIENT_CA", requires = "tls_cert")]
    pub tls_client_ca: Option<std::path::PathBuf>,

    /// Largest particle count one session may create.
    #[arg(long, env = "MESHLESS_MAX_PARTICLES", default_value_t = DEFAULT_MAX_PARTICLES)]
    pub max_particles: u64,

    /// Largest number of sessions held at once.
    #[arg(long, env = "MESHLESS_MAX_SESSIONS", default_value_t = DEFAULT_MAX_SESSIONS)]
    pub max_sessions: u32,

    /// Most gRPC connections open at once; more wait in the kernel's
    /// backlog until one closes.
    #[arg(long, env = "MESHLESS_MAX_CONNECTIONS", default_value_t = DEFAULT_MAX_CONNECTIONS)]
    pub max_connections: u32,

    /// Seconds, in [0.1, 3600], within which a gRPC connection must make
    /// a call that passes the token check, or be closed: a connection
    /// earns its place under `--max-connections` by a call, not by bytes.
    #[arg(long, env = "MESHLESS_HANDSHAKE_TIMEOUT", default_value_t = DEFAULT_HANDSHAKE_TIMEOUT)]
    pub handshake_timeout: f64,

    /// Seconds, in [0.1, 86400], after which a gRPC connection with no
    /// call in flight is closed (clients reconnect at their next call).
    #[arg(long, env = "MESHLESS_IDLE_TIMEOUT", default_value_t = DEFAULT_IDLE_TIMEOUT)]
    pub idle_timeout: f64,

    /// Largest request, in MB; larger ones are RESOURCE_EXHAUSTED before
    /// they are decoded.
    #[arg(long, env = "MESHLESS_MAX_REQUEST_MB", default_value_t = DEFAULT_MAX_REQUEST_MB)]
    pub max_request_mb: u32,

    /// A file of `NAME TOKEN` lines: the principals that may call and
    /// their bearer tokens. Unset: no authentication, which is allowed
    /// only on a loopback `--grpc-addr` (everyone is `anonymous`).
    #[arg(long, env = "MESHLESS_TOKENS_FILE")]
    pub tokens_file: Option<std::path::PathBuf>,

    /// A directory of mesh files that scenes may name by a relative path
    /// (`shape = { type = "mesh", path = "..." }`); nothing outside it is
    /// read, links out of it included. Unset: the server reads no mesh
    /// file, and clients send meshes' bytes in the scene.
    #[arg(long, env = "MESHLESS_MESH_DIR")]
    pub mesh_dir: Option<std::path::PathBuf>,

    /// Largest mesh, sent or read from the mesh directory, in MB.
    #[arg(long, env = "MESHLESS_MAX_MESH_MB", default_value_t = DEFAULT_MAX_MESH_MB)]
    pub max_mesh_mb: u32,

    /// Memory all sessions together may hold, in MB, by each scene's
    /// estimate (`Scene::check`) before it is built. Unset: half of
    /// this host's physical memory.
    #[arg(long, env = "MESHLESS_MEMORY_BUDGET_MB")]
    pub memory_budget_mb: Option<u64>,

    /// Address of the Prometheus metrics endpoint (`GET /metrics`); port
    /// 0 picks a free port. Unset: no endpoint.
    #[arg(long, env = "MESHLESS_METRICS_ADDR")]
    pub metrics_addr: Option<SocketAddr>,

    /// Address of the browser viewer: the page, its scripts, and the
    /// service itself as gRPC-web, with the same token check and access
    /// rules (docs/viewer.md); port 0 picks a free port. Unset: no viewer.
    #[arg(long, env = "MESHLESS_HTTP_ADDR")]
    pub http_addr: Option<SocketAddr>,

    /// When the viewer's listener runs: `idle`, only on CPU time the
    /// simulations leave (a busy host's sessions step as fast with pages
    /// watching; the pages skip the frames it has no time for), or
    /// `normal`, at the simulations' priority. Linux only.
    #[arg(
        long,
        env = "MESHLESS_HTTP_PRIORITY",
        value_enum,
        default_value = "idle"
    )]
    pub http_priority: ViewerPriority,

    /// Seconds, in [0.1, 3600], within which a metrics request's headers
    /// must arrive, counted from the connection's start or its previous
    /// answer; slower connections are closed.
    #[arg(
        long,
        env = "MESHLESS_METRICS_HEADER_TIMEOUT",
        default_value_t = DEFAULT_METRICS_HEADER_TIMEOUT
    )]
    pub metrics_header_timeout: f64,

    /// Largest snapshot blob, in MB: Snapshot refuses to make a larger
    /// one and Restore to read one; the response limit grows to hold one,
    /// while a Restore request must also fit `--max-request-mb`.
    #[arg(long, env = "MESHLESS_MAX_SNAPSHOT_MB", default_value_t = DEFAULT_MAX_SNAPSHOT_MB)]
    pub max_snapshot_mb: u32,

    /// A directory for checkpoints: every session's snapshot, written
    /// every `--checkpoint-interval`, and restored (ids and owners kept)
    /// when the server starts. Unset: no checkpoints.
    #[arg(long, env = "MESHLESS_CHECKPOINT_DIR")]
    pub checkpoint_dir: Option<std::path::PathBuf>,

    /// Seconds between checkpoints, in [0.1, 86400]: at most this much of
    /// a session's work is lost in a crash.
    #[arg(long, env = "MESHLESS_CHECKPOINT_INTERVAL", default_value_t = DEFAULT_CHECKPOINT_INTERVAL)]
    pub checkpoint_interval: f64,
}

/// Longest `--server-name`: with `-` and the 16 hex digits of a session's
/// own part, an id stays within the 64 characters ids may have.
pub const MAX_SERVER_NAME_LEN: usize = 40;

/// Checks a `--server-name`: a DNS label of at most
/// [`MAX_SERVER_NAME_LEN`] characters that starts with a letter.
///
/// # Errors
/// A message saying what the name may hold.
pub fn parse_server_name(name: &str) -> Result<String, String> {
    let fine = name.len() <= MAX_SERVER_NAME_LEN
        && name.starts_with(|c: char| c.is_ascii_lowercase())
        && !name.ends_with('-')
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-');
    if fine {
        Ok(name.to_owned())
    } else {
        Err(format!(
            "a server name is 1 to {MAX_SERVER_NAME_LEN} lowercase letters, digits and '-', \
             starting with a letter and not ending with '-' (a DNS label)"
        ))
    }
}

/// The budget when physical memory cannot be read (not Linux).
const FALLBACK_BUDGET_BYTES: u64 = 4 << 30;

impl ServerConfig {
    /// The largest request in bytes.
    pub fn max_request_bytes(&self) -> usize {
        (self.max_request_mb as usize).saturating_mul(1 << 20)
    }

    /// The largest snapshot in bytes.
    pub fn max_snapshot_bytes(&self) -> usize {
        (self.max_snapshot_mb as usize).saturating_mul(1 << 20)
    }

    /// The checkpoint interval.
    pub fn checkpoint_period(&self) -> std::time::Duration {
        std::time::Duration::from_secs_f64(self.checkpoint_interval)
    }

    /// `--handshake-timeout` as a duration.
    pub fn handshake_period(&self) -> std::time::Duration {
        std::time::Duration::from_secs_f64(self.handshake_timeout)
    }

    /// `--idle-timeout` as a duration.
    pub fn idle_period(&self) -> std::time::Duration {
        std::time::Duration::from_secs_f64(self.idle_timeout)
    }

    /// `--metrics-header-timeout` as a duration.
    pub fn metrics_header_period(&self) -> std::time::Duration {
        std::time::Duration::from_secs_f64(self.metrics_header_timeout)
    }

    /// What scenes may build: the particle limit, the mesh directory (or
    /// none) and the mesh size limit.
    pub fn build_options(&self) -> BuildOptions {
        BuildOptions {
            max_particles: self.max_particles,
            mesh_files: match &self.mesh_dir {
                Some(dir) => MeshFiles::Directory(dir.clone()),
                None => MeshFiles::None,
            },
            max_mesh_bytes: u64::from(self.max_mesh_mb) << 20,
            cancel: Cancel::new(),
            budget: Budget::default(),
        }
    }

    /// The tokens the server accepts; `None` without a tokens file.
    ///
    /// # Errors
    /// An unreadable or malformed file, or no file on an address other
    /// than loopback: a server reachable from elsewhere never runs open.
    pub fn tokens(&self) -> Result<Option<Tokens>, String> {
        match &self.tokens_file {
            Some(path) => Tokens::from_file(path).map(Some),
            None if self.grpc_addr.ip().is_loopback() => Ok(None),
            None => Err(format!(
                "--grpc-addr {} is reachable from other hosts, so the server needs tokens: \
                 give --tokens-file (MESHLESS_TOKENS_FILE), or bind to 127.0.0.1",
                self.grpc_addr
            )),
        }
    }

    /// Whether sessions seal their zenoh payloads, given whether the
    /// server has tokens.
    pub fn seals(&self, has_tokens: bool) -> bool {
        match self.zenoh_sealing {
            ZenohSealing::Auto => has_tokens,
            ZenohSealing::Always => true,
            ZenohSealing::Never => false,
        }
    }

    /// The gRPC endpoint's TLS configuration; `None` without `--tls-cert`.
    ///
    /// # Errors
    /// A missing, unreadable or malformed file, named by its flag.
    pub fn grpc_tls(&self) -> Result<Option<tonic::transport::ServerTlsConfig>, String> {
        match (&self.tls_cert, &self.tls_key) {
            (Some(cert), Some(key)) => crate::tls::server_config(
                crate::tls::TlsFiles {
                    cert,
                    key,
                    client_ca: self.tls_client_ca.as_deref(),
                },
                self.handshake_period(),
            )
            .map(Some),
            (None, None) if self.tls_client_ca.is_some() => {
                Err("--tls-client-ca needs --tls-cert and --tls-key".into())
            }
            (None, None) => Ok(None),
            _ => Err("--tls-cert and --tls-key go together: give both or neither".into()),
        }
    }

    /// The memory budget in bytes: the configured one, or half of the
    /// host's physical memory (`MemTotal` of `/proc/meminfo`).
    pub fn memory_budget_bytes(&self) -> u64 {
        if let Some(mb) = self.memory_budget_mb {
            return mb.saturating_mul(1 << 20);
        }
        std::fs::read_to_string("/proc/meminfo")
            .ok()
            .and_then(|info| {
                let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
                let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
                Some(kib.saturating_mul(1024) / 2)
            })
            .unwrap_or(FALLBACK_BUDGET_BYTES)
    }

    /// A server on loopback with free ports for gRPC and zenoh: what the
    /// embedded `meshless demo` and tests use.
    pub fn ephemeral() -> Self {
        Self {
            grpc_addr: SocketAddr::from(([127, 0, 0, 1], 0)),
            server_name: None,
            zenoh_mode: ZenohMode::Peer,
            zenoh_listen: vec!["tcp/127.0.0.1:0".into()],
            zenoh_connect: Vec::new(),
            zenoh_config: None,
            zenoh_publishers: ZenohPublishers::Server,
            zenoh_sealing: ZenohSealing::Auto,
            zenoh_accept_pending: DEFAULT_ZENOH_ACCEPT_PENDING,
            zenoh_accept_timeout_ms: DEFAULT_ZENOH_ACCEPT_TIMEOUT_MS,
            tls_cert: None,
            tls_key: None,
            tls_client_ca: None,
            max_particles: DEFAULT_MAX_PARTICLES,
            max_sessions: DEFAULT_MAX_SESSIONS,
            max_connections: DEFAULT_MAX_CONNECTIONS,
            handshake_timeout: DEFAULT_HANDSHAKE_TIMEOUT,
            idle_timeout: DEFAULT_IDLE_TIMEOUT,
            max_request_mb: DEFAULT_MAX_REQUEST_MB,
            tokens_file: None,
            mesh_dir: None,
            max_mesh_mb: DEFAULT_MAX_MESH_MB,
            memory_budget_mb: None,
            metrics_addr: None,
            http_addr: None,
            http_priority: ViewerPriority::Idle,
            metrics_header_timeout: DEFAULT_METRICS_HEADER_TIMEOUT,
            max_snapshot_mb: DEFAULT_MAX_SNAPSHOT_MB,
            checkpoint_dir: None,
            checkpoint_interval: DEFAULT_CHECKPOINT_INTERVAL,
        }
    }

    /// Checks combinations that clap cannot.
    ///
    /// # Errors
    /// A message naming the flag to change.
    pub fn validate(&self) -> Result<(), String> {
        if self.zenoh_mode == ZenohMode::Client && self.zenoh_connect.is_empty() {
            return Err("--zenoh-mode client needs at least one --zenoh-connect endpoint".into());
        }
        if self.max_particles == 0 {
            return Err("--max-particles must be at least 1".into());
        }
        if self.zenoh_accept_pending == 0 {
            return Err("--zenoh-accept-pending must be at least 1".into());
        }
        if !(100..=600_000).contains(&self.zenoh_accept_timeout_ms) {
            return Err(format!(
                "--zenoh-accept-timeout-ms must be in [100, 600000] ms, got {}",
                self.zenoh_accept_timeout_ms
            ));
        }
        if self.max_sessions == 0 {
            return Err("--max-sessions must be at least 1".into());
        }
        if self.max_request_mb == 0 {
            return Err("--max-request-mb must be at least 1".into());
        }
        if self.max_connections == 0 {
            return Err("--max-connections must be at least 1".into());
        }
        if self.max_mesh_mb == 0 {
            return Err("--max-mesh-mb must be at least 1".into());
        }
        if let Some(dir) = &self.mesh_dir
            && !dir.is_dir()
        {
            return Err(format!(
                "--mesh-dir {} is not a directory this server can read",
                dir.display()
            ));
        }
        if self.max_snapshot_mb == 0 {
            return Err("--max-snapshot-mb must be at least 1".into());
        }
        if !(0.1..=86_400.0).contains(&self.checkpoint_interval) {
            return Err(format!(
                "--checkpoint-interval must be in [0.1, 86400] seconds, got {}",
                self.checkpoint_interval
            ));
        }
        for (flag, value, most) in [
            ("--handshake-timeout", self.handshake_timeout, 3_600.0),
            ("--idle-timeout", self.idle_timeout, 86_400.0),
            (
                "--metrics-header-timeout",
                self.metrics_header_timeout,
                3_600.0,
            ),
        ] {
            if !(0.1..=most).contains(&value) {
                return Err(format!(
                    "{flag} must be in [0.1, {most}] seconds, got {value}"
                ));
            }
        }
        if self.memory_budget_mb == Some(0) {
            return Err("--memory-budget-mb must be at least 1".into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn server_names_are_dns_labels_that_fit_in_an_id() {
        for fine in [
            "a",
            "meshless-0",
            "server-2b",
            &"s".repeat(MAX_SERVER_NAME_LEN),
        ] {
            assert_eq!(parse_server_name(fine).as_deref(), Ok(fine));
        }
        for bad in [
            "",
            "0server",
            "-a",
            "a-",
            "Server",
            "a_b",
            "a.b",
            "a/b",
            &"s".repeat(MAX_SERVER_NAME_LEN + 1),
        ] {
            let error = parse_server_name(bad).expect_err(bad);
            assert!(error.contains("DNS label"), "{error}");
        }
    }
}
