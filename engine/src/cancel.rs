//! Stopping long work from another thread. One step can run for seconds
//! (a large `time.dt` split into many sub-steps, an implicit solid's
//! Newton loop, a CG solve) and so can an optimisation; whoever started
//! it may need it back sooner (a pause, a deletion, a client that gave
//! up). A [`Cancel`] is raised by the other thread and read by the work
//! at its loop heads: once per sub-step, per Newton or Levenberg–Marquardt
//! iteration and per CG iteration, each a relaxed atomic load, so the
//! work stops within one of those iterations and an uncancelled run
//! computes exactly what it did without the checks. A modal solid's
//! precompute reads it per chunk of every long loop (octree, quadrature,
//! shape functions, assembly, rotation modes, skin) and in the
//! eigensolver.
//!
//! Cancelled work reports [`Cancelled`] and leaves its owner at a
//! consistent state: a world goes back to the start of the step (see
//! [`crate::World::step_cancellable`]), a design solve changes nothing.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// A cancellation flag shared by the work and whoever may stop it: clones
/// share one flag, and once raised it stays raised (make a new one for
/// the next piece of work).
#[derive(Debug, Clone, Default)]
pub struct Cancel(Arc<Flag>);

/// The shared flag; in the engine's own tests also a count of its reads
/// and the read from which it raises itself, so that a test can stop work
/// at a chosen point inside a loop without timing anything.
#[derive(Debug, Default)]
struct Flag {
    raised: AtomicBool,
    #[cfg(test)]
    reads: std::sync::atomic::AtomicUsize,
    #[cfg(test)]
    raise_at: Option<usize>,
}

impl Cancel {
    /// A flag not raised yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// A flag that raises itself at its `read`-th read (1-based): work
    /// stopped from inside, at a point a test picks by counting reads.
    #[cfg(test)]
    pub(crate) fn raised_at_read(read: usize) -> Self {
        Self(Arc::new(Flag {
            raise_at: Some(read),
            ..Flag::default()
        }))
    }

    /// How many times the work read this flag (tests only).
    #[cfg(test)]
    pub(crate) fn reads(&self) -> usize {
        self.0.reads.load(Ordering::Relaxed)
    }

    /// Asks the work holding a clone to stop at its next check.
    pub fn cancel(&self) {
        // Relaxed: the flag orders nothing else; the working thread only
        // needs to see it eventually, and sees it within one iteration.
        self.0.raised.store(true, Ordering::Relaxed);
    }

    /// Whether [`Self::cancel`] was called on this flag or a clone.
    pub fn is_cancelled(&self) -> bool {
        #[cfg(test)]
        {
            let read = self.0.reads.fetch_add(1, Ordering::Relaxed) + 1;
            if self.0.raise_at.is_some_and(|at| read >= at) {
                self.cancel();
            }
        }
        self.0.raised.load(Ordering::Relaxed)
    }

    /// A guard that raises this flag when it is dropped: ties the work to
    /// the lifetime of whatever holds the guard (a request, a stream), so
    /// that work nobody waits for any more stops.
    pub fn raise_on_drop(&self) -> RaiseOnDrop {
        RaiseOnDrop(self.clone())
    }

    /// [`Cancelled`] once raised, to end work with `?`.
    ///
    /// # Errors
    /// [`Cancelled`] when the flag is raised.
    pub fn check(&self) -> Result<(), Cancelled> {
        if self.is_cancelled() {
            Err(Cancelled)
        } else {
            Ok(())
        }
    }
}

/// Raises its [`Cancel`] when dropped ([`Cancel::raise_on_drop`]).
#[derive(Debug)]
pub struct RaiseOnDrop(Cancel);

impl Drop for RaiseOnDrop {
    fn drop(&mut self) {
        self.0.cancel();
    }
}

/// Work stopped because its [`Cancel`] was raised.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("cancelled")]
pub struct Cancelled;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clones_share_one_flag_that_stays_raised() {
        let cancel = Cancel::new();
        let other = cancel.clone();
        assert!(!cancel.is_cancelled());
        assert_eq!(cancel.check(), Ok(()));
        other.cancel();
        assert!(cancel.is_cancelled());
        assert_eq!(cancel.check(), Err(Cancelled));
        assert!(!Cancel::new().is_cancelled(), "a new flag is its own");
    }

    #[test]
    fn a_flag_raised_at_a_read_counts_its_reads() {
        let cancel = Cancel::raised_at_read(3);
        assert_eq!(cancel.check(), Ok(()));
        assert_eq!(cancel.check(), Ok(()));
        assert_eq!(cancel.check(), Err(Cancelled), "the third read raises it");
        assert!(cancel.is_cancelled(), "and it stays raised");
        assert_eq!(cancel.reads(), 4);
    }

    #[test]
    fn a_dropped_guard_raises_its_flag() {
        let cancel = Cancel::new();
        let guard = cancel.raise_on_drop();
        assert!(!cancel.is_cancelled());
        drop(guard);
        assert!(cancel.is_cancelled(), "the work sees its caller go");
    }
}
