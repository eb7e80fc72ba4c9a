//! Zenoh side of a session: tokio tasks that put frames (drop on
//! congestion), put status changes (reliable), and answer queries for the
//! latest frame. The compute thread hands them frames already encoded
//! (`encoded.rs`): here they are only sealed per key, or copied.

use super::LatestFrame;
use super::frame_queue::FrameReceiver;
use crate::metrics::Metrics;
use meshless_proto::seal::Sealer;
use meshless_proto::{keys, v1};
use prost::Message;
use std::sync::Arc;
use tokio::sync::broadcast;
use tokio_util::sync::CancellationToken;
use zenoh::qos::{CongestionControl, Priority};

/// Where a session puts its payloads: the server's zenoh session, and the
/// session's sealer when the server seals (`meshless_proto::seal`).
#[derive(Debug, Clone)]
pub struct Outlet {
    pub zenoh: zenoh::Session,
    pub sealer: Option<Arc<Sealer>>,
    /// Where the bytes and frames put are counted.
    pub metrics: Arc<Metrics>,
}

impl Outlet {
    /// `message` as it is put on `key`: encoded, and sealed for `key` when
    /// the session seals.
    fn payload(&self, key: &str, message: &impl Message) -> Vec<u8> {
        let bytes = match &self.sealer {
            Some(sealer) => sealer.seal(key, message),
            None => message.encode_to_vec(),
        };
        self.metrics.sent(bytes.len());
        bytes
    }

    /// An encoded message as it is put on `key`: sealed for `key` when
    /// the session seals, else the same bytes.
    fn payload_encoded(&self, key: &str, encoded: &[u8]) -> Vec<u8> {
        let bytes = match &self.sealer {
            Some(sealer) => sealer.seal_encoded(key, encoded),
            None => encoded.to_vec(),
        };
        self.metrics.sent(bytes.len());
        bytes
    }
}

/// Puts every frame from `frames` until the worker drops its sender.
pub fn spawn_frames(outlet: Outlet, id: String, mut frames: FrameReceiver) {
    tokio::spawn(async move {
        let key = keys::frames(&id);
        let publisher = match outlet
            .zenoh
            .declare_publisher(key.clone())
            .congestion_control(CongestionControl::Drop)
            .priority(Priority::DataLow)
            .await
        {
            Ok(p) => p,
            Err(e) => {
                tracing::error!(session = %id, "cannot declare publisher {key}: {e}");
                return;
            }
        };
        while let Some(frame) = frames.recv().await {
            let bytes = outlet.payload_encoded(&key, frame.bytes());
            match publisher.put(bytes).await {
                Ok(()) => outlet.metrics.frame_published(),
                Err(e) => {
                    tracing::warn!(session = %id, step = frame.step(), "frame not published: {e}");
                }
            }
        }
    });
}

/// Puts every status change until the session is closed.
pub fn spawn_status(
    outlet: Outlet,
    id: String,
    mut events: broadcast::Receiver<v1::SessionStatus>,
) {
    tokio::spawn(async move {
        let key = keys::status(&id);
        let publisher = match outlet
            .zenoh
            .declare_publisher(key.clone())
            .congestion_control(CongestionControl::Block)
            .priority(Priority::InteractiveLow)
            .await
        {
            Ok(p) => p,
            Err(e) => {
                tracing::error!(session = %id, "cannot declare publisher {key}: {e}");
                return;
            }
        };
        loop {
            match events.recv().await {
                Ok(status) => {
                    let closed = status.state == v1::SessionState::Closed as i32;
                    if let Err(e) = publisher.put(outlet.payload(&key, &status)).await {
                        tracing::warn!(session = %id, "status not published: {e}");
                    }
                    if closed {
                        break;
                    }
                }
                Err(broadcast::error::RecvError::Lagged(n)) => {
                    tracing::warn!(session = %id, "{n} status changes skipped on zenoh");
                }
                Err(broadcast::error::RecvError::Closed) => break,
            }
        }
    });
}

/// Answers `…/latest` queries with the latest frame until cancelled.
pub fn spawn_latest(outlet: Outlet, id: String, latest: LatestFrame, cancel: CancellationToken) {
    tokio::spawn(async move {
        let key = keys::latest(&id);
        let queryable = match outlet.zenoh.declare_queryable(key.clone()).await {
            Ok(q) => q,
            Err(e) => {
                tracing::error!(session = %id, "cannot declare queryable {key}: {e}");
                return;
            }
        };
        loop {
            let query = tokio::select! {
                () = cancel.cancelled() => break,
                query = queryable.recv_async() => match query {
                    Ok(q) => q,
                    Err(_) => break,
                },
            };
            let frame = latest.get().frame;
            let bytes = outlet.payload_encoded(&key, frame.bytes());
            if let Err(e) = query.reply(key.clone(), bytes).await {
                tracing::warn!(session = %id, "latest-frame reply failed: {e}");
            }
        }
    });
}
