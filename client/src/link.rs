//! The zenoh side: frame and status subscriptions, latest-frame queries.

use crate::{ClientError, FrameView};
use meshless_proto::seal::SealKey;
use meshless_proto::{keys, v1};
use prost::Message;
use std::sync::{Mutex, PoisonError};
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::Subscriber;
use zenoh::query::{ConsolidationMode, QueryTarget};
use zenoh::sample::Sample;

type Result<T> = std::result::Result<T, ClientError>;

fn zenoh_error(context: &str) -> impl Fn(zenoh::Error) -> ClientError + '_ {
    move |e| ClientError::Zenoh(format!("{context}: {e}"))
}

/// A session to subscribe to: its id and, when the server seals its
/// payloads (`ServerInfo.zenoh_sealed`), the key that opens them
/// (`Session.seal_key`, given only to callers that may see the session).
/// Made from a [`v1::Session`] (both) or an id (a server that does not
/// seal). Its `Debug` form never shows the key.
#[derive(Clone)]
pub struct Watched {
    id: String,
    seal_key: Vec<u8>,
}

impl Watched {
    /// The session `id`, whose payloads `seal_key` opens (empty: the
    /// server does not seal).
    pub fn new(id: impl Into<String>, seal_key: &[u8]) -> Self {
        Self {
            id: id.into(),
            seal_key: seal_key.to_vec(),
        }
    }

    /// The gate of this session's `key`: the key's checks, and the
    /// opening of sealed payloads. `replay` refuses a payload sealed
    /// before the last one taken (a subscription's; a query's replies are
    /// each new).
    fn gate(&self, key: String, replay: bool) -> Result<Gate> {
        let seal = if self.seal_key.is_empty() {
            None
        } else {
            Some(SealKey::from_bytes(&self.seal_key).map_err(|e| {
                ClientError::Zenoh(format!("session {}: {e}", quote(self.id.as_bytes())))
            })?)
        };
        Ok(Gate::new(key, &self.id, seal, replay))
    }
}

impl std::fmt::Debug for Watched {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Watched")
            .field("id", &self.id)
            .field("sealed", &!self.seal_key.is_empty())
            .finish()
    }
}

impl From<&v1::Session> for Watched {
    fn from(session: &v1::Session) -> Self {
        Self::new(session.id.clone(), &session.seal_key)
    }
}

impl From<&str> for Watched {
    fn from(id: &str) -> Self {
        Self::new(id, &[])
    }
}

impl From<&String> for Watched {
    fn from(id: &String) -> Self {
        Self::new(id.clone(), &[])
    }
}

/// A zenoh session connected to a meshless server (or a router in front of
/// it), in client mode: it listens on nothing and scouts nothing.
#[derive(Debug, Clone)]
pub struct ZenohLink {
    session: zenoh::Session,
}

impl ZenohLink {
    /// Connects to the given zenoh endpoints, e.g. the `zenoh_locators` of
    /// `GetServerInfo`, or a router's `tcp/host:7447`.
    ///
    /// # Errors
    /// [`ClientError::Zenoh`] when no endpoint can be reached.
    pub async fn connect(endpoints: &[String]) -> Result<Self> {
        Self::connect_with(endpoints, zenoh::Config::default()).await
    }

    /// [`ZenohLink::connect`] starting from `config`, zenoh's own
    /// configuration (e.g. `zenoh::Config::from_file`): the CA of `tls/`
    /// endpoints, a client certificate, a user and password. The mode,
    /// the endpoints and scouting are set over it.
    ///
    /// # Errors
    /// As [`ZenohLink::connect`].
    pub async fn connect_with(endpoints: &[String], mut config: zenoh::Config) -> Result<Self> {
        if endpoints.is_empty() {
            return Err(ClientError::Zenoh(
                "no zenoh endpoint to connect to; pass the server's or a router's".into(),
            ));
        }
        let endpoints_json = format!(
            "[{}]",
            endpoints
                .iter()
                .map(|e| format!("{e:?}"))
                .collect::<Vec<_>>()
                .join(",")
        );
        for (key, value) in [
            ("mode", "\"client\"".to_owned()),
            ("connect/endpoints", endpoints_json),
            ("scouting/multicast/enabled", "false".to_owned()),
        ] {
            config
                .insert_json5(key, &value)
                .map_err(|e| ClientError::Zenoh(format!("config {key} = {value}: {e}")))?;
        }
        let session = zenoh::open(config)
            .await
            .map_err(|e| ClientError::Zenoh(format!("cannot connect to {endpoints:?}: {e}")))?;
        Ok(Self { session })
    }

