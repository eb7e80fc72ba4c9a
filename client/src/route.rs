//! Routing a call to the replica that holds its session.
//!
//! A server started with `--server-name NAME` makes session ids of the
//! form `NAME-` and 16 hex digits, so the id alone tells which replica
//! holds a session. A [`Route`] turns that name into the replica's URL
//! from a template such as `https://{server}.meshless-replicas:50051`
//! (a Kubernetes StatefulSet's per-pod DNS names, or compose's service
//! names). No directory is consulted: routing works while zenoh is down
//! and needs nothing but the id.

use crate::ClientError;

/// Length of the part of an id the server makes up (hex digits).
const OWN_PART_LEN: usize = 16;

/// Longest template accepted; a URL, not a document.
const MAX_TEMPLATE_LEN: usize = 512;

/// The name of the server that made `session_id`, or `None` for an id of
/// an unnamed server (16 hex digits alone) or one of no known form.
pub fn server_of(session_id: &str) -> Option<&str> {
    let (server, own) = session_id.rsplit_once('-')?;
    let named = !server.is_empty()
        && own.len() == OWN_PART_LEN
        && own.bytes().all(|b| b.is_ascii_hexdigit());
    named.then_some(server)
}

/// A URL template with one `{server}` placeholder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Route {
    template: String,
}

impl Route {
    /// # Errors
    /// [`ClientError::Route`] for a template without exactly one
    /// `{server}`, or longer than 512 bytes.
    pub fn new(template: &str) -> Result<Self, ClientError> {
        if template.len() > MAX_TEMPLATE_LEN || template.matches("{server}").count() != 1 {
            return Err(ClientError::Route(format!(
                "a route template holds `{{server}}` once, e.g. \
                 `https://{{server}}.meshless-replicas:50051` (at most {MAX_TEMPLATE_LEN} bytes)"
            )));
        }
        Ok(Self {
            template: template.to_owned(),
        })
    }

    /// The URL of the replica that holds `session_id`.
    ///
    /// # Errors
    /// [`ClientError::Route`] when the id names no server.
    pub fn url_for(&self, session_id: &str) -> Result<String, ClientError> {
        let server = server_of(session_id).ok_or_else(|| {
            let shown: String = session_id.chars().take(64).collect();
            ClientError::Route(format!(
                "session id {shown:?} names no server (ids of a server with --server-name \
                 are NAME- and 16 hex digits); call its server with --server instead"
            ))
        })?;
        Ok(self.template.replace("{server}", server))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_name_their_server() {
        assert_eq!(server_of("meshless-1-3f2a9c0d4b1e7a65"), Some("meshless-1"));
        assert_eq!(server_of("a-0123456789abcdef"), Some("a"));
        for unnamed in [
            "3f2a9c0d4b1e7a65",
            "-3f2a9c0d4b1e7a65",
            "meshless-1-3f2a9c0d4b1e7a6",
            "meshless-1-3f2a9c0d4b1e7a650",
            "meshless-1-3f2a9c0d4b1e7a6z",
            "",
        ] {
            assert_eq!(server_of(unnamed), None, "{unnamed}");
        }
    }

    #[test]
    fn a_route_fills_in_the_server() {
        let route = Route::new("https://{server}.meshless-replicas:50051").expect("valid");
        assert_eq!(
            route.url_for("meshless-0-00000000000000ff").expect("named"),
            "https://meshless-0.meshless-replicas:50051"
        );
        let unnamed = route.url_for("00000000000000ff").expect_err("unnamed");
        assert!(unnamed.to_string().contains("names no server"), "{unnamed}");
    }

    #[test]
    fn templates_hold_the_placeholder_once() {
        for bad in [
            "https://meshless:50051",
            "https://{server}.{server}:50051",
            &format!("https://{{server}}/{}", "x".repeat(MAX_TEMPLATE_LEN)),
        ] {
            assert!(Route::new(bad).is_err(), "{bad}");
        }
    }
}
