//! Prometheus metrics: what the sessions compute (steps, sub-steps,
//! solver iterations, time per solver stage, faults), what they publish
//! (frames, bytes, frames dropped under congestion), what callers ask
//! (RPCs by method and code, with latency), and the gauges of what the
//! sessions are now, which `metrics_live.rs` computes at each scrape. This
//! file knows no session, registry or checkpoint, so that all of them can
//! count into it without an import loop.
//!
//! Served as the Prometheus text format at `GET /metrics` on
//! `--metrics-addr` (docs/operations.md lists every metric).

use meshless_engine::StepError;
use meshless_engine::stats::{Stage, StageTimer};
use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeLabelSet};
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, OnceLock};
use std::time::Duration;

type FloatCounter = Counter<f64, AtomicU64>;

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct StageLabel {
    stage: &'static str,
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct ReasonLabel {
    reason: &'static str,
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct MethodLabel {
    method: &'static str,
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RpcLabel {
    method: &'static str,
    code: &'static str,
}

fn latency() -> Histogram {
    // 100 us to about 26 s.
    Histogram::new(exponential_buckets(1e-4, 4.0, 10))
}

fn step_time() -> Histogram {
    // 10 us to about 2.6 s.
    Histogram::new(exponential_buckets(1e-5, 4.0, 10))
}

/// Every metric the server records, and the registry that encodes them.
#[derive(Debug)]
pub struct Metrics {
    registry: Registry,
    steps: Counter,
    substeps: Counter,
    solver_iterations: Counter,
    unconverged: Counter,
    simulated_seconds: FloatCounter,
    step_seconds: Histogram,
    stage_seconds: Family<StageLabel, FloatCounter>,
    faults: Family<ReasonLabel, Counter>,
    frames_published: Counter,
    frames_dropped: Counter,
    bytes_sent: Counter,
    snapshots: Counter,
    restores: Counter,
    checkpoint_failures: Counter,
    rpcs: Family<RpcLabel, Counter>,
    rpc_seconds: Family<MethodLabel, Histogram, fn() -> Histogram>,
    /// The scrape-time gauges (`metrics_live.rs`), set once the sessions
    /// exist (they need the metrics first).
    live: Arc<OnceLock<Box<dyn Collector>>>,
}

impl Metrics {
    /// Every metric at zero, registered under `meshless_`.
    pub fn new() -> Self {
        let mut registry = Registry::with_prefix("meshless");
        let steps = Counter::default();
        registry.register("steps", "Steps completed by all sessions", steps.clone());
        let substeps = Counter::default();
        registry.register(
            "substeps",
            "Sub-steps those steps were split into (the most any system took)",
            substeps.clone(),
        );
        let solver_iterations = Counter::default();
        registry.register(
            "solver_iterations",
            "Pressure-solver and implicit-solid iterations",
            solver_iterations.clone(),
        );
        let unconverged = Counter::default();
        registry.register(
            "unconverged_solves",
            "Solves that stopped at their iteration cap above their tolerance",
            unconverged.clone(),
        );
        let simulated_seconds = FloatCounter::default();
        registry.register(
            "simulated_seconds",
            "Simulated time advanced by all sessions, s (its rate is the real-time factor)",
            simulated_seconds.clone(),
        );
        let step_seconds = step_time();
        registry.register(
            "step_seconds",
            "Wall-clock time of one step, s",
            step_seconds.clone(),
        );
        let stage_seconds = Family::default();
        registry.register(
            "stage_seconds",
            "Wall-clock time in each stage of the fluid's step pipeline, s",
            stage_seconds.clone(),
        );
        let faults = Family::default();
        registry.register("faults", "Sessions faulted, by reason", faults.clone());
        let frames_published = Counter::default();
        registry.register(
            "frames_published",
            "Frames put on zenoh",
            frames_published.clone(),
        );
        let frames_dropped = Counter::default();
        registry.register(
            "frames_dropped",
            "Frames dropped because the publisher was behind",
            frames_dropped.clone(),
        );
        let bytes_sent = Counter::default();
        registry.register(
            "zenoh_bytes_sent",
            "Bytes of frames, status changes and latest-frame replies put on zenoh",
            bytes_sent.clone(),
        );
        let snapshots = Counter::default();
        registry.register(
            "snapshots",
            "Snapshots taken (by Snapshot and by checkpoints)",
            snapshots.clone(),
        );
        let restores = Counter::default();
        registry.register(
            "restores",
            "Snapshots restored (by Restore and from checkpoints)",
            restores.clone(),
        );
        let checkpoint_failures = Counter::default();
        registry.register(
            "checkpoint_failures",
            "Checkpoints not written (a full disk, an unwritable file); the last good one stays",
            checkpoint_failures.clone(),
        );
        let rpcs = Family::default();
        registry.register(
            "rpcs",
            "gRPC calls by method and status code (a stream's code as it started)",
            rpcs.clone(),
        );
        let rpc_seconds = Family::new_with_constructor(latency as fn() -> Histogram);
        registry.register(
            "rpc_seconds",
            "gRPC call latency to the response's headers (a unary call's whole time), s",
            rpc_seconds.clone(),
        );
        let live = Arc::new(OnceLock::new());
        registry.register_collector(Box::new(Deferred(live.clone())));
        Self {
            registry,
            steps,
            substeps,
            solver_iterations,
            unconverged,
            simulated_seconds,
            step_seconds,
            stage_seconds,
            faults,
            frames_published,
            frames_dropped,
            bytes_sent,
            snapshots,
            restores,
            checkpoint_failures,
            rpcs,
            rpc_seconds,
            live,
        }
    }

    /// Adds the gauges computed at each scrape from what the sessions are
    /// now (`metrics_live.rs`); the first call wins.
    pub fn watch(&self, live: Box<dyn Collector>) {
        let _ = self.live.set(live);
    }

    /// Records one completed step: its wall time, the simulated time it
    /// advanced, how it went, and what each stage took (`before` is the
    /// world's stage timer before the step, `after` after it).
    pub fn step(
        &self,
        info: &meshless_engine::StepInfo,
        dt: f64,
        wall: Duration,
        before: &StageTimer,
        after: &StageTimer,
    ) {
        self.steps.inc();
        self.substeps.inc_by(u64::from(info.substeps));
        self.solver_iterations
            .inc_by(u64::from(info.solver_iterations));
        self.unconverged.inc_by(u64::from(info.unconverged));
        self.simulated_seconds.inc_by(dt);
        self.step_seconds.observe(wall.as_secs_f64());
        for ((stage, was), (_, is)) in before.iter().zip(after.iter()) {
            let spent = is.seconds - was.seconds;
            if spent > 0.0 {
                self.stage_seconds
                    .get_or_create(&StageLabel {
                        stage: stage_key(stage),
                    })
                    .inc_by(spent);
            }
        }
    }

    /// Records a fault.
    pub fn fault(&self, error: Option<&StepError>) {
        let reason = match error {
            Some(StepError::Unstable { .. }) => "fluid_unstable",
            Some(StepError::SolidUnstable { .. }) => "solid_unstable",
            Some(StepError::Collapsed { .. }) => "solid_collapsed",
            Some(StepError::CracksOutgrown { .. }) => "cracks_outgrown",
            Some(StepError::FragmentFreeInStatics { .. }) => "fragment_free_in_statics",
            Some(StepError::ParticleLimit { .. }) => "particle_limit",
            Some(StepError::Compressed { .. }) => "compressed",
            Some(StepError::EnergyGained { .. }) => "energy_gained",
            Some(StepError::SolidEnergyGained { .. }) => "solid_energy_gained",
            Some(StepError::ShellFailed { .. }) => "shell_failed",
            // Never a fault: the step is undone, or refused untaken.
            Some(StepError::Cancelled { .. } | StepError::CounterFull { .. }) => return,
            None => "internal",
        };
        self.faults.get_or_create(&ReasonLabel { reason }).inc();
    }

    /// Records a frame put on zenoh (its bytes go through [`Self::sent`]).
    pub fn frame_published(&self) {
        self.frames_published.inc();
    }

    /// Records a frame dropped under congestion.
    pub fn frame_dropped(&self) {
        self.frames_dropped.inc();
    }

    /// Records `bytes` put on zenoh.
    pub fn sent(&self, bytes: usize) {
        self.bytes_sent.inc_by(bytes as u64);
    }

    /// Records a snapshot taken.
    pub fn snapshot(&self) {
        self.snapshots.inc();
    }

    /// Records a snapshot restored.
    pub fn restore(&self) {
        self.restores.inc();
    }

    /// Records a checkpoint that was not written.
    pub fn checkpoint_failed(&self) {
        self.checkpoint_failures.inc();
    }

    /// Records a call of `method` ([`method_name`]) answered with `code`
    /// after `elapsed`.
    pub fn rpc(&self, method: &'static str, code: tonic::Code, elapsed: Duration) {
        self.rpcs
            .get_or_create(&RpcLabel {
                method,
                code: code_name(code),
            })
            .inc();
        self.rpc_seconds
            .get_or_create(&MethodLabel { method })
            .observe(elapsed.as_secs_f64());
    }

    /// Everything, in the Prometheus text format.
    pub fn encode(&self) -> String {
        let mut text = String::new();
        // Writing to a String cannot fail; a collector that did would
        // leave a partial scrape, which Prometheus reports.
        let _ = prometheus_client::encoding::text::encode(&mut text, &self.registry);
        text
    }
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}

/// The scrape-time gauges, once [`Metrics::watch`] has given them:
/// nothing is encoded before.
#[derive(Debug)]
struct Deferred(Arc<OnceLock<Box<dyn Collector>>>);

impl Collector for Deferred {
    fn encode(&self, encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        match self.0.get() {
            Some(live) => live.encode(encoder),
            None => Ok(()),
        }
    }
}

/// A stage's label value.
fn stage_key(stage: Stage) -> &'static str {
    match stage {
        Stage::NeighborSearch => "neighbor_search",
        Stage::Density => "density",
        Stage::PressureForce => "pressure_force",
        Stage::PressureSolve => "pressure_solve",
        Stage::DivergenceSolve => "divergence_solve",
        Stage::Viscosity => "viscosity",
        Stage::Xsph => "xsph",
        Stage::Integrate => "integrate",
        Stage::SolidForces => "solid_forces",
        Stage::SolidSolve => "solid_solve",
        Stage::SolidIntegrate => "solid_integrate",
        Stage::SolidContact => "solid_contact",
        Stage::ModalSolve => "modal_solve",
        Stage::ShellSolve => "shell_solve",
    }
}

/// The methods of `meshless.v1.Simulation`, and of the health service;
/// anything else a caller names is `other`, so that no caller grows the
/// label set.
const METHODS: &[&str] = &[
    "GetServerInfo",
    "CreateSession",
    "GetSession",
    "ListSessions",
    "DeleteSession",
    "Step",
    "Run",
    "Pause",
    "Resume",
    "Reset",
    "WatchStatus",
    "GetLatestFrame",
    "NextFrame",
    "EditConstraints",
    "ListConstraints",
    "Optimize",
    "CancelOptimize",
    "GetDesign",
    "SimulateSteps",
    "Snapshot",
    "Restore",
    "ChangeParticles",
];

/// The method label of a request path.
pub fn method_name(path: &str) -> &'static str {
    if let Some(method) = path.strip_prefix("/meshless.v1.Simulation/") {
        return METHODS
            .iter()
            .find(|&&m| m == method)
            .copied()
            .unwrap_or("other");
    }
    match path {
        "/grpc.health.v1.Health/Check" => "health.Check",
        "/grpc.health.v1.Health/Watch" => "health.Watch",
        _ if path.starts_with("/grpc.reflection.") => "reflection",
        _ => "other",
    }
}

/// A code's label value, as gRPC spells it.
fn code_name(code: tonic::Code) -> &'static str {
    match code {
        tonic::Code::Ok => "OK",
        tonic::Code::Cancelled => "CANCELLED",
        tonic::Code::Unknown => "UNKNOWN",
        tonic::Code::InvalidArgument => "INVALID_ARGUMENT",
        tonic::Code::DeadlineExceeded => "DEADLINE_EXCEEDED",
        tonic::Code::NotFound => "NOT_FOUND",
        tonic::Code::AlreadyExists => "ALREADY_EXISTS",
        tonic::Code::PermissionDenied => "PERMISSION_DENIED",
        tonic::Code::ResourceExhausted => "RESOURCE_EXHAUSTED",
        tonic::Code::FailedPrecondition => "FAILED_PRECONDITION",
        tonic::Code::Aborted => "ABORTED",
        tonic::Code::OutOfRange => "OUT_OF_RANGE",
        tonic::Code::Unimplemented => "UNIMPLEMENTED",
        tonic::Code::Internal => "INTERNAL",
        tonic::Code::Unavailable => "UNAVAILABLE",
        tonic::Code::DataLoss => "DATA_LOSS",
        tonic::Code::Unauthenticated => "UNAUTHENTICATED",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_rpc_of_the_protocol_has_its_label() {
        let descriptor = String::from_utf8_lossy(meshless_proto::FILE_DESCRIPTOR_SET);
        for method in METHODS {
            assert!(descriptor.contains(method), "{method} is not an RPC");
        }
        // Each `rpc` line of the service is listed.
        let protos = [include_str!("../../proto/meshless/v1/simulation.proto")];
        let rpcs: Vec<&str> = protos
            .iter()
            .flat_map(|p| p.lines())
            .filter_map(|l| l.trim().strip_prefix("rpc "))
            .filter_map(|l| l.split('(').next())
            .collect();
        assert_eq!(rpcs.len(), METHODS.len(), "{rpcs:?}");
        for rpc in rpcs {
            assert_eq!(method_name(&format!("/meshless.v1.Simulation/{rpc}")), rpc);
        }
        assert_eq!(method_name("/meshless.v1.Simulation/Evil"), "other");
        assert_eq!(method_name(&"/x".repeat(1000)), "other");
    }

    #[test]
    fn steps_and_faults_are_counted_and_encoded() {
        let metrics = Metrics::new();
        let info = meshless_engine::StepInfo {
            substeps: 3,
            solver_iterations: 7,
            ..Default::default()
        };
        let timer = StageTimer::default();
        metrics.step(&info, 0.01, Duration::from_millis(2), &timer, &timer);
        metrics.fault(None);
        metrics.rpc(
            method_name("/meshless.v1.Simulation/Step"),
            tonic::Code::Ok,
            Duration::from_millis(1),
        );
        let text = metrics.encode();
        for line in [
            "meshless_steps_total 1",
            "meshless_substeps_total 3",
            "meshless_solver_iterations_total 7",
            "meshless_faults_total{reason=\"internal\"} 1",
            "meshless_rpcs_total{method=\"Step\",code=\"OK\"} 1",
        ] {
            assert!(text.contains(line), "{line} missing from\n{text}");
        }
    }
}
