//! Errors of the service and their one mapping to gRPC status codes.

#![warn(clippy::wildcard_enum_match_arm)]

use meshless_engine::SceneError;
use meshless_engine::design::DesignError;
use meshless_proto::v1::SessionState;
use meshless_wire::WireError;
use tonic::{Code, Status};

/// Why a request was refused. Every message says what to change.
#[derive(Debug, Clone, thiserror::Error)]
pub enum ServiceError {
    #[error("{field}: {message}")]
    InvalidArgument { field: String, message: String },
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("no session with id {0:?}; list the sessions to see which exist")]
    NotFound(String),
    #[error("session {0} has no design yet; run Optimize first")]
    NoDesign(String),
    #[error(transparent)]
    Design(#[from] DesignError),
    #[error("cannot {action} session {session_id} while it is {state}; {hint}")]
    WrongState {
        session_id: String,
        state: &'static str,
        action: &'static str,
        hint: &'static str,
    },
    #[error("session {session_id} is faulted ({reason}); reset or delete it")]
    Faulted { session_id: String, reason: String },
    #[error("this server already holds {limit} sessions, its limit; delete one first")]
    TooManySessions { limit: u32 },
    #[error("session {0} stopped and no longer takes commands; delete it")]
    SessionGone(String),
    #[error("internal error: {0}")]
    Internal(String),
}

impl ServiceError {
    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::InvalidArgument {
            field: field.into(),
            message: message.into(),
        }
    }

    /// The gRPC code of this error.
    pub fn code(&self) -> Code {
        match self {
            Self::InvalidArgument { .. } => Code::InvalidArgument,
            Self::Scene(scene) => match scene {
                SceneError::Invalid { .. } | SceneError::Parse(_) => Code::InvalidArgument,
                SceneError::TooManyParticles { .. } => Code::ResourceExhausted,
            },
            Self::NotFound(_) | Self::NoDesign(_) => Code::NotFound,
            Self::Design(design) => match design {
                DesignError::Parameter { .. }
                | DesignError::Constraint(_)
                | DesignError::Problem(_)
                | DesignError::Unsupported { .. }
                | DesignError::Surface(_) => Code::InvalidArgument,
                DesignError::Diverged { .. } => Code::Aborted,
                DesignError::Cancelled { .. } => Code::Cancelled,
            },
            Self::WrongState { .. } | Self::Faulted { .. } => Code::FailedPrecondition,
            Self::TooManySessions { .. } => Code::ResourceExhausted,
            Self::SessionGone(_) => Code::Unavailable,
            Self::Internal(_) => Code::Internal,
        }
    }
}

/// A message that does not convert is a bad argument, named by its path.
impl From<WireError> for ServiceError {
    fn from(error: WireError) -> Self {
        let WireError { field, message } = error;
        Self::InvalidArgument { field, message }
    }
}

impl From<ServiceError> for Status {
    fn from(error: ServiceError) -> Self {
        Status::new(error.code(), error.to_string())
    }
}

/// Lower-case name of a state, for messages.
pub fn state_name(state: SessionState) -> &'static str {
    match state {
        SessionState::Unspecified => "unspecified",
        SessionState::Idle => "idle",
        SessionState::Running => "running",
        SessionState::Paused => "paused",
        SessionState::Finished => "finished",
        SessionState::Faulted => "faulted",
        SessionState::Closed => "closed",
    }
}
