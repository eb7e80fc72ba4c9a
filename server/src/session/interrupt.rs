//! Stopping the compute thread's work in progress from the gRPC side.
//!
//! Commands reach the compute thread on a channel it reads only between
//! steps, and one step can run for seconds, so a Pause, a deletion or a
//! caller that gave up cannot wait for their message to be read: they
//! raise the [`Cancel`] of the work in progress directly, which the
//! engine reads within a sub-step or solver iteration.
//!
//! Messages are numbered in the order the channel carries them. The
//! compute thread begins each piece of stepping work (a `Step`, a run) for
//! a message and steps with that piece's flag; a Pause raises the flags
//! of the work begun for every message sent before it, whether it is in
//! progress or still queued, and a caller that gave up on its `Step`
//! raises the flag of that one.

use meshless_engine::Cancel;
use std::sync::Mutex;

/// The numbering of a session's messages and the flag of its work in
/// progress, shared by the session's handle and its compute thread.
#[derive(Debug, Default)]
pub struct Interrupts {
    state: Mutex<State>,
}

#[derive(Debug, Default)]
struct State {
    /// Messages numbered so far.
    sent: u64,
    /// Work begun for a message numbered below this is interrupted.
    below: u64,
    /// The message the work in progress was begun for, and its flag.
    current: Option<(u64, Cancel)>,
}

impl Interrupts {
    fn state(&self) -> std::sync::MutexGuard<'_, State> {
        self.state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Numbers a message and hands it to `send`, under the lock, so that
    /// numbers follow the channel's order. An `interrupting` message (a
    /// Pause) first interrupts the work of every message before it.
    ///
    /// # Errors
    /// What `send` returns; the number is used up either way.
    pub fn send<E>(
        &self,
        interrupting: bool,
        send: impl FnOnce(u64) -> Result<(), E>,
    ) -> Result<u64, E> {
        let mut state = self.state();
        let number = state.sent;
        state.sent += 1;
        if interrupting {
            state.interrupt_below(number);
        }
        send(number).map(|()| number)
    }

    /// Interrupts the work of every message, sent or to come: the session
    /// is shutting down.
    pub fn interrupt_all(&self) {
        self.state().interrupt_below(u64::MAX);
    }

    /// The caller of message `number` gave up: interrupts the work begun
    /// for it, if it is in progress. (Work not begun yet sees the closed
    /// reply channel, which the caller closes first.)
    pub fn abandon(&self, number: u64) {
        if let Some((begun, cancel)) = &self.state().current
            && *begun == number
        {
            cancel.cancel();
        }
    }

    /// The flag of new work for message `number`, already raised when a
    /// later message interrupted it while it was queued.
    pub fn begin(&self, number: u64) -> Cancel {
        let mut state = self.state();
        let cancel = Cancel::new();
        if number < state.below {
            cancel.cancel();
        }
        state.current = Some((number, cancel.clone()));
        cancel
    }
}

#[cfg(test)]
impl Interrupts {
    /// The message whose work is in progress (or was last begun).
    pub fn begun(&self) -> Option<u64> {
        self.state().current.as_ref().map(|(number, _)| *number)
    }
}

impl State {
    fn interrupt_below(&mut self, number: u64) {
        self.below = self.below.max(number);
        if let Some((begun, cancel)) = &self.current
            && *begun < number
        {
            cancel.cancel();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn send(interrupts: &Interrupts, interrupting: bool) -> u64 {
        interrupts
            .send(interrupting, |_| Ok::<(), ()>(()))
            .expect("sent")
    }

    #[test]
    fn an_interrupt_reaches_the_work_of_earlier_messages_only() {
        let interrupts = Interrupts::default();
        let run = send(&interrupts, false);
        let queued = send(&interrupts, false);
        let running = interrupts.begin(run);
        let pause = send(&interrupts, true);
        let later = send(&interrupts, false);
        assert!(running.is_cancelled(), "the work in progress");
        assert!(interrupts.begin(queued).is_cancelled(), "work still queued");
        assert!(!interrupts.begin(pause).is_cancelled());
        assert!(!interrupts.begin(later).is_cancelled(), "work sent after");
    }

    #[test]
    fn abandoning_reaches_only_the_callers_own_work() {
        let interrupts = Interrupts::default();
        let first = send(&interrupts, false);
        let second = send(&interrupts, false);
        let work = interrupts.begin(second);
        interrupts.abandon(first);
        assert!(!work.is_cancelled(), "another caller's work goes on");
        interrupts.abandon(second);
        assert!(work.is_cancelled());
    }

    #[test]
    fn a_shutdown_interrupts_everything() {
        let interrupts = Interrupts::default();
        let first = send(&interrupts, false);
        let work = interrupts.begin(first);
        interrupts.interrupt_all();
        assert!(work.is_cancelled());
        let next = send(&interrupts, false);
        assert!(interrupts.begin(next).is_cancelled());
    }
}
