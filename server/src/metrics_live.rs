//! The gauges computed at each scrape from the sessions themselves: what
//! they are now (sessions by state, particles, real-time factor) and the
//! checkpoint age. Apart from the counters (`metrics.rs`), which the
//! sessions, registry and checkpoints record into: this collector reads
//! them, so it sits above them. Gauges computed at scrape time never keep
//! a deleted session's labels.

use crate::checkpoint::Checkpoints;
use crate::error::state_name;
use crate::registry::Registry as Sessions;
use meshless_proto::v1::SessionState;
use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeLabelSet, EncodeMetric};
use prometheus_client::metrics::gauge::ConstGauge;
use std::sync::{Arc, Weak};
use std::time::SystemTime;

/// The gauges of what the sessions are now, read at each scrape.
#[derive(Debug)]
pub struct LiveCollector {
    sessions: Weak<Sessions>,
    checkpoints: Option<Arc<Checkpoints>>,
}

impl LiveCollector {
    /// Gauges of `sessions` (held weakly: a scrape after shutdown reads
    /// none) and of the checkpoints' age, when the server keeps them.
    pub fn new(sessions: &Arc<Sessions>, checkpoints: Option<Arc<Checkpoints>>) -> Self {
        Self {
            sessions: Arc::downgrade(sessions),
            checkpoints,
        }
    }
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct StateLabel {
    state: &'static str,
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct SessionLabel {
    session: String,
}

impl Collector for LiveCollector {
    fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        if let Some(sessions) = self.sessions.upgrade() {
            let sessions = sessions.list();
            let states = [
                SessionState::Idle,
                SessionState::Running,
                SessionState::Paused,
                SessionState::Finished,
                SessionState::Faulted,
            ];
            let mut family = encoder.encode_descriptor(
                "sessions",
                "Sessions held, by state",
                None,
                ConstGauge::new(0i64).metric_type(),
            )?;
            for state in states {
                let count = sessions
                    .iter()
                    .filter(|s| s.status().state == state as i32)
                    .count();
                ConstGauge::new(count as i64).encode(family.encode_family(&StateLabel {
                    state: state_name(state),
                })?)?;
            }
            let particles: usize = sessions.iter().map(|s| s.particle_count).sum();
            let gauge = ConstGauge::new(particles as i64);
            gauge.encode(encoder.encode_descriptor(
                "particles",
                "Particles of all sessions",
                None,
                gauge.metric_type(),
            )?)?;
            // One label per session: bounded by --max-sessions.
            let mut family = encoder.encode_descriptor(
                "realtime_factor",
                "Simulated seconds per wall-clock second of each session's last step",
                None,
                ConstGauge::new(0.0f64).metric_type(),
            )?;
            for session in &sessions {
                ConstGauge::new(session.realtime_factor()).encode(family.encode_family(
                    &SessionLabel {
                        session: session.id.clone(),
                    },
                )?)?;
            }
        }
        if let Some(at) = self.checkpoints.as_ref().and_then(|c| c.last_round()) {
            let age = SystemTime::now()
                .duration_since(at)
                .unwrap_or_default()
                .as_secs_f64();
            let gauge = ConstGauge::new(age);
            gauge.encode(encoder.encode_descriptor(
                "checkpoint_age_seconds",
                "Seconds since the last checkpoint round finished",
                None,
                gauge.metric_type(),
            )?)?;
        }
        Ok(())
    }
}
