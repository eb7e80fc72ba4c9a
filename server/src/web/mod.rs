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
//! the session encoded once for its zenoh subscribers.

mod assets;
mod schema;

use crate::connection::{CallsLayer, Deadlines};
use crate::metrics::Metrics;
use crate::metrics_layer::RecordLayer;
use anyhow::{Context, Result};
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use std::net::SocketAddr;
use std::sync::Arc;
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
    pub tls: Option<tonic::transport::ServerTlsConfig>,
    pub max_connections: usize,
    pub deadlines: Deadlines,
    pub metrics: Arc<Metrics>,
}

/// Binds `addr` and serves the page and `simulation` (already behind the
/// token check) until `stop`; returns the bound address and the serving
/// task.
///
/// # Errors
/// An address that cannot be bound, or a schema that cannot be made.
pub async fn serve(
    addr: SocketAddr,
    simulation: Simulation,
    listener: Listener,
    stop: CancellationToken,
) -> Result<(SocketAddr, tokio::task::JoinHandle<()>)> {
    let routes = routes(simulation, listener.metrics)?;
    let tcp = tokio::net::TcpListener::bind(addr)
        .await
        .with_context(|| format!("cannot bind the viewer's --http-addr {addr}"))?;
    let bound = tcp.local_addr()?;
    let mut server = tonic::transport::Server::builder()
        .accept_http1(true)
        .max_concurrent_streams(crate::MAX_STREAMS_PER_CONNECTION)
        .http2_max_header_list_size(crate::MAX_HEADER_LIST_BYTES);
    if let Some(tls) = listener.tls {
        server = server
            .tls_config(tls)
            .context("--tls-cert and --tls-key do not make a TLS identity")?;
    }
    let incoming = crate::listener::incoming(
        tcp,
        "viewer",
        listener.max_connections,
        listener.deadlines,
        stop.clone(),
    );
    let task = tokio::spawn(async move {
        let served = server
            .add_routes(routes)
            .serve_with_incoming_shutdown(incoming, stop.cancelled_owned())
            .await;
        if let Err(e) = served {
            tracing::error!("the viewer's listener failed: {e}");
        }
    });
    tracing::info!(%bound, "viewer at http://{bound}/");
    Ok((bound, task))
}

/// The page's files, the schema, the scenes, and the service, behind the
/// gRPC port's layers: the gRPC-web translation outermost, so that the
/// metrics, the codes' rewriting and the call counting see plain gRPC.
fn routes(simulation: Simulation, metrics: Arc<Metrics>) -> Result<Routes> {
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
    Ok(Routes::from(router.fallback(not_found)))
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
