//! The gRPC listener: at most `max_connections` open at a time, each set
//! up for request-response traffic, accepting under pressure without
//! spinning, and each closed once it holds its place without earning it.
//!
//! The cap is taken before `accept`, so connections beyond it wait in the
//! kernel's backlog instead of holding one of this process's file
//! descriptors (1,100 silent connections once exhausted them). An accept
//! error (out of descriptors, a reset before accept) backs off briefly
//! rather than retrying in a tight loop.
//!
//! A place is earned, not taken: a connection that has made no call
//! passing the token check within the handshake deadline is closed, and
//! so is one with no call in flight for the idle deadline
//! ([`crate::connection`] keeps that state). Sockets that send one byte,
//! the HTTP/2 preface alone, or answer pings on an idle channel held a
//! place for ever before; four of them locked every client out of a
//! server with `--max-connections 4`. Deadlines were chosen over evicting
//! the idlest connection at the cap (a flood of new connections would
//! evict token holders before their first call arrives) and over a share
//! per address (clients behind one proxy or NAT, and every test on
//! loopback, share one). A stranger now holds a place for at most the
//! handshake deadline, and connections waiting in the backlog are served
//! in the order they came.

use crate::connection::{Connection, Deadlines};
use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc};
use tokio::time::{Instant, Sleep};
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::sync::CancellationToken;
use tonic::transport::server::Connected;

/// Pause after a failed accept.
const ACCEPT_BACKOFF: Duration = Duration::from_millis(50);

/// An accepted connection holding its place under the cap until it
/// closes, or until its deadline (see [`Connection::deadline`]) passes:
/// then every read and write fails, and the server drops it.
#[derive(Debug)]
pub struct Admitted {
    stream: TcpStream,
    connection: Connection,
    deadline: Pin<Box<Sleep>>,
    _place: OwnedSemaphorePermit,
}

impl Admitted {
    /// An error once the connection's deadline has passed; otherwise
    /// `cx` is woken when it next may have.
    fn check_deadline(&mut self, cx: &mut Context<'_>) -> io::Result<()> {
        while self.deadline.as_mut().poll(cx).is_ready() {
            match self.connection.deadline(Instant::now()) {
                Some(next) => self.deadline.as_mut().reset(next),
                None => {
                    return Err(io::Error::new(
                        io::ErrorKind::TimedOut,
                        "closed a connection without a call in time",
                    ));
                }
            }
        }
        Ok(())
    }
}

impl AsyncRead for Admitted {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        self.check_deadline(cx)?;
        Pin::new(&mut self.stream).poll_read(cx, buf)
    }
}

impl AsyncWrite for Admitted {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        self.check_deadline(cx)?;
        Pin::new(&mut self.stream).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        self.check_deadline(cx)?;
        Pin::new(&mut self.stream).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.stream.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        self.check_deadline(cx)?;
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}

impl Connected for Admitted {
    /// The connection's state, which tonic puts into each request's
    /// extensions: the authenticator marks it earned, and
    /// [`crate::connection::CallsLayer`] counts its calls.
    type ConnectInfo = Connection;

    fn connect_info(&self) -> Self::ConnectInfo {
        self.connection.clone()
    }
}

/// The connections of `listener` (`what` names it in logs), at most
/// `max_connections` open at once, each closed at its `deadlines`, until
/// `stop` or until the stream is dropped. Each gets `TCP_NODELAY`: a small response held back by
/// Nagle's algorithm until the client's delayed ACK cost about 44 ms per
/// sequential call in the loopback test of issue 13 (`cargo bench -p
/// meshless-load` measures sequential calls; docs/performance.md has its
/// figures).
pub fn incoming(
    listener: TcpListener,
    what: &'static str,
    max_connections: usize,
    deadlines: Deadlines,
    stop: CancellationToken,
) -> ReceiverStream<io::Result<Admitted>> {
    let (admitted, stream) = mpsc::channel(1);
    let places = Arc::new(Semaphore::new(max_connections));
    tokio::spawn(async move {
        loop {
            let next = tokio::select! {
                next = accept_within(&listener, &places, what) => next,
                () = stop.cancelled() => None,
                () = admitted.closed() => None,
            };
            let Some((stream, place)) = next else { break };
            if let Err(e) = stream.set_nodelay(true) {
                tracing::debug!("TCP_NODELAY on an accepted connection: {e}");
                continue;
            }
            let connection = Connection::new(deadlines);
            let first = connection
                .deadline(Instant::now())
                .unwrap_or_else(Instant::now);
            let connection = Admitted {
                stream,
                connection,
                deadline: Box::pin(tokio::time::sleep_until(first)),
                _place: place,
            };
            if admitted.send(Ok(connection)).await.is_err() {
                // The server is shutting down.
                break;
            }
        }
    });
    ReceiverStream::new(stream)
}

