//! # meshless-server
//!
//! Hosts simulation sessions behind the `meshless.v1.Simulation` gRPC
//! service. Each session steps its world on its own thread; frames and
//! status go out over zenoh. Tokio threads only do I/O.
//!
//! [`start`] runs a server inside any tokio program (the `meshless demo`
//! command and the tests do); the `meshless-server` binary wraps it with
//! signal handling.

mod auth;
mod checkpoint;
mod codes;
pub mod config;
pub mod config_file;
mod connection;
mod error;
mod files;
mod listener;
mod metrics;
mod metrics_http;
mod metrics_layer;
mod metrics_live;
mod pubsub;
mod registry;
mod service;
mod session;
mod tls;
mod web;

pub use config::{ServerConfig, ZenohMode, ZenohPublishers};
/// A frame as a session encodes it once for all its readers (public for
/// the load bench, which measures it against encoding per reader).
pub use session::EncodedFrame;

use anyhow::{Context, Result};
use meshless_proto::v1::{self, simulation_server::SimulationServer};
use registry::Registry;
use service::SimulationService;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio_util::sync::CancellationToken;

/// Largest gRPC response: a frame of a few million particles.
const MAX_RESPONSE_BYTES: usize = 64 * 1024 * 1024;

/// Longest the last checkpoint round of a shutdown may take.
const LAST_ROUND_TIMEOUT: Duration = Duration::from_secs(20);

/// Longest the viewer's listener may take to stop once the sessions are
/// gone.
const VIEWER_STOP_TIMEOUT: Duration = Duration::from_secs(5);

/// Room around a snapshot blob in the messages that carry one.
const SNAPSHOT_ENVELOPE: usize = 1 << 20;

/// How often an idle connection is pinged (HTTP/2 PING), so that a peer
/// that vanished without closing is noticed.
const KEEPALIVE_INTERVAL: Duration = Duration::from_secs(30);

/// How long a ping may go unanswered before the connection is closed.
const KEEPALIVE_TIMEOUT: Duration = Duration::from_secs(10);

/// A server started by [`start`].
#[derive(Debug)]
pub struct RunningServer {
    /// The bound gRPC address (the real port when 0 was asked for).
    pub grpc_addr: SocketAddr,
    /// The zenoh endpoints the server listens on.
    pub zenoh_locators: Vec<String>,
    /// The bound metrics address, when the server serves metrics.
    pub metrics_addr: Option<SocketAddr>,
    /// The bound address of the browser viewer, when the server serves it.
    pub http_addr: Option<SocketAddr>,
    shutdown: CancellationToken,
    task: tokio::task::JoinHandle<Result<()>>,
}

impl RunningServer {
    /// Stops accepting requests, stops every session, closes zenoh.
    ///
    /// # Errors
    /// Whatever the serving task failed with.
    pub async fn stop(self) -> Result<()> {
        self.shutdown.cancel();
        self.task.await.context("server task")?
    }
}

