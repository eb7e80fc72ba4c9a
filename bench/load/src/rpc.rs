//! Latency and throughput of gRPC calls: one caller after another
//! (sequential), several callers each on its own connection (closed
//! loop), and a fixed arrival rate (open loop).
//!
//! The open loop sends each call when it is due whether or not earlier
//! calls have returned, so a server that falls behind shows as latency
//! and calls in flight instead of quietly lowering the rate (the
//! coordinated-omission trap of closed-loop load generators). Each call
//! is timed from when it was sent: tokio's timer wakes the sender up to a
//! millisecond late, and that lateness is the generator's, not the
//! server's. A sender the machine cannot keep up with shows as an
//! achieved rate below the one asked for.

use hdrhistogram::Histogram;
use std::future::Future;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::task::JoinSet;

/// Latencies of calls above this are clamped into the histogram's top
/// bucket: a minute is a failed call in any of these measurements.
const HIGHEST_NANOS: u64 = 60_000_000_000;

/// Calls made, how long each took and over what time.
#[derive(Debug, Clone)]
pub struct Latencies {
    histogram: Histogram<u64>,
    /// Calls that failed (not in the histogram).
    pub errors: u64,
    /// Wall time of the whole measurement.
    pub elapsed: Duration,
}

impl Latencies {
    fn new() -> Self {
        Self {
            histogram: Histogram::new_with_bounds(1, HIGHEST_NANOS, 3)
                .expect("constant bounds are valid"),
            errors: 0,
            elapsed: Duration::ZERO,
        }
    }

    fn record(&mut self, latency: Duration) {
        let nanos = u64::try_from(latency.as_nanos()).unwrap_or(u64::MAX);
        self.histogram.saturating_record(nanos.max(1));
    }

    fn merge(&mut self, other: &Self) {
        self.histogram
            .add(&other.histogram)
            .expect("histograms of the same bounds add");
        self.errors += other.errors;
    }

    /// Calls that succeeded.
    pub fn calls(&self) -> u64 {
        self.histogram.len()
    }

    /// Successful calls per second of wall time.
    pub fn rate(&self) -> f64 {
        self.calls() as f64 / self.elapsed.as_secs_f64().max(f64::MIN_POSITIVE)
    }

    /// The latency at quantile `q` (0.5 for the median), in milliseconds.
    pub fn quantile_ms(&self, q: f64) -> f64 {
        self.histogram.value_at_quantile(q) as f64 / 1e6
    }
}

/// `calls` calls, each sent when the one before has returned.
pub async fn sequential<F, Fut, E>(calls: u64, mut call: F) -> Latencies
where
    F: FnMut() -> Fut,
    Fut: Future<Output = Result<(), E>>,
{
    let mut latencies = Latencies::new();
    let start = Instant::now();
    for _ in 0..calls {
        let sent = Instant::now();
        match call().await {
            Ok(()) => latencies.record(sent.elapsed()),
            Err(_) => latencies.errors += 1,
        }
    }
    latencies.elapsed = start.elapsed();
    latencies
}

/// One task per entry of `callers`, each making `calls_each` sequential
/// calls with its own `call`: concurrency without a fixed rate.
pub async fn closed_loop<F, Fut, E>(callers: Vec<F>, calls_each: u64) -> Latencies
where
    F: FnMut() -> Fut + Send + 'static,
    Fut: Future<Output = Result<(), E>> + Send + 'static,
    E: Send + 'static,
{
    let start = Instant::now();
    let mut tasks = JoinSet::new();
    for caller in callers {
        tasks.spawn(sequential(calls_each, caller));
    }
    let mut latencies = Latencies::new();
    while let Some(done) = tasks.join_next().await {
        match done {
            Ok(part) => latencies.merge(&part),
            Err(_) => latencies.errors += calls_each,
        }
    }
    latencies.elapsed = start.elapsed();
    latencies
}

/// Calls due at `rate` per second for `duration`, each sent when due in
/// its own task whether or not the ones before have returned.
pub async fn open_loop<F, Fut, E>(rate: u32, duration: Duration, call: F) -> Latencies
where
    F: Fn() -> Fut + Send + Sync + 'static,
    Fut: Future<Output = Result<(), E>> + Send + 'static,
    E: Send + 'static,
{
    let call = Arc::new(call);
    let rate = f64::from(rate.max(1));
    let total = (duration.as_secs_f64() * rate).ceil() as u64;
    let start = Instant::now();
    let mut tasks = JoinSet::new();
    let mut sent = 0u64;
    while sent < total {
        // Every call due by now leaves at once (the timer's resolution
        // is a millisecond), then the sender sleeps until the next.
        let due = ((start.elapsed().as_secs_f64() * rate) as u64 + 1).min(total);
        for _ in sent..due {
            let call = Arc::clone(&call);
            tasks.spawn(async move {
                let sent_at = Instant::now();
                let result = call().await;
                (result.is_ok(), sent_at.elapsed())
            });
        }
        sent = due;
        let next = start + Duration::from_secs_f64(sent as f64 / rate);
        tokio::time::sleep_until(next.into()).await;
    }
    let mut latencies = Latencies::new();
    while let Some(done) = tasks.join_next().await {
        match done {
            Ok((true, latency)) => latencies.record(latency),
            _ => latencies.errors += 1,
        }
    }
    latencies.elapsed = start.elapsed();
    latencies
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn quantiles_and_rates_come_from_the_recorded_calls() {
        let mut calls = 0u32;
        let latencies = sequential(10, || {
            calls += 1;
            let fail = calls == 3;
            async move { if fail { Err(()) } else { Ok(()) } }
        })
        .await;
        assert_eq!((latencies.calls(), latencies.errors), (9, 1));
        assert!(latencies.rate() > 0.0);
        assert!(latencies.quantile_ms(0.99) >= latencies.quantile_ms(0.5));
    }

    #[tokio::test]
    async fn the_open_loop_sends_on_time_however_slow_the_calls() {
        // Calls that take 30 ms, due every 5 ms: a closed loop would make
        // 4 in 100 ms; the open loop makes all 20, overlapping.
        let latencies = open_loop(200, Duration::from_millis(100), || async {
            tokio::time::sleep(Duration::from_millis(30)).await;
            Ok::<(), ()>(())
        })
        .await;
        assert_eq!((latencies.calls(), latencies.errors), (20, 0));
        assert!(latencies.quantile_ms(0.0) >= 30.0);
        assert!(
            latencies.elapsed < Duration::from_millis(600),
            "{:?}",
            latencies.elapsed
        );
    }
}
