//! Errors of the service and their one mapping to gRPC status codes.

#![warn(clippy::wildcard_enum_match_arm)]

use meshless_engine::SceneError;
use meshless_engine::design::DesignError;
use meshless_engine::world::{ChangeError, InsertError, RemoveError};
use meshless_proto::snapshot::BlobError;
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
    /// The id, already [`quote`]d, names no session.
    #[error("no session with id {0}; list the sessions to see which exist")]
    NotFound(String),
    #[error("session {0} has no design yet; run Optimize first")]
    NoDesign(String),
    #[error(transparent)]
    Design(#[from] DesignError),
    /// A ChangeParticles request the world refused.
    #[error(transparent)]
    Particles(#[from] ChangeError),
    #[error("cannot {action} session {session_id} while it is {state}; {hint}")]
    WrongState {
        session_id: String,
        state: &'static str,
        action: &'static str,
        hint: &'static str,
    },
    #[error("session {session_id} is faulted ({reason}); reset or delete it")]
    Faulted { session_id: String, reason: String },
    /// A stepping call is in progress; `call` says which and how far.
    #[error(
        "cannot {action} session {session_id} while it is stepping for another call ({call}); \
         wait for that call to end, or cancel it (or Pause the session)"
    )]
    Stepping {
        session_id: String,
        action: &'static str,
        call: String,
    },
    /// Taking `steps` more steps would pass the largest step count.
    #[error(
        "session {session_id} is at step {step}, and {steps} more would pass {}, the largest \
         step count, which never wraps: ask for at most {} steps, or reset the session or \
         restore an earlier snapshot", u64::MAX, u64::MAX - step
    )]
    StepCounterFull {
        session_id: String,
        step: u64,
        steps: u64,
    },
    #[error("this server already holds {limit} sessions, its limit; delete one first")]
    TooManySessions { limit: u32 },
    /// The scene's memory estimate does not fit what the budget has left.
    #[error(
        "this scene needs about {needed_mb} MB and the server has {free_mb} MB of its \
         {budget_mb} MB memory budget left; use fewer particles (a coarser spacing) or \
         delete a session"
    )]
    MemoryBudget {
        /// The scene's estimate, MB.
        needed_mb: u64,
        /// What the budget has left, MB.
        free_mb: u64,
        /// The whole budget, MB.
        budget_mb: u64,
    },
    /// The caller may not `action` a session it neither owns nor
    /// observes (or, to drive it, does not own).
    #[error(
        "session {session_id} belongs to another principal; you may not {action} it \
         (its owner can name you among its `observers` to let you see it)"
    )]
    PermissionDenied {
        /// The session, [`quote`]d.
        session_id: String,
        /// What was refused.
        action: &'static str,
    },
    /// An observer of the session asked to `action` it: observers see,
    /// only the owner drives.
    #[error(
        "you observe session {session_id}: you may see it but not {action} it; only its \
         owner `{owner}` drives it"
    )]
    ObserverMayNotDrive {
        /// The session, [`quote`]d.
        session_id: String,
        /// What was refused.
        action: &'static str,
        /// The owner's principal.
        owner: String,
    },
    /// Another client instance of the owner drives the session.
    #[error(
        "session {session_id} is driven by client {controller}; take control with \
         `meshless-take-over: true` (meshless --take-over) or leave it to that client"
    )]
    ControlledElsewhere {
        /// The session.
        session_id: String,
        /// Who drives it: `principal/client`, or the principal alone.
        controller: String,
    },
    /// A blob that is not a snapshot of this build, or is over the limit.
    #[error("data: {0}")]
    Snapshot(#[from] BlobError),
    /// The session's snapshot would pass the limit.
    #[error(
        "the snapshot would have {size} bytes, over this server's limit of {limit} \
         (--max-snapshot-mb); raise the limit or snapshot a smaller scene"
    )]
    SnapshotTooLarge {
        /// Its size.
        size: usize,
        /// The limit.
        limit: usize,
    },
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
                SceneError::TooManyParticles { .. }
                | SceneError::TooFine { .. }
                | SceneError::OverBudget { .. } => Code::ResourceExhausted,
                SceneError::Cancelled => Code::Cancelled,
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
            Self::Particles(change) => match change {
                ChangeError::Insert(InsertError::Capacity { .. }) => Code::ResourceExhausted,
                ChangeError::Insert(InsertError::IdsExhausted { .. }) => Code::ResourceExhausted,
                ChangeError::Remove(
                    RemoveError::NoSystem { .. }
                    | RemoveError::Unsupported { .. }
                    | RemoveError::NoParticle { .. },
                )
                | ChangeError::Insert(
                    InsertError::NoSystem { .. }
                    | InsertError::Unsupported { .. }
                    | InsertError::Lengths { .. }
                    | InsertError::Invalid { .. },
                ) => Code::InvalidArgument,
            },
            Self::WrongState { .. }
            | Self::Faulted { .. }
            | Self::Stepping { .. }
            | Self::StepCounterFull { .. } => Code::FailedPrecondition,
            Self::TooManySessions { .. } | Self::MemoryBudget { .. } => Code::ResourceExhausted,
            Self::PermissionDenied { .. } | Self::ObserverMayNotDrive { .. } => {
                Code::PermissionDenied
            }
            Self::ControlledElsewhere { .. } => Code::Aborted,
            Self::Snapshot(blob) => match blob {
                BlobError::TooLarge { .. } => Code::ResourceExhausted,
                BlobError::NotASnapshot
                | BlobError::Truncated { .. }
                | BlobError::Format { .. }
                | BlobError::Build { .. }
                | BlobError::Trailing { .. }
                | BlobError::Checksum
                | BlobError::Payload(_) => Code::InvalidArgument,
            },
            Self::SnapshotTooLarge { .. } => Code::ResourceExhausted,
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
    /// The code and a message cut to [`MAX_MESSAGE_CHARS`]: a message
    /// travels in an HTTP/2 header, and one that quotes a long input would
    /// overflow it and reach the client as RESOURCE_EXHAUSTED instead of
    /// the real code.
    fn from(error: ServiceError) -> Self {
        Status::new(
            error.code(),
            truncate(&error.to_string(), MAX_MESSAGE_CHARS),
        )
    }
}

