//! `SimulateSteps`: many steps with progress. The steps go to the
//! compute thread as one command, which reports after each step how many
//! of them it has taken; this task turns those reports into a progress
//! message about every interval. A call sent while another stepping call
//! of the session is in progress waits for it, and counts only its own
//! steps. A caller that goes away, or a deadline that passes, abandons
//! the command, whose step in progress is undone (`interrupt.rs`), so the
//! session ends at its last completed step.

use super::{Command, Session};
use crate::error::ServiceError;
use meshless_proto::v1;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch};
use tonic::Status;

/// What a `SimulateSteps` call asked for.
#[derive(Debug, Clone, Copy)]
pub struct Simulate {
    pub steps: u64,
    /// Between progress messages.
    pub interval: Duration,
    /// When the caller stops waiting, if it said.
    pub deadline: Option<Instant>,
}

/// How far a call's steps are, as the compute thread reports them when
/// they begin and after each one.
#[derive(Debug, Clone, Copy)]
pub struct Progress {
    /// The call's own steps taken.
    pub done: u64,
    /// The session's step and simulated time after them.
    pub step: u64,
    pub time: f64,
    /// Simulated time and wall clock when the call's steps began.
    pub start_time: f64,
    pub began: Instant,
}

impl Progress {
    /// The progress message of a call of `total` steps, on `status`
    /// (the session's; its step and time are this report's).
    fn message(
        &self,
        mut status: v1::SessionStatus,
        total: u64,
        done: bool,
    ) -> v1::SimulateProgress {
        status.step = self.step;
        status.time = self.time;
        let elapsed = self.began.elapsed().as_secs_f64();
        v1::SimulateProgress {
            status: Some(status),
            steps_done: self.done,
            steps_total: total,
            done,
            realtime_factor: if elapsed > 0.0 {
                (self.time - self.start_time) / elapsed
            } else {
                0.0
            },
        }
    }
}

impl Session {
    /// Takes `job.steps` steps, sending progress to `tx`: one message
    /// when they begin, then one per interval while they advance, the
    /// last with `done` set. Ends early, at the last completed step, when
    /// `tx` closes, the deadline passes, the session faults or another
    /// command interrupts it.
    pub async fn simulate(
        self: Arc<Self>,
        job: Simulate,
        tx: mpsc::Sender<Result<v1::SimulateProgress, Status>>,
    ) {
        let (report, mut reports) = watch::channel(None);
        // Dropping `step` (the caller gone, the deadline passed)
        // interrupts it at its step in progress.
        let step = self.command(Command::Simulate(job.steps, report));
        tokio::pin!(step);
        let deadline = async {
            match job.deadline {
                Some(at) => tokio::time::sleep_until(at.into()).await,
                None => std::future::pending().await,
            }
        };
        tokio::pin!(deadline);
        let mut ticks = tokio::time::interval(job.interval);
        ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        // The steps reported in the last message sent, once they began.
        let mut sent: Option<u64> = None;
        // Until the compute thread drops its end (with the answer).
        let mut reporting = true;
        loop {
            tokio::select! {
                // In this order: the first report before the answer, so
                // that a call's first message is never its last.
                biased;
                changed = reports.changed(), if reporting && sent.is_none() => {
                    // Closed with the answer, maybe after a last report.
                    reporting = changed.is_ok();
                    // The steps began: the first message.
                    let first = *reports.borrow_and_update();
                    if let Some(p) = first {
                        sent = Some(p.done);
                        ticks.reset();
                        if tx.send(Ok(p.message(self.status(), job.steps, false))).await.is_err() {
                            return;
                        }
                    }
                }
                answer = &mut step => {
                    let last = *reports.borrow();
                    let _ = tx.send(self.finish(answer, last, job.steps)).await;
                    return;
                }
                () = tx.closed() => return,
                () = &mut deadline => {
                    let (step, done) = match *reports.borrow() {
                        Some(p) => (p.step, p.done),
                        None => (self.status().step, 0),
                    };
                    let _ = tx
                        .send(Err(Status::deadline_exceeded(format!(
                            "the deadline passed at step {step} after {done} of {} steps; the \
                             session is paused at its last completed step",
                            job.steps
                        ))))
                        .await;
                    return;
                }
                _ = ticks.tick(), if sent.is_some() => {
                    let current = *reports.borrow();
                    let Some(p) = current else { continue };
                    if sent != Some(p.done) {
                        sent = Some(p.done);
                        if tx.send(Ok(p.message(self.status(), job.steps, false))).await.is_err() {
                            return;
                        }
                    }
                }
            }
        }
    }