    /// Subscribes to a session's frames (pass the [`v1::Session`] the
    /// server answered with, so that sealed frames open). Returns once the
    /// server knows of the subscription (a latest-frame query has made the
    /// round trip), so no frame published afterwards is missed. A sealed
    /// subscription takes nothing sealed before that query's answer, so a
    /// recording of an older frame played to it is dropped
    /// ([`DropReason::Replayed`]).
    ///
    /// # Errors
    /// [`ClientError::Zenoh`] when the subscription cannot be declared or
    /// the seal key is malformed.
    pub async fn frames(&self, session: impl Into<Watched>) -> Result<Frames> {
        let (subscriber, gate) = self
            .subscribe(session.into(), keys::frames, "declare frame subscriber")
            .await?;
        Ok(Frames { subscriber, gate })
    }

    /// Subscribes to a session's status changes, with the same guarantee
    /// as [`ZenohLink::frames`].
    ///
    /// # Errors
    /// As [`ZenohLink::frames`].
    pub async fn statuses(&self, session: impl Into<Watched>) -> Result<Statuses> {
        let (subscriber, gate) = self
            .subscribe(session.into(), keys::status, "declare status subscriber")
            .await?;
        Ok(Statuses { subscriber, gate })
    }

    /// Declares a subscriber on the session's `key`, then queries its
    /// latest frame: once the answer is back the server knows of the
    /// subscriber. The answer is sealed after everything the session put
    /// before it (one counter seals all of a session's keys), so its
    /// counter becomes the subscription's replay floor: a fresh
    /// subscription would otherwise take any recorded payload, its last
    /// counter starting at 0. The gate checks samples as `recv` takes
    /// them, so the floor covers those that came during the query too.
    async fn subscribe(
        &self,
        session: Watched,
        key: fn(&str) -> String,
        what: &str,
    ) -> Result<(Subscriber<FifoChannelHandler<Sample>>, Gate)> {
        let gate = session.gate(key(&session.id), true)?;
        let subscriber = self
            .session
            .declare_subscriber(gate.key.clone())
            .await
            .map_err(zenoh_error(what))?;
        let latest = self
            .latest(session, |frame| FrameView::check(&frame))
            .await?;
        if let Some(((), Some(counter))) = latest {
            gate.raise_floor(counter);
        }
        Ok((subscriber, gate))
    }

    /// Asks the session's `latest` queryable for its most recent frame;
    /// `None` when no server answers for that session with a frame that
    /// passes the subscribers' checks (see [`Frames`]).
    ///
    /// # Errors
    /// [`ClientError::Zenoh`] when the query cannot be sent or the seal
    /// key is malformed.
    pub async fn latest_frame(&self, session: impl Into<Watched>) -> Result<Option<FrameView>> {
        let latest = self.latest(session.into(), FrameView::from_proto).await?;
        Ok(latest.map(|(frame, _)| frame))
    }

    /// [`ZenohLink::latest_frame`] as the protocol's message, checked
    /// ([`FrameView::check`]) but not unpacked: for programs that convert
    /// frames themselves (`meshless demo` hands them to `meshless-wire`).
    ///
    /// # Errors
    /// As [`ZenohLink::latest_frame`].
    pub async fn latest_message(&self, session: impl Into<Watched>) -> Result<Option<v1::Frame>> {
        let latest = self
            .latest(session.into(), |frame| {
                FrameView::check(&frame).map(|()| frame)
            })
            .await?;
        Ok(latest.map(|(frame, _)| frame))
    }