/// Binds the gRPC port, opens zenoh and serves until [`RunningServer::stop`].
///
/// # Errors
/// An invalid configuration or a port that cannot be bound.
pub async fn start(config: ServerConfig) -> Result<RunningServer> {
    config.validate().map_err(anyhow::Error::msg)?;
    let tokens = config.tokens().map_err(anyhow::Error::msg)?;
    match &tokens {
        Some(tokens) => tracing::info!(
            principals = ?tokens.principals().collect::<Vec<_>>(),
            "callers need a token"
        ),
        None => tracing::warn!(
            "no --tokens-file: every caller on this loopback address is `anonymous` \
             and may drive every session"
        ),
    }
    let tls = config.grpc_tls().map_err(anyhow::Error::msg)?;
    let viewer_tls = tls.clone();
    let tokenless = tokens.is_none();
    if tls.is_none() && !config.grpc_addr.ip().is_loopback() {
        tracing::warn!(
            grpc_addr = %config.grpc_addr,
            "gRPC without TLS on an address other hosts reach: tokens and scenes cross \
             the network in clear; give --tls-cert and --tls-key"
        );
    }
    let mut grpc = tonic::transport::Server::builder()
        .http2_keepalive_interval(Some(KEEPALIVE_INTERVAL))
        .http2_keepalive_timeout(Some(KEEPALIVE_TIMEOUT))
        .max_concurrent_streams(connection::MAX_STREAMS_PER_CONNECTION)
        .http2_max_header_list_size(connection::MAX_HEADER_LIST_BYTES);
    if let Some(tls) = tls {
        grpc = grpc
            .tls_config(tls)
            .context("--tls-cert and --tls-key do not make a TLS identity")?;
    }
    let (zenoh, zenoh_locators) = pubsub::open(&config).await?;
    let listener = tokio::net::TcpListener::bind(config.grpc_addr)
        .await
        .with_context(|| format!("cannot bind the gRPC address {}", config.grpc_addr))?;
    let grpc_addr = listener.local_addr()?;

    let shutdown = CancellationToken::new();
    let sessions_stop = CancellationToken::new();
    let sealed = config.seals(tokens.is_some());
    let metrics = Arc::new(metrics::Metrics::new());
    let registry = Arc::new(
        Registry::new(
            zenoh.clone(),
            sealed,
            config.build_options(),
            config.max_sessions,
            config.memory_budget_bytes(),
            // Cancelled once the last checkpoint round is written (see the
            // serving task), not with `shutdown` itself.
            sessions_stop.clone(),
            metrics.clone(),
        )
        .named(config.server_name.as_deref()),
    );
    let checkpoints = match &config.checkpoint_dir {
        Some(dir) => {
            let checkpoints = checkpoint::Checkpoints::new(
                dir,
                config.checkpoint_period(),
                config.max_snapshot_bytes(),
                metrics.clone(),
            )
            .with_context(|| format!("cannot create --checkpoint-dir {}", dir.display()))?;
            let restored = checkpoints.restore_all(&registry).await;
            tracing::info!(dir = %dir.display(), restored, "checkpoints");
            Some(Arc::new(checkpoints))
        }
        None => None,
    };
    metrics.watch(Box::new(metrics_live::LiveCollector::new(
        &registry,
        checkpoints.clone(),
    )));
    let metrics_addr = match config.metrics_addr {
        Some(addr) => Some(
            metrics_http::serve(
                addr,
                metrics.clone(),
                config.metrics_header_period(),
                shutdown.child_token(),
            )
            .await?,
        ),
        None => None,
    };
    let info = v1::ServerInfo {
        version: env!("CARGO_PKG_VERSION").into(),
        zenoh_locators: zenoh_locators.clone(),
        zenoh_key_root: meshless_proto::keys::ROOT.into(),
        max_particles_per_session: config.max_particles,
        max_sessions: config.max_sessions,
        zenoh_sealed: sealed,
        max_snapshot_bytes: config.max_snapshot_bytes() as u64,
        checkpoint_interval: if checkpoints.is_some() {
            config.checkpoint_interval
        } else {
            0.0
        },
        server_name: config.server_name.clone().unwrap_or_default(),
        // Read afresh by each GetServerInfo.
        zenoh_routers: 0,
    };
    // Dropped when the serving task ends: the server's presence for
    // anyone watching `meshless/v1/servers/*`.
    let presence = match &config.server_name {
        Some(name) => Some(
            zenoh
                .liveliness()
                .declare_token(meshless_proto::keys::server(name))
                .await
                .map_err(|e| anyhow::anyhow!("zenoh liveliness token: {e}"))?,
        ),
        None => None,
    };
    // A Snapshot answer carries a whole snapshot. A Restore request does
    // too, within `--max-request-mb` like every request: the request
    // limit bounds what any caller makes the server hold before a check.
    let snapshot_room = config
        .max_snapshot_bytes()
        .saturating_add(SNAPSHOT_ENVELOPE);
    let simulation = SimulationServer::new(SimulationService::new(
        registry.clone(),
        info,
        checkpoints.clone(),
        metrics.clone(),
        shutdown.clone(),
    ))
    .max_decoding_message_size(config.max_request_bytes())
    .max_encoding_message_size(MAX_RESPONSE_BYTES.max(snapshot_room));
    let checkpointer = checkpoints
        .clone()
        .map(|c| c.spawn(registry.clone(), shutdown.child_token()));
    // Health and reflection stay open (probes, tools); every simulation
    // call passes the token check first.
    let simulation = tonic::service::interceptor::InterceptedService::new(
        simulation,
        auth::Authenticator::new(tokens),
    );
    let deadlines = connection::Deadlines {
        handshake: config.handshake_period(),
        idle: config.idle_period(),
    };
    // The viewer's thread stops with the gRPC port, or when the serving
    // task is dropped (a server dropped without `stop`, its runtime gone).
    let viewer_stop = sessions_stop.child_token();
    let viewer_guard = viewer_stop.clone().drop_guard();
    let viewer = match config.http_addr {
        Some(addr) => Some(web::serve(
            addr,
            simulation.clone(),
            web::Listener {
                tokenless,
                tls: viewer_tls,
                max_connections: config.max_connections as usize,
                deadlines,
                metrics: metrics.clone(),
                priority: config.http_priority,
            },
            viewer_stop,
        )?),
        None => None,
    };
    let http_addr = viewer.as_ref().map(|(addr, _)| *addr);
    let (health_reporter, health) = tonic_health::server::health_reporter();
    health_reporter
        .set_serving::<SimulationServer<SimulationService>>()
        .await;
    let reflection = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(meshless_proto::FILE_DESCRIPTOR_SET)
        .build_v1()
        .context("gRPC reflection")?;

    let incoming = listener::incoming(
        listener,
        "gRPC",
        config.max_connections as usize,
        deadlines,
        // Accepting ends with the sessions (below): tonic stops at the
        // end of its connections as soon as they end, which would cut
        // the last checkpoint round short.
        sessions_stop.child_token(),
    );
    let stop = shutdown.clone();
    let last_round = registry.clone();
    // On shutdown: one last checkpoint round while the sessions still
    // answer (bounded: a session busy with a long `Step` may not), then
    // the sessions' steps are interrupted so that calls in flight end and
    // the server can stop.
    let stopping = async move {
        stop.cancelled().await;
        if let Some(checkpoints) = &checkpoints {
            let round = checkpoints.round(&last_round);
            if tokio::time::timeout(LAST_ROUND_TIMEOUT, round)
                .await
                .is_err()
            {
                tracing::warn!("the last checkpoint round did not finish in time");
            }
        }
        sessions_stop.cancel();
    };
    let task = tokio::spawn(async move {
        let _viewer_guard = viewer_guard;
        let served = grpc
            // Outermost: it sees the codes as recoded below.
            .layer(metrics_layer::RecordLayer(metrics))
            .layer(tower::util::MapResponseLayer::new(codes::recode))
            // Innermost: a refusal for the response budget is counted.
            .layer(connection::CallsLayer)
            .add_service(health)
            .add_service(reflection)
            .add_service(simulation)
            .serve_with_incoming_shutdown(incoming, stopping)
            .await;
        if let Some(checkpointer) = checkpointer {
            let _ = checkpointer.await;
        }
        registry.shut_down_all().await;
        if let Some((_, viewer)) = viewer {
            // Its calls ended with the sessions; a page's idle connection
            // does not hold the server up.
            if tokio::time::timeout(VIEWER_STOP_TIMEOUT, viewer)
                .await
                .is_err()
            {
                tracing::warn!("the viewer's listener did not stop in time");
            }
        }
        drop(presence);
        if let Err(e) = zenoh.close().await {
            tracing::warn!("closing zenoh: {e}");
        }
        served.context("gRPC server")
    });
    tracing::info!(%grpc_addr, zenoh = ?zenoh_locators, "meshless-server listening");
    Ok(RunningServer {
        grpc_addr,
        zenoh_locators,
        metrics_addr,
        http_addr,
        shutdown,
        task,
    })
}

/// Runs a server until SIGINT or SIGTERM, printing one line with its
/// addresses to stdout once it is ready (scripts and tests wait for it).
///
/// # Errors
/// See [`start`].
pub async fn serve_until_signal(config: ServerConfig) -> Result<()> {
    let server = start(config).await?;
    let metrics = server
        .metrics_addr
        .map(|addr| format!(" metrics={addr}"))
        .unwrap_or_default();
    let http = server
        .http_addr
        .map(|addr| format!(" http={addr}"))
        .unwrap_or_default();
    println!(
        "meshless-server ready grpc={} zenoh={}{metrics}{http}",
        server.grpc_addr,
        server.zenoh_locators.join(",")
    );
    shutdown_signal().await?;
    tracing::info!("shutting down");
    server.stop().await
}

async fn shutdown_signal() -> Result<()> {
    #[cfg(unix)]
    {
        let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?;
        tokio::select! {
            r = tokio::signal::ctrl_c() => r?,
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    tokio::signal::ctrl_c().await?;
    Ok(())
}
