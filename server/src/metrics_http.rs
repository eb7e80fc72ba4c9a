//! The metrics endpoint's HTTP/1 server: `GET /metrics` on
//! `--metrics-addr`, with at most [`MAX_CONNECTIONS`] connections open and
//! a deadline on each request's headers.
//!
//! `axum::serve` capped nothing and timed nothing out: half-sent requests
//! held a file descriptor each until the process ran out and gRPC could
//! accept no more. Here the cap is taken before `accept` (connections
//! beyond it wait in the kernel's backlog, as on the gRPC port), and
//! hyper closes a connection whose request headers are not complete
//! within `--metrics-header-timeout` of the connection opening or its
//! previous answer (an idle keep-alive connection included; Prometheus
//! reconnects at its next scrape).

use crate::listener::accept_within;
use crate::metrics::Metrics;
use anyhow::{Context, Result};
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Semaphore;
use tokio_util::sync::CancellationToken;

/// Most metrics connections open at once: a scraper holds one, and a few
/// scrapers and a person with curl are all an endpoint serves.
pub const MAX_CONNECTIONS: usize = 16;

/// Serves `GET /metrics` on `addr` until `stop`; returns the bound
/// address.
///
/// # Errors
/// An address that cannot be bound.
pub async fn serve(
    addr: SocketAddr,
    metrics: Arc<Metrics>,
    header_timeout: Duration,
    stop: CancellationToken,
) -> Result<SocketAddr> {
    let listener = tokio::net::TcpListener::bind(addr)
        .await
        .with_context(|| format!("cannot bind the metrics address {addr}"))?;
    let bound = listener.local_addr()?;
    let app = axum::Router::new().route(
        "/metrics",
        axum::routing::get(move || {
            let metrics = metrics.clone();
            async move {
                (
                    [(
                        axum::http::header::CONTENT_TYPE,
                        "text/plain; version=0.0.4; charset=utf-8",
                    )],
                    metrics.encode(),
                )
            }
        }),
    );
    let places = Arc::new(Semaphore::new(MAX_CONNECTIONS));
    tokio::spawn(async move {
        loop {
            let next = tokio::select! {
                next = accept_within(&listener, &places, "metrics") => next,
                () = stop.cancelled() => None,
            };
            let Some((stream, place)) = next else { break };
            let service = TowerToHyperService::new(app.clone());
            let stop = stop.clone();
            tokio::spawn(async move {
                let _place = place;
                let mut builder = hyper::server::conn::http1::Builder::new();
                builder
                    .timer(TokioTimer::new())
                    .header_read_timeout(header_timeout);
                let connection = builder.serve_connection(TokioIo::new(stream), service);
                tokio::pin!(connection);
                let served = tokio::select! {
                    served = connection.as_mut() => served,
                    () = stop.cancelled() => {
                        connection.as_mut().graceful_shutdown();
                        connection.await
                    }
                };
                if let Err(e) = served {
                    tracing::debug!("metrics connection: {e}");
                }
            });
        }
    });
    tracing::info!(%bound, "metrics at /metrics");
    Ok(bound)
}