    /// Queries `…/latest` and keeps the reply that passes the
    /// subscribers' checks and `accept` and was sealed last (the last one
    /// to come when unsealed), with its seal counter. Every queryable is
    /// asked and every reply kept (`QueryTarget::All`, no consolidation):
    /// by default zenoh asks only a queryable declared complete when
    /// there is one, and keeps one reply per key, so another peer could
    /// answer in the server's place, and where peers may answer, one
    /// could answer with a recorded older reply, which the counter
    /// outranks. Error replies and rejected ones are logged and skipped:
    /// the server never sends them.
    async fn latest<T>(
        &self,
        session: Watched,
        accept: impl Fn(v1::Frame) -> Result<T>,
    ) -> Result<Option<(T, Option<u64>)>> {
        let gate = session.gate(keys::latest(&session.id), false)?;
        let replies = self
            .session
            .get(&gate.key)
            .target(QueryTarget::All)
            .consolidation(ConsolidationMode::None)
            .await
            .map_err(zenoh_error("query latest frame"))?;
        let mut latest: Option<(T, Option<u64>)> = None;
        while let Ok(reply) = replies.recv_async().await {
            let sample = match reply.result() {
                Ok(sample) => sample,
                Err(e) => {
                    let why = quote(&e.payload().to_bytes());
                    tracing::warn!("latest frame: error reply {why} skipped");
                    continue;
                }
            };
            match gate.admit_frame(sample, &accept) {
                Ok((frame, counter)) => {
                    if latest.as_ref().is_none_or(|(_, newest)| counter >= *newest) {
                        latest = Some((frame, counter));
                    }
                }
                Err((reason, why)) => {
                    tracing::warn!("latest frame: reply skipped ({reason:?}): {why}");
                }
            }
        }
        Ok(latest)
    }

    /// Closes the zenoh session.
    pub async fn close(self) {
        if let Err(e) = self.session.close().await {
            tracing::warn!("closing zenoh: {e}");
        }
    }
}

/// Why a subscriber dropped a sample rather than hand it on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DropReason {
    /// Put on a key expression other than the one subscribed to: a put on
    /// a wildcard such as `meshless/v1/sessions/*/frames` reaches every
    /// session's subscribers, and the server never makes one.
    WrongKey,
    /// The payload is no protobuf message of the expected type.
    Undecodable,
    /// A message that decodes but fails a check: a frame without a header
    /// or whose lengths disagree ([`FrameView::check`]).
    Malformed,
    /// A message naming another session than the one subscribed to.
    WrongSession,
    /// A payload that does not open with the session's seal key: not
    /// sealed, sealed with another key or for another key expression, or
    /// altered on the way.
    NotAuthentic,
    /// A sealed payload that opens but was sealed before the last one
    /// taken, or before the latest frame the subscription learned of when
    /// it started: a recording played again.
    Replayed,
}

/// The samples a subscriber has dropped so far, by reason. Any zenoh peer
/// can put on a session's keys; these counts say whether one does.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Dropped {
    /// Samples put on another key expression ([`DropReason::WrongKey`]).
    pub wrong_key: u64,
    /// Payloads that did not decode ([`DropReason::Undecodable`]).
    pub undecodable: u64,
    /// Messages that failed a check ([`DropReason::Malformed`]).
    pub malformed: u64,
    /// Messages naming another session ([`DropReason::WrongSession`]).
    pub wrong_session: u64,
    /// Payloads that did not open ([`DropReason::NotAuthentic`]).
    pub not_authentic: u64,
    /// Sealed payloads played again ([`DropReason::Replayed`]).
    pub replayed: u64,
    /// The last drop: its reason and what was wrong, with any text the
    /// sender chose (a session id, a key) cut to 64 characters.
    pub last: Option<(DropReason, String)>,
}

impl Dropped {
    /// Samples dropped for any reason.
    pub fn total(&self) -> u64 {
        self.wrong_key
            + self.undecodable
            + self.malformed
            + self.wrong_session
            + self.not_authentic
            + self.replayed
    }

    fn count(&mut self, reason: DropReason, why: String) {
        let counter = match reason {
            DropReason::WrongKey => &mut self.wrong_key,
            DropReason::Undecodable => &mut self.undecodable,
            DropReason::Malformed => &mut self.malformed,
            DropReason::WrongSession => &mut self.wrong_session,
            DropReason::NotAuthentic => &mut self.not_authentic,
            DropReason::Replayed => &mut self.replayed,
        };
        *counter += 1;
        self.last = Some((reason, why));
    }
}

