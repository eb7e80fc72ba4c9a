//! A hostile HTTP/2 client written frame by frame: it opens streams past
//! the server's limit, never grants flow-control window, and counts what
//! the server answers. Well-behaved clients (tonic, `h2`) obey the
//! server's settings, so they cannot show what happens to one that does
//! not (RFC 9113, sections 4.1, 6 and 6.9).

use std::collections::HashSet;
use std::sync::{Arc, Mutex};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::net::tcp::OwnedWriteHalf;

const PREFACE: &[u8] = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n";
const DATA: u8 = 0x0;
const HEADERS: u8 = 0x1;
const RST_STREAM: u8 = 0x3;
const SETTINGS: u8 = 0x4;
const PING: u8 = 0x6;
const GOAWAY: u8 = 0x7;
const END_STREAM: u8 = 0x1;
const ACK: u8 = 0x1;
const END_HEADERS: u8 = 0x4;
const SETTINGS_INITIAL_WINDOW_SIZE: u16 = 0x4;
const REFUSED_STREAM: u32 = 0x7;

/// What the server has sent on a [`RawH2`] connection so far.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Answers {
    /// HEADERS frames that end their stream: an answer with no body
    /// (gRPC's trailers-only refusals).
    pub ended: usize,
    /// HEADERS frames that open a response with a body to come.
    pub opened: usize,
    /// Streams reset with REFUSED_STREAM.
    pub refused: usize,
    /// Streams reset with another code.
    pub reset: usize,
    /// DATA bytes received.
    pub data_bytes: usize,
    /// Whether the server sent GOAWAY or closed the connection.
    pub closed: bool,
    /// The streams that got any answer.
    pub answered: HashSet<u32>,
}

impl Answers {
    /// How many streams got any answer.
    pub fn answered(&self) -> usize {
        self.answered.len()
    }
}

/// A raw HTTP/2 connection to a gRPC server.
#[derive(Debug)]
pub struct RawH2 {
    writer: Arc<tokio::sync::Mutex<OwnedWriteHalf>>,
    answers: Arc<Mutex<Answers>>,
    next_stream: u32,
}

impl RawH2 {
    /// Connects to `addr` (`HOST:PORT`), sends the preface and settings
    /// with a stream window of `stream_window` bytes (0: the server may
    /// send no response body at all), and answers the server's SETTINGS
    /// and PINGs as the protocol requires.
    ///
    /// # Errors
    /// When the connection fails.
    pub async fn connect(addr: &str, stream_window: u32) -> std::io::Result<Self> {
        let stream = TcpStream::connect(addr).await?;
        let (mut reader, writer) = stream.into_split();
        let writer = Arc::new(tokio::sync::Mutex::new(writer));
        let mut settings = Vec::new();
        settings.extend_from_slice(&SETTINGS_INITIAL_WINDOW_SIZE.to_be_bytes());
        settings.extend_from_slice(&stream_window.to_be_bytes());
        {
            let mut w = writer.lock().await;
            w.write_all(PREFACE).await?;
            w.write_all(&frame(SETTINGS, 0, 0, &settings)).await?;
        }
        let answers = Arc::new(Mutex::new(Answers::default()));
        let (seen, replies) = (answers.clone(), writer.clone());
        tokio::spawn(async move {
            let mut header = [0u8; 9];
            loop {
                if reader.read_exact(&mut header).await.is_err() {
                    break;
                }
                let len = u32::from_be_bytes([0, header[0], header[1], header[2]]) as usize;
                let (kind, flags) = (header[3], header[4]);
                let mut payload = vec![0u8; len];
                if reader.read_exact(&mut payload).await.is_err() {
                    break;
                }
                let reply = match kind {
                    SETTINGS if flags & ACK == 0 => Some(frame(SETTINGS, ACK, 0, &[])),
                    PING if flags & ACK == 0 => Some(frame(PING, ACK, 0, &payload)),
                    _ => None,
                };
                if let Some(reply) = reply
                    && replies.lock().await.write_all(&reply).await.is_err()
                {
                    break;
                }
                let mut answers = seen.lock().expect("answers");
                let stream = u32::from_be_bytes([header[5], header[6], header[7], header[8]]);
                if matches!(kind, HEADERS | RST_STREAM) {
                    answers.answered.insert(stream & 0x7fff_ffff);
                }
                match kind {
                    HEADERS if flags & END_STREAM != 0 => answers.ended += 1,
                    HEADERS => answers.opened += 1,
                    DATA => answers.data_bytes += len,
                    RST_STREAM if payload.get(..4) == Some(&REFUSED_STREAM.to_be_bytes()) => {
                        answers.refused += 1;
                    }
                    RST_STREAM => answers.reset += 1,
                    GOAWAY => answers.closed = true,
                    _ => {}
                }
            }
            seen.lock().expect("answers").closed = true;
        });
        Ok(Self {
            writer,
            answers,
            next_stream: 1,
        })
    }

