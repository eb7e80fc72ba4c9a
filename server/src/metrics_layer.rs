//! The tower layer that counts every gRPC call by method and status code
//! and times it to its response's headers (a unary call's whole time; a
//! stream's start). The code is the response's `grpc-status` header, which
//! a refused call carries (trailers-only); a call that answers carries it
//! in its trailers, after the headers, and is `OK` here. A call dropped
//! before it answered (its caller gone, tonic's deadline timer fired) is
//! `CANCELLED`.

use crate::metrics::{Metrics, method_name};
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Instant;
use tonic::codegen::http;

/// Wraps a service in [`Record`].
#[derive(Debug, Clone)]
pub struct RecordLayer(pub Arc<Metrics>);

impl<S> tower::Layer<S> for RecordLayer {
    type Service = Record<S>;

    fn layer(&self, inner: S) -> Record<S> {
        Record {
            inner,
            metrics: self.0.clone(),
        }
    }
}

/// A service whose calls are counted and timed.
#[derive(Debug, Clone)]
pub struct Record<S> {
    inner: S,
    metrics: Arc<Metrics>,
}

impl<S, B, R> tower::Service<http::Request<B>> for Record<S>
where
    S: tower::Service<http::Request<B>, Response = http::Response<R>>,
    S::Future: Send + 'static,
{
    type Response = S::Response;
    type Error = S::Error;
    type Future = Pin<Box<dyn Future<Output = Result<Self::Response, Self::Error>> + Send>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, request: http::Request<B>) -> Self::Future {
        // A label from a fixed set: a caller's path never grows it.
        let method = method_name(request.uri().path());
        let started = Instant::now();
        let metrics = self.metrics.clone();
        let answer = self.inner.call(request);
        Box::pin(async move {
            // Counted as CANCELLED if dropped unanswered: the caller went
            // away, or tonic's timer for its deadline fired.
            let mut pending = Pending {
                metrics: &metrics,
                method,
                started,
                code: tonic::Code::Cancelled,
            };
            let response = answer.await;
            if let Ok(response) = &response {
                pending.code = response
                    .headers()
                    .get("grpc-status")
                    .and_then(|v| v.to_str().ok())
                    .and_then(|v| v.parse::<i32>().ok())
                    .map_or(tonic::Code::Ok, tonic::Code::from);
            }
            response
        })
    }
}

/// A call in progress, recorded when it ends or is dropped.
struct Pending<'a> {
    metrics: &'a Metrics,
    method: &'static str,
    started: Instant,
    code: tonic::Code,
}

impl Drop for Pending<'_> {
    fn drop(&mut self) {
        self.metrics
            .rpc(self.method, self.code, self.started.elapsed());
    }
}
