//! The browser viewer's listener (`--http-addr`): the page and its
//! scripts, the schema its codec reads, the shipped scenes, and the
//! `meshless.v1.Simulation` service itself as gRPC-web (tonic-web).
//!
//! The page has no API of its own: every control it offers is a call of
//! the same service, through the same token check, access rules, request
//! limits, response budget and metrics as a gRPC client's, on connections
//! with the same limits and deadlines (TLS too, when the server has it).
//! What it serves without a token is the page, its scripts, the schema
//! and the shipped scenes: text that every copy of this binary holds.
//! Frames reach the page by `NextFrame` polls (one frame in flight per
//! page; a page that falls behind skips frames), answered with the bytes
//! the session encoded once for its zenoh subscribers. The listener runs
//! on a thread of its own, below the simulations (`--http-priority`,
//! [`thread`]); its calls run on the server's runtime ([`hop`]).

mod assets;
mod hop;
mod schema;
mod thread;

use crate::connection::{CallsLayer, Deadlines};
use crate::metrics::Metrics;
use crate::metrics_layer::RecordLayer;
use anyhow::{Context, Result};
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use std::net::SocketAddr;
use std::sync::Arc;
use tokio::sync::oneshot;
use tokio_util::sync::CancellationToken;
use tonic::server::NamedService;

/// The service as the gRPC port serves it: behind the token check.
pub type Simulation = tonic::service::interceptor::InterceptedService<
    meshless_proto::v1::simulation_server::SimulationServer<crate::service::SimulationService>,
    crate::auth::Authenticator,
>;
use tonic::service::Routes;

/// Only this server's own scripts and styles run in the page, and it
/// talks to nobody else.
const CONTENT_SECURITY_POLICY: &str = "default-src 'self'; img-src 'self' data: blob:; \
     object-src 'none'; base-uri 'none'; frame-ancestors 'none'";

/// What the listener needs besides its address.
#[derive(Debug)]
pub struct Listener {
    /// Whether callers need no token (a loopback server without
    /// `--tokens-file`): then only requests addressed to a loopback host
    /// are answered (see [`loopback_only`]).
    pub tokenless: bool,
    pub tls: Option<tonic::transport::ServerTlsConfig>,
    pub max_connections: usize,
    pub deadlines: Deadlines,
    pub metrics: Arc<Metrics>,
    /// When the listener's thread runs (`--http-priority`).
    pub priority: crate::config::ViewerPriority,
}

/// Binds `addr` and serves the page and `simulation` (already behind the
/// token check) until `stop`, on the viewer's own thread; returns the
/// bound address and a receiver that resolves when the listener has
/// stopped. Called on the server's runtime, where the calls will run.
///
/// # Errors
/// An address that cannot be bound, a schema that cannot be made, or a
/// thread that cannot start.
pub fn serve(
    addr: SocketAddr,
    simulation: Simulation,
    listener: Listener,
    stop: CancellationToken,
) -> Result<(SocketAddr, oneshot::Receiver<()>)> {
    let simulation = hop::Hop::new(simulation, tokio::runtime::Handle::current());
    let routes = routes(simulation, listener.metrics, listener.tokenless)?;
    // Bound here, so that a taken port fails the start; served there.
    let tcp = std::net::TcpListener::bind(addr)
        .with_context(|| format!("cannot bind the viewer's --http-addr {addr}"))?;
    tcp.set_nonblocking(true)?;
    let bound = tcp.local_addr()?;
    let mut server = tonic::transport::Server::builder()
        .accept_http1(true)
        .max_concurrent_streams(crate::connection::MAX_STREAMS_PER_CONNECTION)
        .http2_max_header_list_size(crate::connection::MAX_HEADER_LIST_BYTES);
    if let Some(tls) = listener.tls {
        server = server
            .tls_config(tls)
            .context("--tls-cert and --tls-key do not make a TLS identity")?;
    }
    let (max_connections, deadlines) = (listener.max_connections, listener.deadlines);
    let stopped = thread::spawn(listener.priority, async move {
        let tcp = match tokio::net::TcpListener::from_std(tcp) {
            Ok(tcp) => tcp,
            Err(e) => {
                tracing::error!("the viewer's listener failed: {e}");
                return;
            }
        };
        let incoming =
            crate::listener::incoming(tcp, "viewer", max_connections, deadlines, stop.clone());
        let served = server
            .add_routes(routes)
            .serve_with_incoming_shutdown(incoming, stop.cancelled_owned())
            .await;
        if let Err(e) = served {
            tracing::error!("the viewer's listener failed: {e}");
        }
    })
    .context("cannot start the viewer's thread")?;
    tracing::info!(%bound, priority = ?listener.priority, "viewer at http://{bound}/");
    Ok((bound, stopped))
}

