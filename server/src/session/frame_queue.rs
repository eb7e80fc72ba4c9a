//! The queue between a session's compute thread and its frame publisher,
//! bounded in frames and in bytes.
//!
//! A count alone fits no scene: four frames of a million particles are
//! 100 MB, while four frames of a small tank are gone in the time the
//! publisher task waits for a busy core, and a run of ten quick steps
//! dropped frames on a loaded machine. The byte budget lets small frames
//! queue deep and keeps large ones few; a frame over the whole budget
//! still goes when the queue is empty, so no scene is too large to stream.

use super::encoded::EncodedFrame;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use tokio::sync::mpsc;

/// Most frames queued, however small.
const MAX_FRAMES: usize = 64;
/// Most bytes of frame data queued per session (a frame over it still
/// goes alone).
const MAX_BYTES: usize = 8 << 20;

/// A new queue: the worker's end and the publisher's end.
pub fn frame_queue() -> (FrameSender, FrameReceiver) {
    let (tx, rx) = mpsc::channel(MAX_FRAMES);
    let queued = Arc::new(AtomicUsize::new(0));
    (
        FrameSender {
            tx,
            queued: queued.clone(),
        },
        FrameReceiver { rx, queued },
    )
}

/// Bytes a queued frame holds.
fn frame_bytes(frame: &EncodedFrame) -> usize {
    frame.bytes().len()
}

/// The compute thread's end.
#[derive(Debug)]
pub struct FrameSender {
    tx: mpsc::Sender<Arc<EncodedFrame>>,
    queued: Arc<AtomicUsize>,
}

/// Why a frame was not queued.
#[derive(Debug, PartialEq, Eq)]
pub enum Dropped {
    /// The publisher is behind by the queue's budget.
    Full,
    /// The publisher has stopped.
    Closed,
}

impl FrameSender {
    /// Queues `frame` unless the publisher is a budget behind; never waits.
    pub fn try_send(&self, frame: Arc<EncodedFrame>) -> Result<(), Dropped> {
        let bytes = frame_bytes(&frame);
        let queued = self.queued.load(Ordering::Acquire);
        if queued > 0 && queued + bytes > MAX_BYTES {
            return Err(Dropped::Full);
        }
        self.queued.fetch_add(bytes, Ordering::AcqRel);
        self.tx.try_send(frame).map_err(|e| {
            self.queued.fetch_sub(bytes, Ordering::AcqRel);
            match e {
                mpsc::error::TrySendError::Full(_) => Dropped::Full,
                mpsc::error::TrySendError::Closed(_) => Dropped::Closed,
            }
        })
    }

    /// Queues `frame`, waiting for room in the count (not the bytes): for
    /// the few frames where each one matters. Call from a thread outside
    /// the runtime.
    pub fn blocking_send(&self, frame: Arc<EncodedFrame>) -> Result<(), Dropped> {
        let bytes = frame_bytes(&frame);
        self.queued.fetch_add(bytes, Ordering::AcqRel);
        self.tx.blocking_send(frame).map_err(|_| {
            self.queued.fetch_sub(bytes, Ordering::AcqRel);
            Dropped::Closed
        })
    }
}

/// The publisher's end.
#[derive(Debug)]
pub struct FrameReceiver {
    rx: mpsc::Receiver<Arc<EncodedFrame>>,
    queued: Arc<AtomicUsize>,
}

impl FrameReceiver {
    /// The next frame, or `None` once the worker has dropped its end.
    pub async fn recv(&mut self) -> Option<Arc<EncodedFrame>> {
        let frame = self.rx.recv().await?;
        self.queued.fetch_sub(frame_bytes(&frame), Ordering::AcqRel);
        Some(frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use meshless_engine::{FieldData, FieldKind, Frame};

    fn frame(particles: usize) -> Arc<EncodedFrame> {
        Arc::new(EncodedFrame::encode(
            "s",
            &Frame {
                step: 0,
                time: 0.0,
                substeps: 1,
                substep_dt: 0.0,
                solver_iterations: 0,
                density_error: 0.0,
                capped: false,
                unconverged: 0,
                added: 0,
                particle_count: particles,
                fields: vec![FieldData {
                    kind: FieldKind::Position,
                    components: 3,
                    values: vec![0.0; 3 * particles],
                }],
                bodies: Vec::new(),
                surface: None,
                solids: Vec::new(),
                solid_surfaces: Vec::new(),
                crack_surfaces: Vec::new(),
                ids: None,
            },
        ))
    }

    #[test]
    fn small_frames_queue_deep_and_large_ones_few() {
        let (tx, _rx) = frame_queue();
        let small = frame(125);
        let sent = (0..MAX_FRAMES + 5)
            .take_while(|_| tx.try_send(small.clone()).is_ok())
            .count();
        assert_eq!(sent, MAX_FRAMES, "small frames stop at the count");

        let (tx, _rx) = frame_queue();
        // About 1.2 MB each: the byte budget stops them first.
        let large = frame(100_000);
        let sent = (0..MAX_FRAMES)
            .take_while(|_| tx.try_send(large.clone()).is_ok())
            .count();
        assert_eq!(sent, MAX_BYTES / frame_bytes(&large));
    }

    #[tokio::test]
    async fn a_frame_over_the_budget_goes_alone_and_receiving_frees_room() {
        let (tx, mut rx) = frame_queue();
        let huge = frame(MAX_BYTES / 4);
        assert_eq!(tx.try_send(huge.clone()), Ok(()));
        assert_eq!(tx.try_send(huge.clone()), Err(Dropped::Full));
        assert!(rx.recv().await.is_some());
        assert_eq!(tx.try_send(huge), Ok(()));

        let (tx, rx) = frame_queue();
        drop(rx);
        assert_eq!(tx.try_send(frame(1)), Err(Dropped::Closed));
    }
}
