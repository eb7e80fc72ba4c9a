//! Who a request comes from: bearer tokens checked by an interceptor in
//! front of the simulation service, and the client instance that drives a
//! session.
//!
//! Each token belongs to a named *principal*. A request carries it as
//! `authorization: Bearer TOKEN`; without tokens configured (allowed only
//! on a loopback address) every caller is the principal `anonymous`. A
//! request may also name its client instance (`meshless-client: ID`) and
//! ask to take control of a session another instance drives
//! (`meshless-take-over: true`); see [`Caller::controller`].

use std::fmt;
use std::path::Path;
use std::sync::Arc;
use tonic::{Request, Status};

/// Metadata key of the bearer token.
pub const AUTHORIZATION: &str = "authorization";
/// Metadata key naming the client instance.
pub const CLIENT_ID: &str = "meshless-client";
/// Metadata key asking to take control of a session.
pub const TAKE_OVER: &str = "meshless-take-over";

/// The principal of every caller when no token is configured.
pub const ANONYMOUS: &str = "anonymous";

/// Longest principal name or client id, in bytes.
pub const MAX_NAME_BYTES: usize = 64;
/// Shortest token a file may hold: 128 bits as hex or Base64 text.
const MIN_TOKEN_BYTES: usize = 16;
/// Longest token a request may present, far above any generated secret
/// (`openssl rand -hex 32` makes 64 bytes). A longer one is refused by
/// name before it is compared; the server's header limit leaves room
/// for it so that it reaches this check instead of an HTTP 431, which
/// clients show as UNKNOWN.
pub const MAX_TOKEN_BYTES: usize = 4096;

/// Longest tokens file read: a line of a name and a token is about a
/// hundred bytes, so this holds some ten thousand principals.
pub const MAX_TOKENS_FILE_BYTES: u64 = 1 << 20;

/// A request's caller, put into the request's extensions by
/// [`Authenticator`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Caller {
    /// The principal the token belongs to, or [`ANONYMOUS`].
    pub principal: Arc<str>,
    /// The client instance, when the request names one.
    pub client: Option<Arc<str>>,
    /// Whether the request takes control of a session another client
    /// instance drives.
    pub take_over: bool,
}

impl Caller {
    /// Who drives a session when this caller does: its client instance
    /// (`principal/client`), or the principal alone for clients that name
    /// no instance (each `meshless session ...` command is its own
    /// process, yet the same user).
    pub fn controller(&self) -> String {
        match &self.client {
            Some(client) => format!("{}/{client}", self.principal),
            None => self.principal.to_string(),
        }
    }
}

/// The tokens a server accepts, by principal.
#[derive(Clone, PartialEq, Eq)]
pub struct Tokens {
    entries: Vec<(Arc<str>, Vec<u8>)>,
}

/// Tokens are secrets: never printed, not even in debug output.
impl fmt::Debug for Tokens {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Tokens")
            .field(
                "principals",
                &self.entries.iter().map(|e| &e.0).collect::<Vec<_>>(),
            )
            .finish()
    }
}

impl Tokens {
    /// Parses `NAME TOKEN` lines (blank lines and `#` comments skipped);
    /// `origin` names the source in errors. Names are at most 64 bytes of
    /// letters, digits, `.`, `_`, `-`; tokens at least 16 visible ASCII
    /// characters; neither may repeat.
    ///
    /// # Errors
    /// A message naming the line, never the token.
    pub fn parse(text: &str, origin: &str) -> Result<Self, String> {
        let mut entries: Vec<(Arc<str>, Vec<u8>)> = Vec::new();
        for (n, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let at = format!("{origin}, line {}", n + 1);
            let mut words = line.split_whitespace();
            let (Some(name), Some(token), None) = (words.next(), words.next(), words.next()) else {
                return Err(format!("{at}: write `NAME TOKEN`, two words"));
            };
            check_name(name).map_err(|e| format!("{at}: principal {e}"))?;
            if token.len() < MIN_TOKEN_BYTES || !token.bytes().all(|b| b.is_ascii_graphic()) {
                return Err(format!(
                    "{at}: the token must be at least {MIN_TOKEN_BYTES} visible ASCII characters \
                     (e.g. `openssl rand -hex 32`)"
                ));
            }
            if entries.iter().any(|(n, _)| &**n == name) {
                return Err(format!("{at}: principal {name:?} is named twice"));
            }
            if entries.iter().any(|(_, t)| t == token.as_bytes()) {
                return Err(format!(
                    "{at}: this token is given to another principal too"
                ));
            }
            entries.push((name.into(), token.as_bytes().to_vec()));
        }
        if entries.is_empty() {
            return Err(format!("{origin} names no token"));
        }
        Ok(Self { entries })
    }