/// The page's files, the schema, the scenes, and the service, behind the
/// gRPC port's layers: the gRPC-web translation outermost, so that the
/// metrics, the codes' rewriting and the call counting see plain gRPC.
fn routes(
    simulation: hop::Hop<Simulation>,
    metrics: Arc<Metrics>,
    tokenless: bool,
) -> Result<Routes> {
    let schema: Arc<str> = schema::json(meshless_proto::FILE_DESCRIPTOR_SET)?.into();
    let scenes: Arc<str> = assets::scenes_json().into();
    let service = tower::ServiceBuilder::new()
        .layer(tonic_web::GrpcWebLayer::new())
        .layer(RecordLayer(metrics))
        .layer(tower::util::MapResponseLayer::new(crate::codes::recode))
        .layer(CallsLayer)
        .service(simulation);
    let mut router = axum::Router::new()
        .route_service(&format!("/{}/{{*rest}}", Simulation::NAME), service)
        .route(
            "/",
            axum::routing::get(|| async { file(&assets::ASSETS[0]) }),
        )
        .route(
            "/schema.json",
            axum::routing::get(move || {
                let schema = schema.clone();
                async move { json(&schema) }
            }),
        )
        .route(
            "/scenes.json",
            axum::routing::get(move || {
                let scenes = scenes.clone();
                async move { json(&scenes) }
            }),
        );
    for asset in assets::ASSETS {
        router = router.route(
            &format!("/{}", asset.name),
            axum::routing::get(move || async move { file(asset) }),
        );
    }
    let mut router = router.fallback(not_found);
    if tokenless {
        router = router.layer(axum::middleware::from_fn(loopback_only));
    }
    Ok(Routes::from(router))
}

/// On a server without tokens every caller may drive every session, and a
/// browser sends a page's calls to whatever address its name resolves to:
/// another site whose name resolves to 127.0.0.1 (DNS rebinding) would be
/// answered as this page is. So such a server answers only requests
/// addressed to a loopback host (`127.0.0.1`, `[::1]`, `localhost`), the
/// only names it may be reached by; with tokens, the token keeps other
/// sites out (a page of another origin cannot read it).
async fn loopback_only(request: axum::extract::Request, next: axum::middleware::Next) -> Response {
    let host = request.uri().host().map(str::to_owned).or_else(|| {
        request
            .headers()
            .get(header::HOST)
            .and_then(|h| h.to_str().ok())
            .map(str::to_owned)
    });
    if host.as_deref().is_some_and(is_loopback_host) {
        next.run(request).await
    } else {
        (
            StatusCode::FORBIDDEN,
            [(header::CONTENT_TYPE, "text/plain; charset=utf-8")],
            "this server has no tokens, so its viewer answers only at a loopback address \
             (http://127.0.0.1:PORT/ or http://localhost:PORT/)\n",
        )
            .into_response()
    }
}

/// Whether a `Host` value (with or without its port) names this machine's
/// loopback interface.
fn is_loopback_host(host: &str) -> bool {
    let name = match host.strip_prefix('[') {
        // `[::1]` or `[::1]:8080`.
        Some(rest) => match rest.split_once(']') {
            Some((name, _)) => name,
            None => return false,
        },
        None => host.rsplit_once(':').map_or(host, |(name, _)| name),
    };
    name.eq_ignore_ascii_case("localhost")
        || name
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// A file of the page: never cached stale (a new server may bring a new
/// page), never sniffed as another type.
fn file(asset: &assets::Asset) -> Response {
    let mut response = asset.text.into_response();
    let headers = response.headers_mut();
    headers.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(asset.media_type),
    );
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    headers.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    headers.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CONTENT_SECURITY_POLICY),
    );
    headers.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    response
}

fn json(text: &str) -> Response {
    let mut response = text.to_owned().into_response();
    let headers = response.headers_mut();
    headers.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    headers.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    response
}

/// Anything else: a plain 404 that echoes nothing of the request.
async fn not_found() -> Response {
    (
        StatusCode::NOT_FOUND,
        [(header::CONTENT_TYPE, "text/plain; charset=utf-8")],
        "not found: the viewer is at /\n",
    )
        .into_response()
}

#[cfg(test)]
mod tests {
    use super::is_loopback_host;

    #[test]
    fn only_loopback_names_pass_the_host_check() {
        for host in [
            "127.0.0.1:8080",
            "127.0.0.1",
            "localhost:1",
            "LOCALHOST",
            "[::1]:8080",
            "[::1]",
            "127.1.2.3:80",
        ] {
            assert!(is_loopback_host(host), "{host}");
        }
        for host in [
            "evil.example",
            "evil.example:8080",
            "localhost.evil.example",
            "10.0.0.1:8080",
            "[fe80::1]:80",
            "",
            "[::1",
        ] {
            assert!(!is_loopback_host(host), "{host}");
        }
    }
}
