//! What one gRPC connection has earned and holds: whether a caller with
//! a token has used it, how many calls are in flight on it, and how many
//! bytes of large responses it holds that its client has not read.
//!
//! A place under `--max-connections` is earned by a call that passes the
//! token check ([`Connection::earn`], called by the authenticator): until
//! then a connection lives at most `--handshake-timeout`, whatever it
//! sends (one byte, the HTTP/2 preface, pings, calls to the open health
//! and reflection services), so that strangers cannot hold every place.
//! An earned connection is closed once no call has been in flight on it
//! for `--idle-timeout` (clients reconnect on their next call). The
//! listener's [`crate::listener::Admitted`] enforces both deadlines; the
//! [`CallsLayer`] here counts the calls and keeps the response budget.
//!
//! The response budget: a response held behind a client's flow-control
//! window stays in memory until the client reads it, so a client that
//! never reads could pile up any number of 1 MB frames (400 of them held
//! 473 MB). Each large response takes its size from its connection's
//! budget ([`RESPONSE_BUDGET_BYTES`]) until the last of its bytes is
//! written to the socket; one that does not fit is refused with
//! RESOURCE_EXHAUSTED and dropped at once. A single response larger than
//! the budget is served when the connection holds nothing else.

use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tokio::time::Instant;
use tonic::codegen::{Bytes, http};

/// Most streams (calls) open at once on one connection: RFC 9113's
/// recommended minimum. Unset, hyper's limit was none at all (20,000
/// streams on one connection were answered, holding 257 MB); past it a
/// new stream is refused (REFUSED_STREAM), which clients retry.
pub(crate) const MAX_STREAMS_PER_CONNECTION: u32 = 100;

/// Largest header block of a request. hyper's default (16 kB) answered a
/// 16 kB token with HTTP 431, which clients show as UNKNOWN; with room
/// above `auth::MAX_TOKEN_BYTES` the token check refuses it by name.
pub(crate) const MAX_HEADER_LIST_BYTES: u32 = 64 << 10;

/// Bytes of large responses one connection may hold unread: room for the
/// largest frame a session publishes by default several times over.
pub const RESPONSE_BUDGET_BYTES: usize = 64 << 20;

/// Responses smaller than this pass outside the budget: every call's
/// answer that changes a session is far smaller, so the budget never
/// refuses a call whose work was already done; their number is bounded by
/// the streams a connection may open.
const LARGE_RESPONSE_BYTES: usize = 64 << 10;

/// The deadlines of a connection.
#[derive(Debug, Clone, Copy)]
pub struct Deadlines {
    /// How long a connection may live without a call that passes the
    /// token check.
    pub handshake: Duration,
    /// How long an earned connection may go without a call in flight.
    pub idle: Duration,
}

/// One connection's state, shared by its socket and its calls (tonic puts
/// it into every request's extensions as the connection's info).
#[derive(Debug, Clone)]
pub struct Connection(Arc<State>);

#[derive(Debug)]
struct State {
    opened: Instant,
    deadlines: Deadlines,
    earned: AtomicBool,
    in_flight: AtomicUsize,
    /// When the last call in flight ended.
    idle_since: Mutex<Instant>,
    responses: Arc<Semaphore>,
}

impl Connection {
    /// A connection accepted now.
    pub fn new(deadlines: Deadlines) -> Self {
        let now = Instant::now();
        Self(Arc::new(State {
            opened: now,
            deadlines,
            earned: AtomicBool::new(false),
            in_flight: AtomicUsize::new(0),
            idle_since: Mutex::new(now),
            responses: Arc::new(Semaphore::new(RESPONSE_BUDGET_BYTES)),
        }))
    }

    /// Records a call that passed the token check: the connection has
    /// earned its place.
    pub fn earn(&self) {
        self.0.earned.store(true, Ordering::Relaxed);
    }

    /// When the connection is to be closed unless something changes, or
    /// `None` when that time has come.
    pub fn deadline(&self, now: Instant) -> Option<Instant> {
        let state = &self.0;
        let due = if !state.earned.load(Ordering::Relaxed) {
            state.opened + state.deadlines.handshake
        } else if state.in_flight.load(Ordering::Acquire) > 0 {
            now + state.deadlines.idle
        } else {
            *state.idle_since.lock().unwrap_or_else(|e| e.into_inner()) + state.deadlines.idle
        };
        (due > now).then_some(due)
    }

