//! What a slow subscriber costs the simulation: steps per second of one
//! session with nobody watching, then with a subscriber that takes
//! `pause` over every frame, each from the scene's start and in
//! alternating order, so that neither the scene's own changes nor a drift
//! in the machine's speed fall on one side. The server publishes frames with
//! congestion control *drop*, so a slow reader should cost it nothing:
//! the goal is a ratio of at least 0.98.

use anyhow::Result;
use meshless_client::{Client, ZenohLink};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Steps per second without and with the slow subscriber.
#[derive(Debug, Clone, Copy)]
pub struct SlowSubscriber {
    /// Steps per second, nobody subscribed.
    pub alone: f64,
    /// Steps per second while the slow subscriber reads.
    pub watched: f64,
    /// Frames the slow subscriber got through.
    pub frames_read: u64,
}

impl SlowSubscriber {
    /// `watched / alone`.
    pub fn ratio(&self) -> f64 {
        self.watched / self.alone
    }
}

/// Steps `steps` at a time, `rounds` times each way, on a session of the
/// scene `toml` (which should publish a frame every step).
///
/// # Errors
/// Any failed call.
pub async fn measure(
    client: &Client,
    zenoh: &[String],
    toml: &str,
    steps: u64,
    rounds: u32,
    pause: Duration,
) -> Result<SlowSubscriber> {
    let session = client.create_session_toml(toml).await?;
    let id = session.id.clone();
    // One warm-up batch: first-touch allocations, the neighbour grid.
    client.step(&id, steps).await?;
    let link = ZenohLink::connect(zenoh).await?;
    let (mut alone, mut watched, mut frames_read) = (Duration::ZERO, Duration::ZERO, 0u64);
    for round in 0..rounds {
        // Each arm simulates the same steps from the scene's start (a
        // reset), in the order alone-watched, then watched-alone, so that
        // a drift in the machine's speed falls on both.
        let order = if round % 2 == 0 {
            [false, true]
        } else {
            [true, false]
        };
        for with_reader in order {
            client.reset(&id).await?;
            let read = Arc::new(AtomicU64::new(0));
            let reader = if with_reader {
                let frames = link.frames(&id).await?;
                let read = Arc::clone(&read);
                Some(tokio::spawn(async move {
                    while frames.recv().await.is_ok() {
                        read.fetch_add(1, Ordering::Relaxed);
                        // A reader that cannot keep up: zenoh's queue
                        // fills, then the socket, then the server's send
                        // queue, which drops frames rather than wait.
                        tokio::time::sleep(pause).await;
                    }
                }))
            } else {
                None
            };
            let start = Instant::now();
            client.step(&id, steps).await?;
            let elapsed = start.elapsed();
            match reader {
                Some(reader) => {
                    watched += elapsed;
                    reader.abort();
                    frames_read += read.load(Ordering::Relaxed);
                }
                None => alone += elapsed,
            }
        }
    }
    link.close().await;
    client.delete_session(&id).await?;
    let per_s = |time: Duration| (steps * u64::from(rounds)) as f64 / time.as_secs_f64();
    Ok(SlowSubscriber {
        alone: per_s(alone),
        watched: per_s(watched),
        frames_read,
    })
}
