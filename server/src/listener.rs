//! The gRPC listener: at most `max_connections` open at a time, each set
//! up for request-response traffic, accepting under pressure without
//! spinning.
//!
//! The cap is taken before `accept`, so connections beyond it wait in the
//! kernel's backlog instead of holding one of this process's file
//! descriptors (1,100 silent connections once exhausted them). An accept
//! error (out of descriptors, a reset before accept) backs off briefly
//! rather than retrying in a tight loop. A connection that sends nothing
//! within [`FIRST_BYTE_TIMEOUT`] of being accepted is closed, so silent
//! sockets cannot hold every place under the cap.

use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc};
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::sync::CancellationToken;
use tonic::transport::server::{Connected, TcpConnectInfo};

/// Pause after a failed accept.
const ACCEPT_BACKOFF: Duration = Duration::from_millis(50);

/// How long an accepted connection may stay silent before it is closed:
/// a gRPC client sends the HTTP/2 preface at once, so ten seconds covers
/// any real client on a slow link.
pub const FIRST_BYTE_TIMEOUT: Duration = Duration::from_secs(10);

/// An accepted connection holding its place under the cap until it
/// closes.
#[derive(Debug)]
pub struct Admitted {
    stream: TcpStream,
    _place: OwnedSemaphorePermit,
}

impl AsyncRead for Admitted {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_read(cx, buf)
    }
}

impl AsyncWrite for Admitted {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.stream).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.stream).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.stream.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}

impl Connected for Admitted {
    type ConnectInfo = TcpConnectInfo;

    fn connect_info(&self) -> Self::ConnectInfo {
        self.stream.connect_info()
    }
}

/// The connections of `listener`, at most `max_connections` open at
/// once, until `stop` or until the stream is dropped. Each gets
/// `TCP_NODELAY`: a small response held back by Nagle's algorithm until
/// the client's delayed ACK cost about 44 ms per sequential call in the
/// loopback test of issue 13 (`cargo bench -p meshless-load` measures
/// sequential calls; docs/performance.md has its figures).
pub fn incoming(
    listener: TcpListener,
    max_connections: usize,
    first_byte_timeout: Duration,
    stop: CancellationToken,
) -> ReceiverStream<io::Result<Admitted>> {
    let (admitted, stream) = mpsc::channel(1);
    let places = Arc::new(Semaphore::new(max_connections));
    tokio::spawn(async move {
        loop {
            let place = tokio::select! {
                place = places.clone().acquire_owned() => place,
                () = stop.cancelled() => break,
                () = admitted.closed() => break,
            };
            let Ok(place) = place else { break };
            let accepted = tokio::select! {
                accepted = listener.accept() => accepted,
                () = stop.cancelled() => break,
                () = admitted.closed() => break,
            };
            match accepted {
                Ok((stream, _)) => {
                    if let Err(e) = stream.set_nodelay(true) {
                        tracing::debug!("TCP_NODELAY on an accepted connection: {e}");
                        continue;
                    }
                    let connection = Admitted {
                        stream,
                        _place: place,
                    };
                    // Waiting for the first byte must not hold up accept.
                    let admitted = admitted.clone();
                    tokio::spawn(async move {
                        let mut byte = [0u8; 1];
                        let first = tokio::time::timeout(
                            first_byte_timeout,
                            connection.stream.peek(&mut byte),
                        )
                        .await;
                        match first {
                            Ok(Ok(n)) if n > 0 => {
                                // The server may be shutting down.
                                let _ = admitted.send(Ok(connection)).await;
                            }
                            // Silent, closed or failed: dropping it closes
                            // the socket and frees its place.
                            Ok(_) | Err(_) => tracing::debug!("closed a silent connection"),
                        }
                    });
                }
                Err(e) => {
                    tracing::warn!("accepting a gRPC connection: {e}");
                    tokio::time::sleep(ACCEPT_BACKOFF).await;
                }
            }
        }
    });
    ReceiverStream::new(stream)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    use tokio::time::timeout;
    use tokio_stream::StreamExt;

    const WAIT: Duration = Duration::from_secs(10);

    #[tokio::test]
    async fn connections_beyond_the_cap_wait_and_all_send_without_delay() {
        let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
        let addr = listener.local_addr().expect("address");
        let mut connections = incoming(listener, 1, WAIT, CancellationToken::new());
        let mut first_client = timeout(WAIT, TcpStream::connect(addr))
            .await
            .expect("connects in time")
            .expect("connects");
        first_client.write_all(b"P").await.expect("speaks");
        let first = timeout(WAIT, connections.next())
            .await
            .expect("admitted in time")
            .expect("a connection")
            .expect("accepted");
        assert!(first.stream.nodelay().expect("option"));

        let mut second_client = timeout(WAIT, TcpStream::connect(addr))
            .await
            .expect("connects in time (the kernel's backlog)")
            .expect("connects");
        second_client.write_all(b"P").await.expect("speaks");
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
    async fn a_silent_connection_is_closed_and_frees_its_place() {
        let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
        let addr = listener.local_addr().expect("address");
        let silence = Duration::from_millis(200);
        let mut connections = incoming(listener, 1, silence, CancellationToken::new());
        let mut silent = timeout(WAIT, TcpStream::connect(addr))
            .await
            .expect("connects in time")
            .expect("connects");
        let mut speaking = timeout(WAIT, TcpStream::connect(addr))
            .await
            .expect("connects in time")
            .expect("connects");
        speaking.write_all(b"P").await.expect("speaks");
        // The silent one is closed by the server (end of stream)...
        let mut buf = [0u8; 1];
        let read = timeout(WAIT, silent.read(&mut buf))
            .await
            .expect("closed in time");
        assert!(matches!(read, Ok(0) | Err(_)), "{read:?}");
        // ...and its place goes to the one that speaks.
        let admitted = timeout(WAIT, connections.next())
            .await
            .expect("admitted once the silent one is gone")
            .expect("a connection")
            .expect("accepted");
        let mut peeked = [0u8; 1];
        assert_eq!(admitted.stream.peek(&mut peeked).await.expect("peek"), 1);
        assert_eq!(&peeked, b"P");
    }
}