/// The next connection of `listener` with a place under `places`, which
/// it keeps until it closes: the place is taken before `accept`, so
/// connections beyond the cap wait in the kernel's backlog instead of
/// holding one of this process's file descriptors, and a failed accept
/// (out of descriptors, a reset before accept) backs off briefly rather
/// than retrying in a tight loop. `None` once `places` is closed. The
/// gRPC port and the metrics port (`what` in the log) accept this way.
pub async fn accept_within(
    listener: &TcpListener,
    places: &Arc<Semaphore>,
    what: &str,
) -> Option<(TcpStream, OwnedSemaphorePermit)> {
    let place = places.clone().acquire_owned().await.ok()?;
    loop {
        match listener.accept().await {
            Ok((stream, _)) => return Some((stream, place)),
            Err(e) => {
                tracing::warn!("accepting a {what} connection: {e}");
                tokio::time::sleep(ACCEPT_BACKOFF).await;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    use tokio::time::timeout;
    use tokio_stream::StreamExt;

    const WAIT: Duration = Duration::from_secs(10);

    const PATIENT: Deadlines = Deadlines {
        handshake: WAIT,
        idle: WAIT,
    };

    #[tokio::test]
    async fn connections_beyond_the_cap_wait_and_all_send_without_delay() {
        let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
        let addr = listener.local_addr().expect("address");
        let mut connections = incoming(listener, "test", 1, PATIENT, CancellationToken::new());
        let _first_client = timeout(WAIT, TcpStream::connect(addr))
            .await
            .expect("connects in time")
            .expect("connects");
        let first = timeout(WAIT, connections.next())
            .await
            .expect("admitted in time")
            .expect("a connection")
            .expect("accepted");
        assert!(first.stream.nodelay().expect("option"));

        let _second_client = timeout(WAIT, TcpStream::connect(addr))
            .await
            .expect("connects in time (the kernel's backlog)")
            .expect("connects");
        // At the cap: the second waits for a place...
        assert!(
            timeout(Duration::from_millis(300), connections.next())
                .await
                .is_err(),
            "a second connection was admitted past a cap of 1"
        );
        // ...and gets it once the first closes.
        drop(first);
        let second = timeout(WAIT, connections.next())
            .await
            .expect("admitted once a place is free")
            .expect("a connection")
            .expect("accepted");
        assert!(second.stream.nodelay().expect("option"));
    }

    #[tokio::test]
    async fn a_connection_that_earns_nothing_fails_at_its_deadline_and_frees_its_place() {
        let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
        let addr = listener.local_addr().expect("address");
        let brief = Deadlines {
            handshake: Duration::from_millis(200),
            idle: WAIT,
        };
        let mut connections = incoming(listener, "test", 1, brief, CancellationToken::new());
        let mut speaking = timeout(WAIT, TcpStream::connect(addr))
            .await
            .expect("connects in time")
            .expect("connects");
        speaking.write_all(b"PRI").await.expect("speaks");
        let mut admitted = timeout(WAIT, connections.next())
            .await
            .expect("admitted")
            .expect("a connection")
            .expect("accepted");
        let _waiting = timeout(WAIT, TcpStream::connect(addr))
            .await
            .expect("connects in time")
            .expect("connects");
        // Bytes do not earn a place: reads fail once the deadline passes...
        let mut buf = [0u8; 8];
        let read = timeout(WAIT, async {
            loop {
                match admitted.read(&mut buf).await {
                    Ok(n) if n > 0 => continue,
                    other => return other,
                }
            }
        })
        .await
        .expect("fails in time");
        let error = read.expect_err("the deadline passed");
        assert_eq!(error.kind(), io::ErrorKind::TimedOut, "{error}");
        // ...and dropping it admits the one waiting.
        drop(admitted);
        let next = timeout(WAIT, connections.next())
            .await
            .expect("admitted once the first is gone")
            .expect("a connection")
            .expect("accepted");
        // An authenticated call earns the place past the handshake.
        next.connection.earn();
        let mut next = next;
        let pending = timeout(Duration::from_millis(500), next.read(&mut buf)).await;
        assert!(
            pending.is_err(),
            "an earned connection was closed: {pending:?}"
        );
    }
}