    /// Reads a tokens file, a regular file of at most
    /// [`MAX_TOKENS_FILE_BYTES`] ([`crate::files`]); see [`Tokens::parse`].
    ///
    /// # Errors
    /// An unreadable file, one that is not regular or too large, or a bad
    /// line.
    pub fn from_file(path: &Path) -> Result<Self, String> {
        let text = crate::files::read_regular_text(path, MAX_TOKENS_FILE_BYTES)
            .map_err(|e| format!("cannot read the tokens file {}: {e}", path.display()))?;
        Self::parse(&text, &path.display().to_string())
    }

    /// The principals, in file order.
    pub fn principals(&self) -> impl Iterator<Item = &str> {
        self.entries.iter().map(|(name, _)| &**name)
    }

    /// The principal `presented` belongs to. Compares against every token
    /// in time independent of where they differ, so timing tells an
    /// attacker nothing about how close a guess came.
    fn principal(&self, presented: &[u8]) -> Option<Arc<str>> {
        let mut found = None;
        for (name, token) in &self.entries {
            if constant_time_eq(token, presented) {
                found = Some(name.clone());
            }
        }
        found
    }
}

/// Whether `a == b`, in time that depends on their lengths only.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Checks a principal name, client id or observer: the one rule for all
/// three, so a name that may own a session may also observe one.
pub(crate) fn check_name(name: &str) -> Result<(), String> {
    let allowed = |c: char| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-');
    if name.is_empty() || name.len() > MAX_NAME_BYTES || !name.chars().all(allowed) {
        return Err(format!(
            "must be 1 to {MAX_NAME_BYTES} letters, digits, '.', '_' or '-'"
        ));
    }
    Ok(())
}

/// The interceptor in front of the simulation service: checks the token
/// and records the [`Caller`].
#[derive(Debug, Clone)]
pub struct Authenticator {
    tokens: Option<Arc<Tokens>>,
}

impl Authenticator {
    /// Checks `tokens`; `None` lets every caller in as [`ANONYMOUS`].
    pub fn new(tokens: Option<Tokens>) -> Self {
        Self {
            tokens: tokens.map(Arc::new),
        }
    }

    fn principal<T>(&self, request: &Request<T>) -> Result<Arc<str>, Status> {
        let Some(tokens) = &self.tokens else {
            return Ok(ANONYMOUS.into());
        };
        let value = request.metadata().get(AUTHORIZATION).ok_or_else(|| {
            Status::unauthenticated(
                "this server needs a token: send `authorization: Bearer TOKEN` \
                 (meshless --token, MESHLESS_TOKEN)",
            )
        })?;
        let presented = value
            .as_bytes()
            .strip_prefix(b"Bearer ")
            .ok_or_else(|| Status::unauthenticated("write the token as `Bearer TOKEN`"))?;
        if presented.len() > MAX_TOKEN_BYTES {
            return Err(Status::unauthenticated(format!(
                "the token is {} bytes; a token has at most {MAX_TOKEN_BYTES}: send the one \
                 the server's tokens file holds",
                presented.len()
            )));
        }
        tokens.principal(presented).ok_or_else(|| {
            Status::unauthenticated("the token is not one this server accepts; check it")
        })
    }
}

impl tonic::service::Interceptor for Authenticator {
    fn call(&mut self, mut request: Request<()>) -> Result<Request<()>, Status> {
        let principal = self.principal(&request)?;
        // The call passed the token check: its connection has earned its
        // place under --max-connections (`crate::connection`).
        if let Some(connection) = request.extensions().get::<crate::connection::Connection>() {
            connection.earn();
        }
        let client = match request.metadata().get(CLIENT_ID) {
            None => None,
            Some(value) => {
                let id = value
                    .to_str()
                    .map_err(|_| "must be visible ASCII".to_owned())
                    .and_then(|id| check_name(id).map(|()| id))
                    .map_err(|e| Status::invalid_argument(format!("{CLIENT_ID}: {e}")))?;
                Some(Arc::from(id))
            }
        };
        let take_over = match request.metadata().get(TAKE_OVER).map(|v| v.as_bytes()) {
            None | Some(b"false") => false,
            Some(b"true") => true,
            Some(_) => {
                return Err(Status::invalid_argument(format!(
                    "{TAKE_OVER}: must be `true` or `false`"
                )));
            }
        };
        request.extensions_mut().insert(Caller {
            principal,
            client,
            take_over,
        });
        Ok(request)
    }
}