    fn call_started(&self) -> InFlight {
        self.0.in_flight.fetch_add(1, Ordering::AcqRel);
        InFlight(self.0.clone())
    }
}

/// A call in flight, until its response ends or is dropped.
#[derive(Debug)]
struct InFlight(Arc<State>);

impl Drop for InFlight {
    fn drop(&mut self) {
        let mut idle_since = self.0.idle_since.lock().unwrap_or_else(|e| e.into_inner());
        if self.0.in_flight.fetch_sub(1, Ordering::AcqRel) == 1 {
            *idle_since = Instant::now();
        }
    }
}

/// Wraps a service in [`Calls`].
#[derive(Debug, Clone, Copy)]
pub struct CallsLayer;

impl<S> tower::Layer<S> for CallsLayer {
    type Service = Calls<S>;

    fn layer(&self, inner: S) -> Calls<S> {
        Calls { inner }
    }
}

/// A service whose calls are counted on their connection and whose large
/// responses take from its response budget.
#[derive(Debug, Clone)]
pub struct Calls<S> {
    inner: S,
}

type BoxError = Box<dyn std::error::Error + Send + Sync>;

impl<S, B, R> tower::Service<http::Request<B>> for Calls<S>
where
    S: tower::Service<http::Request<B>, Response = http::Response<R>>,
    S::Future: Send + 'static,
    R: http_body::Body<Data = Bytes> + Send + Unpin + 'static,
    R::Error: Into<BoxError>,
{
    type Response = http::Response<tonic::body::Body>;
    type Error = S::Error;
    type Future = Pin<Box<dyn Future<Output = Result<Self::Response, Self::Error>> + Send>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, request: http::Request<B>) -> Self::Future {
        let connection = request.extensions().get::<Connection>().cloned();
        let in_flight = connection.as_ref().map(Connection::call_started);
        let answer = self.inner.call(request);
        Box::pin(async move {
            let response = answer.await?;
            let (Some(connection), Some(in_flight)) = (connection, in_flight) else {
                return Ok(response.map(tonic::body::Body::new));
            };
            let (parts, mut body) = response.into_parts();
            // The first frame now: a unary answer is encoded at once, so
            // its size is known before the response is handed on; a stream
            // not yet ready is accounted frame by frame.
            let first =
                std::future::poll_fn(|cx| Poll::Ready(Pin::new(&mut body).poll_frame(cx))).await;
            let mut tracked = Tracked {
                body,
                pending: None,
                refused: false,
                budget: connection.0.responses.clone(),
                _in_flight: in_flight,
            };
            match first {
                Poll::Pending | Poll::Ready(None) => {}
                Poll::Ready(Some(Err(e))) => tracked.pending = Some(Err(e.into())),
                Poll::Ready(Some(Ok(frame))) => match tracked.admit(frame) {
                    Ok(frame) => tracked.pending = Some(Ok(frame)),
                    Err(status) => return Ok(status.into_http()),
                },
            }
            Ok(http::Response::from_parts(
                parts,
                tonic::body::Body::new(tracked),
            ))
        })
    }
}

/// A response body that holds its call in flight until it ends, and
/// whose large data frames carry their share of the budget until written.
struct Tracked<R> {
    body: R,
    pending: Option<Result<http_body::Frame<Bytes>, BoxError>>,
    /// Set once a refusal ended the stream.
    refused: bool,
    budget: Arc<Semaphore>,
    _in_flight: InFlight,
}

/// Data that returns its bytes to the budget when the last copy of it is
/// dropped: when h2 has written it, or the stream is gone.
struct Budgeted {
    data: Bytes,
    _permit: OwnedSemaphorePermit,
}

impl AsRef<[u8]> for Budgeted {
    fn as_ref(&self) -> &[u8] {
        &self.data
    }
}

impl<R> Tracked<R> {
    /// `frame` with its share of the budget, or the status that refuses
    /// it when the budget is spent.
    fn admit(
        &self,
        frame: http_body::Frame<Bytes>,
    ) -> Result<http_body::Frame<Bytes>, tonic::Status> {
        let data = match frame.into_data() {
            Ok(data) if data.len() >= LARGE_RESPONSE_BYTES => data,
            Ok(small) => return Ok(http_body::Frame::data(small)),
            Err(frame) => return Ok(frame),
        };
        let share = data.len().min(RESPONSE_BUDGET_BYTES);
        let Ok(permit) = self
            .budget
            .clone()
            .try_acquire_many_owned(u32::try_from(share).unwrap_or(u32::MAX))
        else {
            let unread = RESPONSE_BUDGET_BYTES - self.budget.available_permits();
            return Err(tonic::Status::resource_exhausted(format!(
                "this connection holds {} MB of answers its client has not read (at most {} \
                 MB per connection); read them before asking for more, or use another \
                 connection",
                unread >> 20,
                RESPONSE_BUDGET_BYTES >> 20
            )));
        };
        Ok(http_body::Frame::data(Bytes::from_owner(Budgeted {
            data,
            _permit: permit,
        })))
    }
}