    /// Opens a stream calling gRPC method `path` (`/pkg.Service/Method`)
    /// with `headers` besides the protocol's own; with `message`, sends it
    /// and ends the request, without, leaves the request open (the
    /// server waits for its body, the stream stays open).
    ///
    /// # Errors
    /// When the connection is gone.
    pub async fn call(
        &mut self,
        path: &str,
        headers: &[(&str, &str)],
        message: Option<&[u8]>,
    ) -> std::io::Result<()> {
        let stream = self.next_stream;
        self.next_stream += 2;
        let mut block = Vec::new();
        for (name, value) in [
            (":method", "POST"),
            (":scheme", "http"),
            (":path", path),
            (":authority", "localhost"),
            ("content-type", "application/grpc"),
            ("te", "trailers"),
        ]
        .into_iter()
        .chain(headers.iter().copied())
        {
            literal(&mut block, name, value);
        }
        let mut bytes = frame(HEADERS, END_HEADERS, stream, &block);
        if let Some(message) = message {
            let mut body = vec![0u8];
            body.extend_from_slice(&u32::try_from(message.len()).expect("small").to_be_bytes());
            body.extend_from_slice(message);
            bytes.extend_from_slice(&frame(DATA, END_STREAM, stream, &body));
        }
        self.writer.lock().await.write_all(&bytes).await
    }

    /// What the server has answered so far.
    pub fn answers(&self) -> Answers {
        self.answers.lock().expect("answers").clone()
    }
}

/// One frame: RFC 9113 section 4.1.
fn frame(kind: u8, flags: u8, stream: u32, payload: &[u8]) -> Vec<u8> {
    let len = u32::try_from(payload.len()).expect("a small frame");
    let mut out = len.to_be_bytes()[1..].to_vec();
    out.extend_from_slice(&[kind, flags]);
    out.extend_from_slice(&stream.to_be_bytes());
    out.extend_from_slice(payload);
    out
}

/// A header as an HPACK literal without indexing, new name, no Huffman
/// coding (RFC 7541 section 6.2.2).
fn literal(block: &mut Vec<u8>, name: &str, value: &str) {
    block.push(0);
    for text in [name, value] {
        integer(block, text.len(), 7);
        block.extend_from_slice(text.as_bytes());
    }
}

/// An HPACK integer with an `prefix`-bit prefix (RFC 7541 section 5.1).
fn integer(block: &mut Vec<u8>, mut value: usize, prefix: u32) {
    let max = (1usize << prefix) - 1;
    if value < max {
        block.push(value as u8);
        return;
    }
    block.push(max as u8);
    value -= max;
    while value >= 128 {
        block.push((value % 128 + 128) as u8);
        value /= 128;
    }
    block.push(value as u8);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hpack_integers_follow_rfc_7541_examples() {
        let mut out = Vec::new();
        integer(&mut out, 10, 5);
        assert_eq!(out, [10]);
        out.clear();
        integer(&mut out, 1337, 5);
        assert_eq!(out, [31, 154, 10]);
    }
}