/// Longest status message, in characters.
pub const MAX_MESSAGE_CHARS: usize = 1024;

/// Longest piece of client input a message quotes, in characters.
const MAX_QUOTE_CHARS: usize = 64;

/// `message` cut to the length a status message may have.
pub fn truncate_message(message: &str) -> String {
    truncate(message, MAX_MESSAGE_CHARS)
}

/// `text` cut to at most `max` characters, marked when cut.
fn truncate(text: &str, max: usize) -> String {
    match text.char_indices().nth(max) {
        None => text.to_owned(),
        Some((end, _)) => format!("{}... ({} bytes in all)", &text[..end], text.len()),
    }
}

/// Client input as an error message may quote it: debug-escaped (no
/// control characters reach a log or a terminal) and cut to a short prefix.
pub fn quote(input: &str) -> String {
    truncate(&format!("{input:?}"), MAX_QUOTE_CHARS)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_quote_a_short_prefix_of_the_input() {
        let long = "x".repeat(20_000);
        let quoted = quote(&long);
        assert!(quoted.chars().count() < 100, "{quoted}");
        assert!(quoted.contains("20002 bytes in all"), "{quoted}");
        assert_eq!(quote("ab\ncd"), "\"ab\\ncd\"");
        // Multi-byte characters are cut at a character boundary.
        let wide = "\u{e9}".repeat(1000);
        assert!(quote(&wide).starts_with("\"\u{e9}"));
    }

    #[test]
    fn status_messages_are_bounded() {
        let error = ServiceError::invalid("name", "y".repeat(1 << 20));
        let status = Status::from(error);
        assert_eq!(status.code(), Code::InvalidArgument);
        assert!(status.message().len() < MAX_MESSAGE_CHARS + 64);
    }

    #[test]
    fn scene_errors_map_to_what_the_caller_should_do() {
        for (error, code) in [
            (SceneError::Parse("bad".into()), Code::InvalidArgument),
            (
                SceneError::TooManyParticles { count: 2, limit: 1 },
                Code::ResourceExhausted,
            ),
            (SceneError::Cancelled, Code::Cancelled),
        ] {
            assert_eq!(Status::from(ServiceError::Scene(error)).code(), code);
        }
    }
}
