//! The error of a message that does not convert, and the helper that
//! turns a missing message into one.

/// Why a message does not convert to the engine's type: the field's path
/// in the message (`systems[1].shape.kind`) and what to change. The server
/// answers it as `INVALID_ARGUMENT` with the text `{field}: {message}`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct WireError {
    /// Path of the offending field in the message.
    pub field: String,
    /// What is wrong with it and what to change.
    pub message: String,
}

impl WireError {
    /// An error of the field at path `field`.
    pub fn new(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            message: message.into(),
        }
    }
}

/// The result of a conversion.
pub(crate) type Result<T> = std::result::Result<T, WireError>;

/// The message in an optional field that the conversion needs.
pub(crate) fn required<T>(value: Option<T>, field: &str) -> Result<T> {
    value.ok_or_else(|| WireError::new(field, "is required"))
}
