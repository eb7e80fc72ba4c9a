//! Errors of the client library.

/// Why a client call failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// [`crate::Client::connect`] could not reach a server at `url`, or
    /// `url` is malformed; check the address (e.g.
    /// `http://127.0.0.1:50051`) and that the server is running there.
    #[error("cannot connect to {url}: {message}")]
    Connect {
        /// The address given.
        url: String,
        /// The transport error with its causes (e.g. `Connection refused`).
        message: String,
    },
    /// The server refused the request; the status says why.
    #[error("{}: {}", .0.code(), .0.message())]
    Rpc(#[from] tonic::Status),
    /// A zenoh operation failed: no endpoint given or reachable, or a
    /// subscription or query refused; the message names the operation.
    /// Check the endpoints (e.g. the server's `zenoh_locators`).
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// A frame, design or optimisation event from the server failed a
    /// consistency check (a missing field, an unknown kind, lengths that
    /// disagree); the message names the check. The server's data is at
    /// fault, not the request: check that client and server share a
    /// protocol version.
    #[error("malformed frame: {0}")]
    Decode(String),
    /// A scene file, or a mesh file it names, could not be read or
    /// parsed; the message names the file.
    #[error("{0}")]
    Scene(String),
    /// A session id or a route template that cannot route a call to a
    /// replica ([`crate::Route`]); the message says what to change.
    #[error("{0}")]
    Route(String),
    /// A stream ended before its result: the zenoh session closed, or an
    /// optimisation stream ended without a design.
    #[error("the server closed the stream")]
    Closed,
}

impl ClientError {
    /// The gRPC code, when the server refused the request.
    pub fn code(&self) -> Option<tonic::Code> {
        match self {
            Self::Rpc(status) => Some(status.code()),
            _ => None,
        }
    }
}