/// Why a sample was refused, and what was wrong with it.
type Rejection = (DropReason, String);

/// At most 64 characters of text a peer chose, quoted, so a hostile
/// sample cannot flood a log line or a [`Dropped`] message.
fn quote(bytes: &[u8]) -> String {
    let text = String::from_utf8_lossy(bytes);
    let mut cut: String = text.chars().take(64).collect();
    if cut.len() < text.len() {
        cut.push('…');
    }
    format!("{cut:?}")
}

/// The session a frame names; `None` without a header.
fn frame_session(frame: &v1::Frame) -> Option<&str> {
    frame.header.as_ref().map(|h| h.session_id.as_str())
}

/// The session a status change names.
fn status_session(status: &v1::SessionStatus) -> Option<&str> {
    Some(status.session_id.as_str())
}

/// What one subscription (or query) accepts: samples on exactly its key
/// that open with the session's seal key (when it has one), sealed after
/// the last one taken (when it checks replays), whose message decodes and
/// names its session. Counts what it drops.
#[derive(Debug)]
struct Gate {
    key: String,
    session_id: String,
    seal: Option<SealKey>,
    /// The counter of the last sealed payload taken; `None` when replays
    /// are not checked.
    newest: Option<Mutex<u64>>,
    dropped: Mutex<Dropped>,
}

impl Gate {
    fn new(key: String, session_id: &str, seal: Option<SealKey>, replay: bool) -> Self {
        Self {
            key,
            session_id: session_id.to_owned(),
            seal,
            newest: replay.then(Mutex::default),
            dropped: Mutex::default(),
        }
    }

    /// The message of a sample that passes and its seal counter (`None`
    /// unsealed), or why it does not. `session_of` reads the session a
    /// message names (`None`: it lacks the part that names it). Decoding
    /// is bounded by the payload: protobuf allocates only for bytes it
    /// holds.
    fn admit<M: Message + Default>(
        &self,
        sample: &Sample,
        session_of: impl Fn(&M) -> Option<&str>,
    ) -> std::result::Result<(M, Option<u64>), Rejection> {
        self.check_counted(
            sample.key_expr().as_str(),
            &sample.payload().to_bytes(),
            session_of,
        )
    }

    /// [`Gate::admit`] for a frame, then `accept` (a check or an unpack):
    /// a frame it refuses is [`DropReason::Malformed`].
    fn admit_frame<T>(
        &self,
        sample: &Sample,
        accept: impl Fn(v1::Frame) -> Result<T>,
    ) -> std::result::Result<(T, Option<u64>), Rejection> {
        let (frame, counter) = self.admit(sample, frame_session)?;
        let taken = accept(frame).map_err(|e| (DropReason::Malformed, e.to_string()))?;
        Ok((taken, counter))
    }

    /// [`Gate::admit`] of a key and payload, without the counter.
    #[cfg(test)]
    fn check<M: Message + Default>(
        &self,
        key: &str,
        payload: &[u8],
        session_of: impl Fn(&M) -> Option<&str>,
    ) -> std::result::Result<M, Rejection> {
        self.check_counted(key, payload, session_of)
            .map(|(message, _)| message)
    }

    /// [`Gate::admit`] of a key and payload.
    fn check_counted<M: Message + Default>(
        &self,
        key: &str,
        payload: &[u8],
        session_of: impl Fn(&M) -> Option<&str>,
    ) -> std::result::Result<(M, Option<u64>), Rejection> {
        if key != self.key {
            return Err((
                DropReason::WrongKey,
                format!("put on {}, not {}", quote(key.as_bytes()), self.key),
            ));
        }
        let mut opened;
        let (payload, counter) = match &self.seal {
            None => (payload, None),
            Some(seal) => {
                opened = payload.to_vec();
                let (counter, plain) = seal
                    .open(key, &mut opened)
                    .map_err(|e| (DropReason::NotAuthentic, e.to_string()))?;
                self.check_fresh(counter)?;
                (plain, Some(counter))
            }
        };
        let message = M::decode(payload).map_err(|e| {
            (
                DropReason::Undecodable,
                format!("{} bytes: {e}", payload.len()),
            )
        })?;
        match session_of(&message) {
            None => Err((DropReason::Malformed, "no header".into())),
            Some(session) if session != self.session_id => Err((
                DropReason::WrongSession,
                format!(
                    "names session {}, not {:?}",
                    quote(session.as_bytes()),
                    self.session_id
                ),
            )),
            Some(_) => Ok((message, counter)),
        }
    }

