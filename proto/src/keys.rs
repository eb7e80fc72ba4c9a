//! Zenoh key expressions of the protocol. One family per session:
//!
//! - `meshless/v1/sessions/{id}/frames`: every published [`Frame`](crate::v1::Frame)
//!   (drop on congestion),
//! - `meshless/v1/sessions/{id}/status`: every [`SessionStatus`](crate::v1::SessionStatus)
//!   change (reliable),
//! - `meshless/v1/sessions/{id}/latest`: a queryable answering with the most
//!   recent frame, for late joiners.
//!
//! And one per named server: a liveliness token on
//! `meshless/v1/servers/{name}`, alive while the server's zenoh session
//! reaches the subscriber (a partition or a stop withdraws it).

/// Root of every key expression the server publishes.
pub const ROOT: &str = "meshless/v1/sessions";

/// `meshless/v1/sessions/{session_id}`.
pub fn session_prefix(session_id: &str) -> String {
    format!("{ROOT}/{session_id}")
}

/// Where a session's frames are put.
pub fn frames(session_id: &str) -> String {
    format!("{ROOT}/{session_id}/frames")
}

/// Where a session's status changes are put.
pub fn status(session_id: &str) -> String {
    format!("{ROOT}/{session_id}/status")
}

/// The queryable that answers with a session's latest frame.
pub fn latest(session_id: &str) -> String {
    format!("{ROOT}/{session_id}/latest")
}

/// Frames of every session, for a subscriber that watches them all.
pub const ALL_FRAMES: &str = "meshless/v1/sessions/*/frames";

/// Root of the servers' liveliness tokens.
pub const SERVERS: &str = "meshless/v1/servers";

/// The liveliness token a server named `name` declares.
pub fn server(name: &str) -> String {
    format!("{SERVERS}/{name}")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Python package and other clients build these strings by hand from
    /// the documented layout; this pins the layout.
    #[test]
    fn key_expressions_follow_the_documented_layout() {
        assert_eq!(frames("abc"), "meshless/v1/sessions/abc/frames");
        assert_eq!(status("abc"), "meshless/v1/sessions/abc/status");
        assert_eq!(server("meshless-0"), "meshless/v1/servers/meshless-0");
        assert_eq!(latest("abc"), "meshless/v1/sessions/abc/latest");
        assert_eq!(session_prefix("abc"), "meshless/v1/sessions/abc");
    }
}