impl<R> http_body::Body for Tracked<R>
where
    R: http_body::Body<Data = Bytes> + Unpin,
    R::Error: Into<BoxError>,
{
    type Data = Bytes;
    type Error = BoxError;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<http_body::Frame<Bytes>, BoxError>>> {
        if let Some(pending) = self.pending.take() {
            return Poll::Ready(Some(pending));
        }
        if self.refused {
            return Poll::Ready(None);
        }
        match std::task::ready!(Pin::new(&mut self.body).poll_frame(cx)) {
            None => Poll::Ready(None),
            Some(Err(e)) => Poll::Ready(Some(Err(e.into()))),
            Some(Ok(frame)) => match self.admit(frame) {
                Ok(frame) => Poll::Ready(Some(Ok(frame))),
                // A later message of a stream that does not fit ends the
                // stream, the refusal as its status.
                Err(status) => {
                    self.refused = true;
                    let mut trailers = http::HeaderMap::new();
                    // Only a message that is no valid header fails, and
                    // this one is plain ASCII.
                    let _ = status.add_header(&mut trailers);
                    Poll::Ready(Some(Ok(http_body::Frame::trailers(trailers))))
                }
            },
        }
    }

    fn is_end_stream(&self) -> bool {
        self.pending.is_none() && (self.refused || self.body.is_end_stream())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DEADLINES: Deadlines = Deadlines {
        handshake: Duration::from_secs(10),
        idle: Duration::from_secs(100),
    };

    #[test]
    fn a_place_is_earned_by_an_authenticated_call_and_lost_by_idling() {
        let connection = Connection::new(DEADLINES);
        let opened = Instant::now();
        let due = connection.deadline(opened).expect("not yet");
        assert!(due <= opened + DEADLINES.handshake, "{due:?}");
        assert_eq!(
            connection.deadline(opened + DEADLINES.handshake),
            None,
            "bytes alone earn nothing"
        );

        connection.earn();
        let call = connection.call_started();
        let later = opened + Duration::from_secs(500);
        assert_eq!(
            connection.deadline(later),
            Some(later + DEADLINES.idle),
            "a call in flight keeps the connection"
        );
        drop(call);
        let ended = Instant::now();
        let due = connection.deadline(ended).expect("idle from now on");
        assert!(due <= ended + DEADLINES.idle, "{due:?}");
        assert_eq!(
            connection.deadline(ended + DEADLINES.idle),
            None,
            "idle too long"
        );
    }

    #[test]
    fn large_answers_take_from_the_budget_until_their_bytes_are_dropped() {
        let connection = Connection::new(DEADLINES);
        let tracked = Tracked {
            body: tonic::body::Body::empty(),
            pending: None,
            refused: false,
            budget: connection.0.responses.clone(),
            _in_flight: connection.call_started(),
        };
        let frame = |n: usize| http_body::Frame::data(Bytes::from(vec![7u8; n]));
        let small = tracked.admit(frame(100)).expect("small answers pass");
        assert_eq!(
            connection.0.responses.available_permits(),
            RESPONSE_BUDGET_BYTES
        );
        let big = tracked
            .admit(frame(RESPONSE_BUDGET_BYTES + 1))
            .expect("one answer larger than the budget passes alone");
        let status = tracked.admit(frame(1 << 20)).expect_err("budget spent");
        assert_eq!(status.code(), tonic::Code::ResourceExhausted);
        assert!(status.message().contains("64 MB"), "{}", status.message());
        // h2 splits data into frames: the budget returns with the last.
        let mut data = big.into_data().expect("data");
        let head = data.split_to(10);
        drop(data);
        assert_eq!(connection.0.responses.available_permits(), 0);
        drop(head);
        assert_eq!(
            connection.0.responses.available_permits(),
            RESPONSE_BUDGET_BYTES
        );
        drop(small);
    }
}