    /// Takes the counter of an authentic payload, refusing one at or
    /// below the last taken. Only authentic payloads get here, so a
    /// forger cannot move the mark.
    fn check_fresh(&self, counter: u64) -> std::result::Result<(), Rejection> {
        let Some(newest) = &self.newest else {
            return Ok(());
        };
        let mut newest = newest.lock().unwrap_or_else(PoisonError::into_inner);
        if counter <= *newest {
            return Err((
                DropReason::Replayed,
                format!("sealed as number {counter}, after number {newest}"),
            ));
        }
        *newest = counter;
        Ok(())
    }

    /// Refuses, from now on, every payload sealed at or before `counter`:
    /// that of an authentic latest-frame reply, sealed after everything
    /// the session had put before it.
    fn raise_floor(&self, counter: u64) {
        if let Some(newest) = &self.newest {
            let mut newest = newest.lock().unwrap_or_else(PoisonError::into_inner);
            *newest = (*newest).max(counter);
        }
    }

    fn reject(&self, (reason, why): Rejection) {
        tracing::debug!(key = %self.key, "sample dropped ({reason:?}): {why}");
        self.dropped
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .count(reason, why);
    }

    fn dropped(&self) -> Dropped {
        self.dropped
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }
}

/// Frames of one session, in publication order (some may be dropped under
/// congestion; step numbers tell).
///
/// Any zenoh peer can put on a session's key, so each sample is checked
/// before it is handed on: it must be put on exactly the session's frame
/// key, decode as a `Frame`, carry a header naming this session, and pass
/// [`FrameView::check`]. Anything else is dropped and counted
/// ([`Frames::dropped`]); `recv` goes on to the next sample. When the
/// server seals (see [`Watched`]), a sample must also open with the
/// session's key and be sealed after the last one taken (and after the
/// latest frame the subscription learned of as it started), so a frame a
/// peer forged or recorded is dropped too; unsealed, a well-formed frame
/// a peer puts in the session's name is refused only by access control
/// on the zenoh plane.
#[derive(Debug)]
pub struct Frames {
    subscriber: Subscriber<FifoChannelHandler<Sample>>,
    gate: Gate,
}

impl Frames {
    /// The next frame that passes the checks.
    ///
    /// # Errors
    /// [`ClientError::Closed`] when the zenoh session closed.
    pub async fn recv(&self) -> Result<FrameView> {
        self.next(FrameView::from_proto).await
    }

    /// The next frame that passes the checks, as the protocol's message,
    /// not unpacked: for programs that convert frames themselves (`meshless
    /// demo` hands them to `meshless-wire`).
    ///
    /// # Errors
    /// [`ClientError::Closed`] when the zenoh session closed.
    pub async fn recv_message(&self) -> Result<v1::Frame> {
        self.next(|frame| FrameView::check(&frame).map(|()| frame))
            .await
    }

    /// The samples dropped so far, counted as `recv` meets them.
    pub fn dropped(&self) -> Dropped {
        self.gate.dropped()
    }

    /// The next sample the gate admits and `accept` takes; the rest are
    /// dropped and counted.
    async fn next<T>(&self, accept: impl Fn(v1::Frame) -> Result<T>) -> Result<T> {
        loop {
            let sample = self
                .subscriber
                .recv_async()
                .await
                .map_err(|_| ClientError::Closed)?;
            match self.gate.admit_frame(&sample, &accept) {
                Ok((frame, _)) => return Ok(frame),
                Err(rejection) => self.gate.reject(rejection),
            }
        }
    }
}

/// Status changes of one session, checked as [`Frames`] are: put on
/// exactly the session's status key, decoding as a `SessionStatus` that
/// names this session; anything else is dropped and counted.
#[derive(Debug)]
pub struct Statuses {
    subscriber: Subscriber<FifoChannelHandler<Sample>>,
    gate: Gate,
}

