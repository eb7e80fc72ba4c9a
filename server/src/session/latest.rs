//! A session's most recent frame, numbered, for every reader that wants
//! the newest one rather than each one: the zenoh latest-frame queryable,
//! `GetLatestFrame`, and `NextFrame`'s waiting polls (the browser viewer).
//!
//! The compute thread replaces it; readers take the `Arc`. A poll waits on
//! the number (a watch channel), so a thousand waiting viewers cost one
//! wake-up each per frame and hold no frame of their own until they wake:
//! a slow viewer skips frames, it never queues them.

use super::EncodedFrame;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

/// The latest frame and its number: frames are numbered from 1 in the
/// order the session made them, across resets and restores (a frame's
/// step may go back; its number never does).
#[derive(Debug, Clone)]
pub struct Numbered {
    /// 1 for the frame the session was built with, then one more per frame.
    pub number: u64,
    /// The frame, encoded once.
    pub frame: Arc<EncodedFrame>,
}

/// The writer's and readers' shared handle.
#[derive(Debug, Clone)]
pub struct LatestFrame(Arc<watch::Sender<Numbered>>);

impl LatestFrame {
    /// Starts with the frame a session was built with, number 1.
    pub fn new(frame: EncodedFrame) -> Self {
        Self(Arc::new(watch::Sender::new(Numbered {
            number: 1,
            frame: Arc::new(frame),
        })))
    }

    /// The latest frame and its number.
    pub fn get(&self) -> Numbered {
        self.0.borrow().clone()
    }

    /// Makes `frame` the latest, with the next number, and wakes the waiters.
    pub fn replace(&self, frame: Arc<EncodedFrame>) {
        self.0.send_modify(|latest| {
            latest.number += 1;
            latest.frame = frame;
        });
    }

    /// The latest frame once its number passes `after`, waiting at most
    /// `wait`; `None` when no newer frame came in time.
    pub async fn newer_than(&self, after: u64, wait: Duration) -> Option<Numbered> {
        let mut changes = self.0.subscribe();
        let newer = changes.wait_for(|latest| latest.number > after);
        match tokio::time::timeout(wait, newer).await {
            Ok(Ok(latest)) => Some(latest.clone()),
            // The sender lives as long as this handle: never closed here.
            Ok(Err(_)) | Err(_) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use meshless_engine::{BuildOptions, Scene};

    fn frame() -> EncodedFrame {
        let scene = Scene::from_toml_str(include_str!("../../../tests/fixtures/small_tank.toml"))
            .expect("fixture");
        EncodedFrame::encode(
            "s",
            &scene
                .build(&BuildOptions::default())
                .expect("world")
                .frame(),
        )
    }

    #[tokio::test]
    async fn a_poll_gets_the_next_frame_or_nothing_when_none_comes() {
        let latest = LatestFrame::new(frame());
        let now = latest.get();
        assert_eq!(now.number, 1);
        // Nothing newer than 1: the wait ends empty.
        let none = latest.newer_than(1, Duration::from_millis(20)).await;
        assert!(none.is_none());
        // Anything newer than 0 is there at once.
        let first = latest.newer_than(0, Duration::from_secs(5)).await;
        assert_eq!(first.map(|f| f.number), Some(1));

        let waiting = {
            let latest = latest.clone();
            tokio::spawn(async move { latest.newer_than(1, Duration::from_secs(5)).await })
        };
        let next = Arc::new(frame());
        latest.replace(next.clone());
        latest.replace(next.clone());
        let got = tokio::time::timeout(Duration::from_secs(5), waiting)
            .await
            .expect("the poll ends")
            .expect("joins")
            .expect("a newer frame");
        // A waiter that woke late gets the newest, having skipped one.
        assert!(got.number >= 2);
        assert_eq!(latest.get().number, 3);
        assert!(Arc::ptr_eq(&latest.get().frame, &next));
    }
}