    /// The last message of a call of `total` steps: its answer, with the
    /// call's last report.
    fn finish(
        &self,
        answer: Result<v1::SessionStatus, ServiceError>,
        last: Option<Progress>,
        total: u64,
    ) -> Result<v1::SimulateProgress, Status> {
        let status = answer?;
        let progress = last.unwrap_or(Progress {
            done: 0,
            step: status.step,
            time: status.time,
            start_time: status.time,
            began: Instant::now(),
        });
        // Fewer steps than asked and not faulted: a Pause stopped them.
        let done = progress.done >= total || status.state == v1::SessionState::Faulted as i32;
        let mut message = progress.message(status.clone(), total, done);
        message.status = Some(status);
        Ok(message)
    }
}

/// The deadline a `grpc-timeout` header value gives (`"250m"`: 250 ms;
/// units H M S m u n), from `now`; `None` for a value that is not one.
pub fn grpc_deadline(value: &str, now: Instant) -> Option<Instant> {
    let unit_at = value.len().checked_sub(1)?;
    if !value.is_char_boundary(unit_at) {
        return None;
    }
    let (digits, unit) = value.split_at(unit_at);
    // The protocol allows at most 8 digits.
    if digits.is_empty() || digits.len() > 8 || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let n: u64 = digits.parse().ok()?;
    let timeout = match unit {
        "H" => Duration::from_secs(n.checked_mul(3600)?),
        "M" => Duration::from_secs(n.checked_mul(60)?),
        "S" => Duration::from_secs(n),
        "m" => Duration::from_millis(n),
        "u" => Duration::from_micros(n),
        "n" => Duration::from_nanos(n),
        _ => return None,
    };
    now.checked_add(timeout)
}

/// Checks a `SimulateSteps` request's numbers.
///
/// # Errors
/// [`ServiceError::InvalidArgument`] naming the field.
pub fn check_request(steps: u64, interval: f64) -> Result<Duration, ServiceError> {
    if steps == 0 || steps > MAX_SIMULATE_STEPS {
        return Err(ServiceError::invalid(
            "steps",
            format!("must be in [1, {MAX_SIMULATE_STEPS}], got {steps}"),
        ));
    }
    if interval == 0.0 {
        return Ok(DEFAULT_INTERVAL);
    }
    if !(MIN_INTERVAL..=MAX_INTERVAL).contains(&interval) {
        return Err(ServiceError::invalid(
            "progress_interval",
            format!(
                "must be 0 (every {} s) or in [{MIN_INTERVAL}, {MAX_INTERVAL}] s, got {interval}",
                DEFAULT_INTERVAL.as_secs_f64()
            ),
        ));
    }
    Ok(Duration::from_secs_f64(interval))
}

/// Most steps one `SimulateSteps` call may ask for.
pub const MAX_SIMULATE_STEPS: u64 = 1_000_000_000;
/// Progress interval when the request names none.
const DEFAULT_INTERVAL: Duration = Duration::from_millis(500);
/// Shortest progress interval, s.
const MIN_INTERVAL: f64 = 0.01;
/// Longest progress interval, s: an hour.
const MAX_INTERVAL: f64 = 3600.0;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grpc_timeouts_parse_as_the_protocol_spells_them() {
        let now = Instant::now();
        let after = |v: &str| grpc_deadline(v, now).map(|d| d - now);
        assert_eq!(after("250m"), Some(Duration::from_millis(250)));
        assert_eq!(after("2S"), Some(Duration::from_secs(2)));
        assert_eq!(after("1H"), Some(Duration::from_secs(3600)));
        assert_eq!(after("99999999n"), Some(Duration::from_nanos(99_999_999)));
        for bad in ["", "m", "123456789m", "12x", "-1S", "1.5S", "１S", "S１"] {
            assert_eq!(after(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn request_numbers_are_bounded() {
        assert!(check_request(0, 0.0).is_err());
        assert!(check_request(MAX_SIMULATE_STEPS + 1, 0.0).is_err());
        assert_eq!(check_request(5, 0.0).ok(), Some(DEFAULT_INTERVAL));
        assert!(check_request(5, 0.001).is_err());
        assert!(check_request(5, f64::NAN).is_err());
        assert_eq!(
            check_request(5, 0.25).ok(),
            Some(Duration::from_millis(250))
        );
    }
}