impl Statuses {
    /// The next status change that passes the checks.
    ///
    /// # Errors
    /// [`ClientError::Closed`] when the zenoh session closed.
    pub async fn recv(&self) -> Result<v1::SessionStatus> {
        loop {
            let sample = self
                .subscriber
                .recv_async()
                .await
                .map_err(|_| ClientError::Closed)?;
            match self.gate.admit(&sample, status_session) {
                Ok((status, _)) => return Ok(status),
                Err(rejection) => self.gate.reject(rejection),
            }
        }
    }

    /// The samples dropped so far, counted as `recv` meets them.
    pub fn dropped(&self) -> Dropped {
        self.gate.dropped()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(session_id: &str, step: u64) -> v1::Frame {
        v1::Frame {
            header: Some(v1::FrameHeader {
                session_id: session_id.into(),
                step,
                particle_count: 1,
                fields: vec![v1::FieldKind::Position as i32],
                ..Default::default()
            }),
            fields: vec![v1::FieldData {
                kind: v1::FieldKind::Position as i32,
                components: 3,
                scalar: v1::ScalarType::F32 as i32,
                data: vec![0; 12].into(),
            }],
            ..Default::default()
        }
    }

    fn frame_gate() -> Gate {
        Gate::new(keys::frames("abc"), "abc", None, true)
    }

    /// The reason a frame sample on `key` is refused, `None` if it passes.
    fn refusal(key: &str, payload: &[u8]) -> Option<DropReason> {
        frame_gate()
            .check::<v1::Frame>(key, payload, frame_session)
            .and_then(|f| FrameView::check(&f).map_err(|e| (DropReason::Malformed, e.to_string())))
            .err()
            .map(|(reason, _)| reason)
    }

    #[test]
    fn only_frames_on_the_exact_key_naming_the_session_pass() {
        let key = keys::frames("abc");
        let good = frame("abc", 3).encode_to_vec();
        assert_eq!(refusal(&key, &good), None);
        assert_eq!(
            refusal("meshless/v1/sessions/*/frames", &good),
            Some(DropReason::WrongKey),
            "a wildcard put reaches every session's subscribers"
        );
        assert_eq!(
            refusal(&key, &frame("FAKE", 999_999).encode_to_vec()),
            Some(DropReason::WrongSession)
        );
        assert_eq!(
            refusal(&key, &frame("", 1).encode_to_vec()),
            Some(DropReason::WrongSession)
        );
        assert_eq!(
            refusal(&key, b"\xff\xff\xff"),
            Some(DropReason::Undecodable)
        );
        assert_eq!(
            refusal(&key, b"\x08\x01"),
            Some(DropReason::Undecodable),
            "field 1 is the header, not a varint"
        );
        // An unknown field decodes to a frame without a header.
        assert_eq!(refusal(&key, b"\x78\x01"), Some(DropReason::Malformed));
        assert_eq!(refusal(&key, b""), Some(DropReason::Malformed));
        let mut short = frame("abc", 3);
        let len = short.fields[0].data.len();
        short.fields[0].data.truncate(len - 1);
        assert_eq!(
            refusal(&key, &short.encode_to_vec()),
            Some(DropReason::Malformed)
        );
    }

    #[test]
    fn statuses_must_name_the_session() {
        let gate = Gate::new(keys::status("abc"), "abc", None, true);
        let status = |id: &str| {
            v1::SessionStatus {
                session_id: id.into(),
                step: 5,
                ..Default::default()
            }
            .encode_to_vec()
        };
        let passed = gate.check::<v1::SessionStatus>(&gate.key, &status("abc"), status_session);
        assert_eq!(passed.map(|s| s.step), Ok(5));
        let refused = |key: &str, payload: &[u8]| {
            gate.check::<v1::SessionStatus>(key, payload, status_session)
                .map(drop)
                .map_err(|(reason, _)| reason)
        };
        assert_eq!(
            refused(&gate.key, &status("FAKE")),
            Err(DropReason::WrongSession)
        );
        assert_eq!(
            refused(&keys::status("other"), &status("abc")),
            Err(DropReason::WrongKey)
        );
        assert_eq!(refused(&gate.key, b"\xff"), Err(DropReason::Undecodable));
    }

    #[test]
    fn drops_are_counted_by_reason_with_the_last_one_cut_short() {
        let gate = frame_gate();
        let long = "x".repeat(10_000);
        for payload in [
            frame(&long, 1).encode_to_vec(),
            frame("FAKE", 2).encode_to_vec(),
            b"\xff".to_vec(),
        ] {
            let rejection = gate
                .check::<v1::Frame>(&gate.key, &payload, frame_session)
                .expect_err("refused");
            gate.reject(rejection);
        }
        let dropped = gate.dropped();
        assert_eq!((dropped.wrong_session, dropped.undecodable), (2, 1));
        assert_eq!(dropped.total(), 3);
        assert_eq!(dropped.last.map(|(r, _)| r), Some(DropReason::Undecodable));

        let (_, why) = gate
            .check::<v1::Frame>(&gate.key, &frame(&long, 1).encode_to_vec(), frame_session)
            .expect_err("refused");
        assert!(why.len() < 200, "a sender's text is cut: {why}");
        assert!(why.contains(&"x".repeat(64)) && why.contains('…'), "{why}");
    }

    #[test]
    fn sealed_frames_open_once_in_order_and_nothing_else_passes() {
        let sealer = meshless_proto::seal::Sealer::generate().expect("random");
        let watched = Watched::new("abc", sealer.key().bytes());
        let gate = watched.gate(keys::frames("abc"), true).expect("32 bytes");
        let key = keys::frames("abc");
        let check = |payload: &[u8]| {
            gate.check::<v1::Frame>(&key, payload, frame_session)
                .map(|f| f.header.map(|h| h.step))
                .map_err(|(reason, _)| reason)
        };
        let first = sealer.seal(&key, &frame("abc", 1));
        let second = sealer.seal(&key, &frame("abc", 2));
        assert_eq!(check(&first), Ok(Some(1)));
        assert_eq!(check(&second), Ok(Some(2)));
        assert_eq!(check(&first), Err(DropReason::Replayed), "played again");
        assert_eq!(
            check(&frame("abc", 3).encode_to_vec()),
            Err(DropReason::NotAuthentic),
            "a plain frame where sealed ones are expected"
        );
        let stranger = meshless_proto::seal::Sealer::generate().expect("random");
        assert_eq!(
            check(&stranger.seal(&key, &frame("abc", 4))),
            Err(DropReason::NotAuthentic)
        );
        assert_eq!(
            check(&sealer.seal(&keys::status("abc"), &frame("abc", 5))),
            Err(DropReason::NotAuthentic),
            "sealed for the status key"
        );
        let mut altered = sealer.seal(&key, &frame("abc", 6));
        altered[20] ^= 4;
        assert_eq!(check(&altered), Err(DropReason::NotAuthentic));
        assert_eq!(check(&sealer.seal(&key, &frame("abc", 7))), Ok(Some(7)));

        // A fresh subscription whose latest-frame answer was sealed as
        // number 9 refuses a recording sealed before it, however new to it.
        let fresh = watched.gate(key.clone(), true).expect("32 bytes");
        let recorded = sealer.seal(&key, &frame("abc", 8));
        let answer = sealer.seal(&keys::latest("abc"), &frame("abc", 8));
        let (floor, _) = sealer
            .key()
            .open(&keys::latest("abc"), &mut answer.clone())
            .expect("opens");
        fresh.raise_floor(floor);
        let fresh_check = |payload: &[u8]| {
            fresh
                .check::<v1::Frame>(&key, payload, frame_session)
                .map(|f| f.header.map(|h| h.step))
                .map_err(|(reason, _)| reason)
        };
        assert_eq!(fresh_check(&recorded), Err(DropReason::Replayed));
        let nine = sealer.seal(&key, &frame("abc", 9));
        assert_eq!(fresh_check(&nine), Ok(Some(9)));
        fresh.raise_floor(1);
        assert_eq!(
            fresh_check(&nine),
            Err(DropReason::Replayed),
            "a lower floor never lowers the mark"
        );

        let err = Watched::new("abc", &[1; 5])
            .gate(key.clone(), true)
            .expect_err("short key");
        assert!(err.to_string().contains("32 bytes"), "{err}");
        assert!(!format!("{watched:?}").contains(&format!("{:?}", sealer.key().bytes())));
    }
}
