//! Frames delivered over zenoh: a publisher set up as the server's frame
//! publisher (a peer listening on TCP, congestion control *drop*, data
//! priority) puts frames of `n` particles as fast as it can; a subscriber
//! set up as every client's (`meshless_client::ZenohLink`, client mode
//! over loopback TCP) receives, checks and unpacks each one into arrays
//! (`FrameView`). The figures are what reaches the subscriber, so they
//! include the decoding every client pays.
//!
//! The frames carry positions and velocities, 24 bytes per particle, as
//! a fluid scene that asks for velocities publishes; the simulation
//! itself is left out, since no machine steps a million particles 60
//! times a second.
//!
//! [`Payload`] says what each put costs the publisher: one encoding
//! shared by every put (the transport alone), a fresh encoding per put,
//! or a fresh encoding sealed per put and opened by the subscriber (what
//! a server with tokens does: `meshless_proto::seal`). The last two,
//! side by side, give sealing's cost.

use anyhow::{Context, Result};
use meshless_client::{Watched, ZenohLink, v1};
use meshless_proto::keys;
use meshless_proto::seal::Sealer;
use prost::Message;
use std::future::IntoFuture;
use std::time::{Duration, Instant};
use zenoh::qos::{CongestionControl, Priority};

/// The session id the frames name.
const SESSION: &str = "load-bench";

/// How long the subscriber waits for stragglers once the publisher stops.
const DRAIN: Duration = Duration::from_secs(2);

/// What the publisher does for each put.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Payload {
    /// One encoding, shared by every put: what the transport alone does.
    Shared,
    /// The frame encoded afresh for every put, as a server that does not
    /// seal does.
    Encoded,
    /// Encoded and sealed afresh for every put, and opened by the
    /// subscriber, as a server with tokens does.
    Sealed,
}

/// What one run delivered.
#[derive(Debug, Clone, Copy)]
pub struct Delivery {
    /// Particles per frame.
    pub particles: usize,
    /// Encoded size of one frame.
    pub frame_bytes: usize,
    /// Frames the publisher put.
    pub published: u64,
    /// Frames the subscriber received and unpacked.
    pub delivered: u64,
    /// From the first frame received to the last.
    pub elapsed: Duration,
}

impl Delivery {
    /// Frames delivered per second.
    pub fn frames_per_s(&self) -> f64 {
        self.delivered.saturating_sub(1) as f64 / self.elapsed.as_secs_f64().max(f64::MIN_POSITIVE)
    }

    /// Payload delivered per second, in MB (10^6 bytes).
    pub fn mb_per_s(&self) -> f64 {
        self.frames_per_s() * self.frame_bytes as f64 / 1e6
    }
}

/// A frame of `particles` particles with positions and velocities.
fn frame(particles: usize) -> v1::Frame {
    let field = |kind: v1::FieldKind| v1::FieldData {
        kind: kind as i32,
        components: 3,
        scalar: v1::ScalarType::F32 as i32,
        data: (0..particles * 3)
            .flat_map(|i| (i as f32 * 1e-3).to_le_bytes())
            .collect(),
    };
    v1::Frame {
        header: Some(v1::FrameHeader {
            session_id: SESSION.into(),
            step: 1,
            time: 0.01,
            particle_count: particles as u64,
            fields: vec![
                v1::FieldKind::Position as i32,
                v1::FieldKind::Velocity as i32,
            ],
            ..Default::default()
        }),
        fields: vec![
            field(v1::FieldKind::Position),
            field(v1::FieldKind::Velocity),
        ],
        ..Default::default()
    }
}

/// A free TCP port on loopback for the publisher to listen on.
fn free_port() -> Result<u16> {
    let listener = std::net::TcpListener::bind("127.0.0.1:0")?;
    Ok(listener.local_addr()?.port())
}

/// Publishes frames of `particles` particles for `duration`, each made as
/// `payload` says, and counts what the subscriber receives.
///
/// # Errors
/// When zenoh cannot open, listen or connect.
pub async fn deliver(particles: usize, duration: Duration, payload: Payload) -> Result<Delivery> {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port()?);
    let mut config = zenoh::Config::default();
    for (key, value) in [
        ("mode", "\"peer\"".to_owned()),
        ("listen/endpoints", format!("[{endpoint:?}]")),
        ("scouting/multicast/enabled", "false".to_owned()),
    ] {
        config
            .insert_json5(key, &value)
            .map_err(|e| anyhow::anyhow!("zenoh config {key}: {e}"))?;
    }
    let publishing = zenoh::open(config)
        .await
        .map_err(|e| anyhow::anyhow!("publisher: {e}"))?;
    let publisher = publishing
        .declare_publisher(keys::frames(SESSION))
        .congestion_control(CongestionControl::Drop)
        .priority(Priority::DataLow)
        .await
        .map_err(|e| anyhow::anyhow!("declare publisher: {e}"))?;
    let sealer = Sealer::generate().map_err(|e| anyhow::anyhow!("seal key: {e}"))?;
    let watched = match payload {
        Payload::Sealed => Watched::new(SESSION, sealer.key().bytes()),
        Payload::Shared | Payload::Encoded => Watched::new(SESSION, &[]),
    };
    let link = ZenohLink::connect(std::slice::from_ref(&endpoint)).await?;
    let frames = link.frames(watched).await?;

    let message = frame(particles);
    let key = keys::frames(SESSION);
    let frame_bytes = message.encoded_len();
    // Shared: a put hands zenoh the bytes without a copy.
    let shared = zenoh::bytes::ZBytes::from(message.encode_to_vec());
    let receiving = tokio::spawn(async move {
        let (mut delivered, mut first, mut last) = (0u64, None, None);
        while let Ok(Ok(frame)) = tokio::time::timeout(
            if delivered == 0 {
                duration + DRAIN
            } else {
                DRAIN
            },
            frames.recv(),
        )
        .await
        {
            debug_assert_eq!(frame.particle_count, particles);
            let now = Instant::now();
            first.get_or_insert(now);
            last = Some(now);
            delivered += 1;
        }
        let elapsed = match (first, last) {
            (Some(first), Some(last)) => last - first,
            _ => Duration::ZERO,
        };
        (delivered, elapsed)
    });

    let start = Instant::now();
    let mut published = 0u64;
    while start.elapsed() < duration {
        let bytes = match payload {
            Payload::Shared => shared.clone(),
            Payload::Encoded => message.encode_to_vec().into(),
            Payload::Sealed => sealer.seal(&key, &message).into(),
        };
        publisher
            .put(bytes)
            .into_future()
            .await
            .map_err(|e| anyhow::anyhow!("put: {e}"))?;
        published += 1;
        // Puts that zenoh drops return at once; yield so the subscriber's
        // side of this process gets its share of the two cores.
        tokio::task::yield_now().await;
    }
    let (delivered, elapsed) = receiving.await.context("subscriber task")?;
    link.close().await;
    publishing
        .close()
        .await
        .map_err(|e| anyhow::anyhow!("close: {e}"))?;
    Ok(Delivery {
        particles,
        frame_bytes,
        published,
        delivered,
        elapsed,
    })
}
