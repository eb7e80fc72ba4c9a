//! The zenoh side: frame and status subscriptions, latest-frame queries.

use crate::{ClientError, FrameView};
use meshless_proto::{keys, v1};
use prost::Message;
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::Subscriber;
use zenoh::sample::Sample;

type Result<T> = std::result::Result<T, ClientError>;

fn zenoh_error(context: &str) -> impl Fn(zenoh::Error) -> ClientError + '_ {
    move |e| ClientError::Zenoh(format!("{context}: {e}"))
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
        if endpoints.is_empty() {
            return Err(ClientError::Zenoh(
                "no zenoh endpoint to connect to; pass the server's or a router's".into(),
            ));
        }
        let mut config = zenoh::Config::default();
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

    /// Subscribes to a session's frames. Returns once the server knows of
    /// the subscription (a latest-frame query has made the round trip), so
    /// no frame published afterwards is missed.
    ///
    /// # Errors
    /// [`ClientError::Zenoh`] when the subscription cannot be declared.
    pub async fn frames(&self, session_id: &str) -> Result<Frames> {
        let subscriber = self
            .session
            .declare_subscriber(keys::frames(session_id))
            .await
            .map_err(zenoh_error("declare frame subscriber"))?;
        self.latest_frame(session_id).await?;
        Ok(Frames { subscriber })
    }

    /// Subscribes to a session's status changes, with the same guarantee
    /// as [`ZenohLink::frames`].
    ///
    /// # Errors
    /// [`ClientError::Zenoh`] when the subscription cannot be declared.
    pub async fn statuses(&self, session_id: &str) -> Result<Statuses> {
        let subscriber = self
            .session
            .declare_subscriber(keys::status(session_id))
            .await
            .map_err(zenoh_error("declare status subscriber"))?;
        self.latest_frame(session_id).await?;
        Ok(Statuses { subscriber })
    }

    /// Asks the session's `latest` queryable for its most recent frame;
    /// `None` when no server answers for that session.
    ///
    /// # Errors
    /// [`ClientError::Zenoh`] or [`ClientError::Decode`].
    pub async fn latest_frame(&self, session_id: &str) -> Result<Option<FrameView>> {
        self.latest_message(session_id)
            .await?
            .map(FrameView::from_proto)
            .transpose()
    }

    /// [`ZenohLink::latest_frame`] as the protocol's message, decoded but
    /// not checked: for programs that convert frames themselves (`meshless
    /// demo` hands them to `meshless-wire`).
    ///
    /// # Errors
    /// [`ClientError::Zenoh`], or [`ClientError::Decode`] when the bytes
    /// are no `Frame` message.
    pub async fn latest_message(&self, session_id: &str) -> Result<Option<v1::Frame>> {
        let replies = self
            .session
            .get(keys::latest(session_id))
            .await
            .map_err(zenoh_error("query latest frame"))?;
        let mut latest = None;
        while let Ok(reply) = replies.recv_async().await {
            match reply.result() {
                Ok(sample) => latest = Some(decode_frame(&sample.payload().to_bytes())?),
                Err(e) => {
                    return Err(ClientError::Zenoh(format!(
                        "latest frame: {}",
                        String::from_utf8_lossy(&e.payload().to_bytes())
                    )));
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

/// Frames of one session, in publication order (some may be dropped under
/// congestion; step numbers tell).
#[derive(Debug)]
pub struct Frames {
    subscriber: Subscriber<FifoChannelHandler<Sample>>,
}

impl Frames {
    /// The next frame.
    ///
    /// # Errors
    /// [`ClientError::Closed`] when the zenoh session closed;
    /// [`ClientError::Decode`] for a malformed frame.
    pub async fn recv(&self) -> Result<FrameView> {
        FrameView::from_proto(self.recv_message().await?)
    }

    /// The next frame as the protocol's message, decoded but not checked:
    /// for programs that convert frames themselves (`meshless demo` hands
    /// them to `meshless-wire`).
    ///
    /// # Errors
    /// [`ClientError::Closed`] when the zenoh session closed;
    /// [`ClientError::Decode`] when the bytes are no `Frame` message.
    pub async fn recv_message(&self) -> Result<v1::Frame> {
        let sample = self
            .subscriber
            .recv_async()
            .await
            .map_err(|_| ClientError::Closed)?;
        decode_frame(&sample.payload().to_bytes())
    }
}

/// A `Frame` message of its encoded bytes.
fn decode_frame(bytes: &[u8]) -> Result<v1::Frame> {
    v1::Frame::decode(bytes).map_err(|e| ClientError::Decode(e.to_string()))
}

/// Status changes of one session.
#[derive(Debug)]
pub struct Statuses {
    subscriber: Subscriber<FifoChannelHandler<Sample>>,
}

impl Statuses {
    /// The next status change.
    ///
    /// # Errors
    /// [`ClientError::Closed`] or [`ClientError::Decode`].
    pub async fn recv(&self) -> Result<v1::SessionStatus> {
        let sample = self
            .subscriber
            .recv_async()
            .await
            .map_err(|_| ClientError::Closed)?;
        v1::SessionStatus::decode(&*sample.payload().to_bytes())
            .map_err(|e| ClientError::Decode(e.to_string()))
    }
}
