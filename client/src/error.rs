//! Errors of the client library.

/// Why a client call failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("cannot connect to {url}: {message}")]
    Connect { url: String, message: String },
    /// The server refused the request; the status says why.
    #[error("{}: {}", .0.code(), .0.message())]
    Rpc(#[from] tonic::Status),
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error("malformed frame: {0}")]
    Decode(String),
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
