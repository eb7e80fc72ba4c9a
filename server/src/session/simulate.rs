//! `SimulateSteps`: many steps with progress. The steps go to the
//! compute thread in chunks sized to report about every interval; a
//! caller that goes away, or a deadline that passes, abandons the chunk in
//! hand, whose step in progress is undone (`interrupt.rs`), so the
//! session ends at its last completed step.

use super::{Command, Session};
use crate::error::ServiceError;
use meshless_proto::v1;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;
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

/// Largest chunk: a step count no single `Step` command exceeds.
const MAX_CHUNK: u64 = 1_000_000;

impl Session {
    /// Takes `job.steps` steps in chunks, sending progress to `tx`: one
    /// message first, then one per chunk, the last with `done` set. Ends
    /// early, at the last completed step, when `tx` closes, the deadline
    /// passes, the session faults or another command interrupts it.
    pub async fn simulate(
        self: Arc<Self>,
        job: Simulate,
        tx: mpsc::Sender<Result<v1::SimulateProgress, Status>>,
    ) {
        let first = self.status();
        let started = Instant::now();
        let progress = |status: v1::SessionStatus, done: bool| {
            let steps_done = status.step.saturating_sub(first.step);
            let elapsed = started.elapsed().as_secs_f64();
            let simulated = status.time - first.time;
            v1::SimulateProgress {
                status: Some(status),
                steps_done,
                steps_total: job.steps,
                done,
                realtime_factor: if elapsed > 0.0 {
                    simulated / elapsed
                } else {
                    0.0
                },
            }
        };
        if tx.send(Ok(progress(first.clone(), false))).await.is_err() {
            return;
        }
        let mut taken = 0;
        let mut chunk = 1;
        while taken < job.steps {
            let want = chunk.min(job.steps - taken);
            let began = Instant::now();
            let step = self.command(Command::Step(want));
            let deadline = async {
                match job.deadline {
                    Some(at) => tokio::time::sleep_until(at.into()).await,
                    None => std::future::pending().await,
                }
            };
            // Dropping `step` (the caller gone, the deadline passed)
            // interrupts it at its step in progress.
            let answer = tokio::select! {
                answer = step => answer,
                () = tx.closed() => return,
                () = deadline => {
                    let status = self.status();
                    let _ = tx
                        .send(Err(Status::deadline_exceeded(format!(
                            "the deadline passed at step {} after {} of {} steps; the session is \
                             paused there",
                            status.step,
                            status.step.saturating_sub(first.step),
                            job.steps
                        ))))
                        .await;
                    return;
                }
            };
            let status = match answer {
                Ok(status) => status,
                Err(e) => {
                    let _ = tx.send(Err(e.into())).await;
                    return;
                }
            };
            let done_now = status.step.saturating_sub(first.step);
            let faulted = status.state == v1::SessionState::Faulted as i32;
            // Fewer steps than asked: a Pause or a fault stopped them.
            let stopped = done_now < taken + want;
            taken = done_now;
            let done = taken >= job.steps || faulted;
            if tx.send(Ok(progress(status, done))).await.is_err() || done || stopped {
                return;
            }
            // The next chunk takes about one interval, by this one's pace.
            let per_step = began.elapsed().as_secs_f64() / want as f64;
            chunk = if per_step > 0.0 {
                ((job.interval.as_secs_f64() / per_step) as u64).clamp(1, MAX_CHUNK)
            } else {
                MAX_CHUNK
            };
        }
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
