//! The viewer's calls run on the server's runtime, not on the viewer's
//! thread.
//!
//! The viewer's listener lives on a thread of its own at a lower priority
//! ([`super::thread`]), but what a call does is the service's work, not the
//! page's: a `CreateSession` starts a session's publisher and its zenoh
//! tasks, which must live with every other session's on the server's
//! runtime (and outlive the viewer's thread at shutdown), and a check or a
//! snapshot should not wait behind the pages' bytes. So each call's
//! handler is spawned onto the server's runtime and awaited from the
//! viewer's thread; the HTTP around it (parsing, gRPC-web framing, the
//! answer's encoding and its socket writes) stays on the viewer's thread.
//! A page that goes away drops its call, and the handler is aborted with
//! it, as it would be on the gRPC port.

use std::convert::Infallible;
use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll};
use tokio::runtime::Handle;
use tokio_util::task::AbortOnDropHandle;
use tonic::codegen::http;

/// Runs `inner`'s calls on `runtime` (see the module's doc).
#[derive(Debug, Clone)]
pub struct Hop<S> {
    inner: S,
    runtime: Handle,
}

impl<S> Hop<S> {
    /// `inner`, its calls run on `runtime`.
    pub fn new(inner: S, runtime: Handle) -> Self {
        Self { inner, runtime }
    }
}

impl<S, B, R> tower::Service<http::Request<B>> for Hop<S>
where
    S: tower::Service<http::Request<B>, Response = http::Response<R>, Error = Infallible>,
    S::Future: Send + 'static,
    R: tonic::codegen::Body<Data = tonic::codegen::Bytes> + Send + 'static,
    R::Error: Into<tonic::codegen::StdError>,
{
    type Response = http::Response<tonic::body::Body>;
    type Error = Infallible;
    type Future =
        Pin<Box<dyn Future<Output = Result<Self::Response, Infallible>> + Send + 'static>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Infallible>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, request: http::Request<B>) -> Self::Future {
        let handler = AbortOnDropHandle::new(self.runtime.spawn(self.inner.call(request)));
        Box::pin(async move {
            match handler.await {
                Ok(answer) => answer.map(|answer| answer.map(tonic::body::Body::new)),
                // The server's runtime is shutting down: the handler was
                // cancelled.
                Err(e) if e.is_cancelled() => Ok(tonic::Status::unavailable(
                    "the server is stopping; call again on a running server",
                )
                .into_http()),
                Err(_) => Ok(tonic::Status::internal(
                    "the call failed inside the server; see its log",
                )
                .into_http()),
            }
        })
    }
}