/// The caller a request's extensions hold.
///
/// # Errors
/// UNAUTHENTICATED when no [`Authenticator`] ran: a request that reached
/// the service some other way is trusted with nothing.
pub fn caller<T>(request: &Request<T>) -> Result<Caller, Status> {
    request
        .extensions()
        .get::<Caller>()
        .cloned()
        .ok_or_else(|| Status::unauthenticated("the request was not authenticated"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tonic::Code;
    use tonic::service::Interceptor;

    const FILE: &str = "# who may call\nalice 0123456789abcdef0123\n\nbob   fedcba9876543210fedc\n";

    fn request(headers: &[(&'static str, &str)]) -> Request<()> {
        let mut request = Request::new(());
        for (key, value) in headers {
            request
                .metadata_mut()
                .insert(*key, value.parse().expect("ascii"));
        }
        request
    }

    #[test]
    fn tokens_files_are_checked_line_by_line_without_echoing_tokens() {
        let tokens = Tokens::parse(FILE, "tokens").expect("valid");
        assert_eq!(tokens.principals().collect::<Vec<_>>(), ["alice", "bob"]);
        assert!(!format!("{tokens:?}").contains("0123456789"));
        for (text, expected) in [
            ("alice", "line 1: write `NAME TOKEN`"),
            ("alice short", "line 1: the token must be at least 16"),
            ("al/ce 0123456789abcdef0123", "line 1: principal must be"),
            (
                "a 0123456789abcdef0123\na 0123456789abcdef9999",
                "line 2: principal \"a\" is named twice",
            ),
            (
                "a 0123456789abcdef0123\nb 0123456789abcdef0123",
                "line 2: this token is given to another principal too",
            ),
            ("# nothing\n", "names no token"),
        ] {
            let err = Tokens::parse(text, "tokens").expect_err(text);
            assert!(err.contains(expected), "{text:?}: {err}");
            assert!(!err.contains("0123456789abcdef"), "{err}");
        }
    }

    #[test]
    fn the_interceptor_names_the_caller_or_refuses() {
        let mut auth = Authenticator::new(Some(Tokens::parse(FILE, "t").expect("valid")));
        let ok = auth
            .call(request(&[
                (AUTHORIZATION, "Bearer fedcba9876543210fedc"),
                (CLIENT_ID, "notebook-1"),
                (TAKE_OVER, "true"),
            ]))
            .expect("bob");
        let bob = caller(&ok).expect("caller");
        assert_eq!(&*bob.principal, "bob");
        assert_eq!(bob.controller(), "bob/notebook-1");
        assert!(bob.take_over);

        for (headers, code) in [
            (vec![], Code::Unauthenticated),
            (
                vec![(AUTHORIZATION, "fedcba9876543210fedc")],
                Code::Unauthenticated,
            ),
            (
                vec![(AUTHORIZATION, "Bearer fedcba9876543210fedX")],
                Code::Unauthenticated,
            ),
            (
                vec![(AUTHORIZATION, "Bearer fedcba9876543210fed")],
                Code::Unauthenticated,
            ),
            (
                vec![
                    (AUTHORIZATION, "Bearer fedcba9876543210fedc"),
                    (CLIENT_ID, "a b"),
                ],
                Code::InvalidArgument,
            ),
            (
                vec![
                    (AUTHORIZATION, "Bearer fedcba9876543210fedc"),
                    (TAKE_OVER, "yes"),
                ],
                Code::InvalidArgument,
            ),
        ] {
            let status = auth.call(request(&headers)).expect_err("refused");
            assert_eq!(status.code(), code, "{headers:?}: {status:?}");
        }

        // An oversized token is refused by its size, never echoed.
        let giant = format!("Bearer {}", "x".repeat(16 << 10));
        let status = auth
            .call(request(&[(AUTHORIZATION, &giant)]))
            .expect_err("too long");
        assert_eq!(status.code(), Code::Unauthenticated);
        assert!(
            status.message().contains("16384 bytes") && status.message().contains("at most 4096"),
            "{}",
            status.message()
        );
        assert!(!status.message().contains("xxxx"), "{}", status.message());

        let mut open = Authenticator::new(None);
        let ok = open.call(request(&[])).expect("anonymous");
        assert_eq!(caller(&ok).expect("caller").controller(), ANONYMOUS);
        assert_eq!(
            caller(&Request::new(()))
                .expect_err("no interceptor")
                .code(),
            Code::Unauthenticated
        );
    }

    #[test]
    fn comparison_is_exact() {
        assert!(constant_time_eq(b"abc", b"abc"));
        assert!(!constant_time_eq(b"abc", b"abd"));
        assert!(!constant_time_eq(b"abc", b"abcd"));
        assert!(!constant_time_eq(b"", b"a"));
    }
}
