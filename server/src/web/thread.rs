//! The viewer's own thread, scheduled below the simulations.
//!
//! A page's frames are framed, copied and written to its socket by the
//! thread that serves its connection: twenty pages on a session of
//! 100,000 particles move 50 MB a step, CPU that a busy host's
//! simulations lose. So the viewer's listener runs on a runtime of its
//! own, on one thread whose scheduling `--http-priority` sets: `idle`
//! (Linux's `SCHED_IDLE`) runs it only on CPU time the simulations leave,
//! and a page gets the frames the server has time for, skipping the rest
//! as a slow zenoh subscriber does; it never holds a step up. A lower
//! niceness would not do this: the scheduler shares a busy core by
//! weight, so low-priority threads still take their share of it. The
//! load bench measures both policies (docs/performance.md). The calls
//! themselves run on the server's runtime ([`super::hop`]): only the
//! HTTP work is here.
//!
//! On Linux a scheduling policy belongs to a thread, and threads inherit
//! their creator's: the runtime's helper threads (blocking work, if any)
//! are scheduled alike. Elsewhere the thread keeps the server's priority
//! and says so in the log.

use crate::config::ViewerPriority;
use std::future::Future;
use tokio::sync::oneshot;

/// The thread's name, as `top -H` and `/proc/PID/task/*/comm` show it.
pub const THREAD_NAME: &str = "meshless-viewer";

/// Runs `work` to its end on a new thread scheduled at `priority`, on a
/// single-threaded runtime of its own. Returns once the thread is named
/// and scheduled, so that a server that says it is ready has its viewer
/// thread as `top -H` will show it (a test that read the threads at once
/// found none of that name now and then). The receiver resolves when
/// `work` has ended (or the thread could not run it, which it logs).
///
/// # Errors
/// A thread the system cannot start.
pub fn spawn<F>(priority: ViewerPriority, work: F) -> std::io::Result<oneshot::Receiver<()>>
where
    F: Future<Output = ()> + Send + 'static,
{
    let (ended, done) = oneshot::channel();
    let (started, scheduled) = std::sync::mpsc::sync_channel(1);
    std::thread::Builder::new()
        .name(THREAD_NAME.into())
        .spawn(move || {
            schedule(priority);
            let _ = started.send(());
            match tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
            {
                Ok(runtime) => runtime.block_on(work),
                Err(e) => tracing::error!("the viewer's runtime could not start: {e}"),
            }
            // Its connections end with the runtime, here.
            let _ = ended.send(());
        })?;
    // The thread sends before anything that can fail; a thread that died
    // first leaves the channel closed, and `done` says so.
    let _ = scheduled.recv();
    Ok(done)
}

/// Schedules the calling thread at `priority`.
#[cfg(target_os = "linux")]
fn schedule(priority: ViewerPriority) {
    use thread_priority::{
        NormalThreadSchedulePolicy, ThreadPriority, ThreadSchedulePolicy,
        set_thread_priority_and_policy, thread_native_id,
    };
    if priority == ViewerPriority::Normal {
        return;
    }
    let idle = ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Idle);
    match set_thread_priority_and_policy(thread_native_id(), ThreadPriority::Min, idle) {
        Ok(()) => tracing::debug!("the viewer's thread runs on idle CPU time"),
        Err(e) => tracing::warn!("the viewer's thread keeps the server's priority: {e:?}"),
    }
}

/// Schedules the calling thread at `priority`: only on Linux, where a
/// policy is a thread's own.
#[cfg(not(target_os = "linux"))]
fn schedule(priority: ViewerPriority) {
    if priority != ViewerPriority::Normal {
        tracing::warn!(
            "--http-priority idle works on Linux only: the viewer keeps the server's priority"
        );
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::{ViewerPriority, spawn};
    use thread_priority::{NormalThreadSchedulePolicy, ThreadSchedulePolicy};

    /// The policy the work sees on its thread.
    fn seen(priority: ViewerPriority) -> ThreadSchedulePolicy {
        let (tx, rx) = std::sync::mpsc::channel();
        let done = spawn(priority, async move {
            let _ = tx.send(thread_priority::unix::thread_schedule_policy());
        })
        .expect("a thread");
        let policy = rx.recv().expect("the work ran").expect("a policy");
        done.blocking_recv().expect("the thread says it ended");
        policy
    }

    #[test]
    fn the_work_runs_at_the_priority_asked_for() {
        assert_eq!(
            seen(ViewerPriority::Idle),
            ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Idle)
        );
        let caller = thread_priority::unix::thread_schedule_policy().expect("a policy");
        assert_eq!(seen(ViewerPriority::Normal), caller, "normal keeps it");
    }
}
