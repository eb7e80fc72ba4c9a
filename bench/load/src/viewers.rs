//! Browsers on one big session: a session's steps per second with nobody
//! watching, then with `n` simulated browser viewers, each polling
//! `NextFrame` over gRPC-web on the server's viewer listener
//! (`--http-addr`) exactly as the page does (`server/web/viewer.js`): one
//! POST over HTTP/1.1 in flight per viewer, `after` the number of the last
//! frame it got, `wait_ms` 5,000, on a keep-alive connection of its own.
//!
//! The session is a block of water at rest in a tank, a frame every step
//! (positions and velocities: 24 bytes a particle). Each arm resets it
//! and runs it forever, and times the same stretch of its steps (from
//! [`SETTLE_STEPS`] on, a fixed count), so that every arm does the same
//! work: the block is settling, and its cost per step changes as it does,
//! more than the viewers change it. The arms alternate (none, viewers;
//! then viewers, none; ...), so that a drift in the machine's speed falls
//! on both. Beside the rates: the frames each viewer got per second, and
//! the resident memory of this process (the server's, in the same
//! process) before, at the peak of and after the viewer arms.
//!
//! The viewers run in this process, as threads, on the server's cores:
//! each reads every answer off the socket and decodes its envelope and
//! number, but leaves the frame packed (a browser would unpack and draw
//! it, on its own machine). They stand for browsers on other machines,
//! which take none of the server's CPU, so they run only on CPU time
//! nothing else wants (`SCHED_IDLE`, as the server's viewer thread does
//! by default); their kernel's share of the transport (loopback TCP's
//! receiving half) still falls on the same two cores. The server's side
//! (the viewer's thread, at the `--http-priority` asked for) is the
//! server's cost; the bench measures both priorities in one run.

use anyhow::{Context, Result, bail};
use meshless_client::{Client, v1};
use meshless_server::ServerConfig;
use meshless_server::config::ViewerPriority;
use prost::Message;
use prost::bytes::Bytes;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// How long a poll waits on the server for a newer frame: the page's
/// `FRAME_WAIT_MS`.
pub const WAIT_MS: u32 = 5_000;

/// A poll's limit on this side: the wait and the frame's transfer.
const POLL_TIMEOUT: Duration = Duration::from_secs(30);

/// Largest answer a viewer reads, bytes.
const MAX_ANSWER: u64 = 256 << 20;

/// How often an arm reads the step count and samples the resident memory.
const SAMPLE_EVERY: Duration = Duration::from_millis(20);

/// A block of `side` x `height` x `side` particles of water at rest in a
/// tank, 2 cm apart, a frame every step with positions and velocities (24
/// bytes a particle): at 50 x 40 x 50, the viewer's own speed scene
/// (`bench/viewer/water_100k.toml`), built here at any size.
pub fn resting_block(side: u32, height: u32) -> String {
    let spacing = 0.02;
    let width = f64::from(side) * spacing;
    let depth = f64::from(height) * spacing;
    format!(
        "# {side} x {height} x {side} particles of water at rest.\n\
         name = \"resting block\"\n\
         [domain]\n\
         min = [0.0, 0.0, 0.0]\n\
         max = [{width:.2}, {top:.2}, {width:.2}]\n\
         [time]\n\
         dt = 0.002\n\
         [output]\n\
         fields = [\"velocity\"]\n\
         frame_every = 1\n\
         [[systems]]\n\
         kind = \"fluid\"\n\
         spacing = {spacing}\n\
         stiffness = 2.0e4\n\
         [[systems.blocks]]\n\
         region = {{ min = [0.0, 0.0, 0.0], max = [{width:.2}, {depth:.2}, {width:.2}] }}\n",
        top = depth + 0.2,
    )
}

/// Steps each arm lets the session take after its reset before the timed
/// stretch starts: the viewers are all polling by then.
pub const SETTLE_STEPS: u64 = 3;

/// One arm: the session's rate over its timed steps, and what the viewers
/// got meanwhile.
#[derive(Debug, Clone, Copy)]
pub struct Arm {
    /// Viewers polling during the arm (0: none).
    pub viewers: usize,
    /// Steps the session took in the timed stretch.
    pub steps: u64,
    /// The stretch's wall-clock time.
    pub elapsed: Duration,
    /// Frames the viewers got in the stretch, all together.
    pub frames: u64,
    /// Polls that failed in the arm.
    pub errors: u64,
    /// Largest resident memory sampled in the arm, bytes.
    pub peak_rss: u64,
}

impl Arm {
    /// Steps per second.
    pub fn steps_per_s(&self) -> f64 {
        self.steps as f64 / self.elapsed.as_secs_f64()
    }

    /// Frames each viewer got per second.
    pub fn frames_per_viewer_s(&self) -> f64 {
        if self.viewers == 0 {
            return 0.0;
        }
        self.frames as f64 / self.viewers as f64 / self.elapsed.as_secs_f64()
    }
}

/// Every arm, in order, with the session and memory figures.
#[derive(Debug, Clone)]
pub struct Viewers {
    /// Particles in every frame.
    pub particles: u64,
    /// Encoded size of the last frame a viewer got, bytes.
    pub frame_bytes: u64,
    /// Viewers in each viewer arm.
    pub viewers: usize,
    /// The arms, in the order they ran.
    pub arms: Vec<Arm>,
    /// Resident memory before the first viewer arm, bytes.
    pub rss_before: u64,
    /// The largest sampled during the viewer arms, bytes.
    pub rss_peak: u64,
    /// After the last viewer arm's viewers stopped, bytes.
    pub rss_after: u64,
}

impl Viewers {
    fn total(&self, watched: bool) -> (u64, Duration, u64) {
        self.arms
            .iter()
            .filter(|a| (a.viewers > 0) == watched)
            .fold((0, Duration::ZERO, 0), |(s, t, f), a| {
                (s + a.steps, t + a.elapsed, f + a.frames)
            })
    }

    /// Steps per second over every arm without viewers.
    pub fn alone(&self) -> f64 {
        let (steps, time, _) = self.total(false);
        steps as f64 / time.as_secs_f64()
    }

    /// Steps per second over every arm with viewers.
    pub fn watched(&self) -> f64 {
        let (steps, time, _) = self.total(true);
        steps as f64 / time.as_secs_f64()
    }

    /// `watched / alone`.
    pub fn ratio(&self) -> f64 {
        self.watched() / self.alone()
    }

    /// Frames each viewer got per second, over every viewer arm.
    pub fn frames_per_viewer_s(&self) -> f64 {
        let (_, time, frames) = self.total(true);
        frames as f64 / self.viewers.max(1) as f64 / time.as_secs_f64()
    }
}

/// This process's resident memory (`VmRSS`), bytes.
///
/// # Errors
/// Without `/proc/self/status` (not Linux).
pub fn resident_bytes() -> Result<u64> {
    let status = std::fs::read_to_string("/proc/self/status").context("/proc/self/status")?;
    let kib: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .context("no VmRSS in /proc/self/status")?;
    Ok(kib * 1024)
}

/// Starts a server with the viewer's listener at `priority` on
/// its own runtime (two workers, as in the rest of the bench), creates a
/// session of `toml` and runs `rounds` pairs of arms (no viewer and
/// `viewers` viewers, in turns), each timing `steps` steps of the session
/// after its reset.
///
/// # Errors
/// A server, session or call that fails, viewers that get no first frame,
/// or a session that faults.
pub fn measure(
    toml: &str,
    viewers: usize,
    rounds: u32,
    steps: u64,
    priority: ViewerPriority,
) -> Result<Viewers> {
    let server_runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("server")
        .enable_all()
        .build()?;
    let config = ServerConfig {
        http_addr: Some(SocketAddr::from(([127, 0, 0, 1], 0))),
        http_priority: priority,
        ..ServerConfig::ephemeral()
    };
    let server = server_runtime.block_on(meshless_server::start(config))?;
    let http = server
        .http_addr
        .context("the server serves no viewer listener")?;
    let grpc = format!("http://{}", server.grpc_addr);
    // The bench's own gRPC calls: a few a second.
    let calls = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let measured = run_arms(&calls, &grpc, http, toml, viewers, rounds, steps);
    server_runtime.block_on(server.stop())?;
    measured
}

fn run_arms(
    calls: &tokio::runtime::Runtime,
    grpc: &str,
    http: SocketAddr,
    toml: &str,
    viewers: usize,
    rounds: u32,
    steps: u64,
) -> Result<Viewers> {
    let client = calls.block_on(Client::connect(grpc))?;
    let session = calls.block_on(client.create_session_toml(toml))?;
    let id = session.id.clone();
    let step = || -> Result<(u64, Instant)> {
        let session = calls.block_on(client.get_session(&id))?;
        let status = session.status.context("a session without a status")?;
        if status.state == v1::SessionState::Faulted as i32 {
            bail!(
                "the session faulted at step {}: {}",
                status.step,
                status.reason
            );
        }
        Ok((status.step, Instant::now()))
    };
    let url = format!("http://{http}/meshless.v1.Simulation/NextFrame");
    let frame_bytes = Arc::new(AtomicU64::new(0));
    let mut arms = Vec::new();
    let (mut rss_before, mut rss_peak, mut rss_after) = (0, 0, 0);
    for round in 0..rounds {
        let order = if round % 2 == 0 {
            [0, viewers]
        } else {
            [viewers, 0]
        };
        for watched in order {
            calls.block_on(client.reset(&id))?;
            calls.block_on(client.run_forever(&id, None))?;
            let stop = Arc::new(AtomicBool::new(false));
            let frames = Arc::new(AtomicU64::new(0));
            let errors = Arc::new(AtomicU64::new(0));
            if watched > 0 && rss_before == 0 {
                rss_before = resident_bytes()?;
            }
            let threads: Vec<_> = (0..watched)
                .map(|k| {
                    let viewer = Viewer {
                        url: url.clone(),
                        id: id.clone(),
                        stop: stop.clone(),
                        frames: frames.clone(),
                        errors: errors.clone(),
                        frame_bytes: frame_bytes.clone(),
                    };
                    std::thread::Builder::new()
                        .name(format!("viewer-{k}"))
                        .spawn(move || viewer.run())
                })
                .collect::<Result<_, _>>()?;
            // Every viewer has its first frame, and the session its
            // first steps, before the timed stretch starts.
            let start = Instant::now();
            while frames.load(Ordering::Relaxed) < watched as u64 || step()?.0 < SETTLE_STEPS {
                if start.elapsed() > POLL_TIMEOUT {
                    stop.store(true, Ordering::Relaxed);
                    bail!(
                        "{} of {watched} viewers got a first frame in {POLL_TIMEOUT:?} ({} polls \
                         failed)",
                        frames.load(Ordering::Relaxed),
                        errors.load(Ordering::Relaxed)
                    );
                }
                std::thread::sleep(Duration::from_millis(10));
            }
            let (first, opened) = step()?;
            let got = frames.load(Ordering::Relaxed);
            let failed = errors.load(Ordering::Relaxed);
            let mut peak = resident_bytes()?;
            let (last, closed) = loop {
                std::thread::sleep(SAMPLE_EVERY);
                peak = peak.max(resident_bytes()?);
                let now = step()?;
                if now.0 >= first + steps {
                    break now;
                }
            };
            let got = frames.load(Ordering::Relaxed) - got;
            stop.store(true, Ordering::Relaxed);
            for thread in threads {
                thread
                    .join()
                    .map_err(|_| anyhow::anyhow!("a viewer panicked"))?;
            }
            arms.push(Arm {
                viewers: watched,
                steps: last - first,
                elapsed: closed - opened,
                frames: got,
                errors: errors.load(Ordering::Relaxed) - failed,
                peak_rss: peak,
            });
            if watched > 0 {
                rss_peak = rss_peak.max(peak);
                rss_after = resident_bytes()?;
            }
        }
    }
    calls.block_on(client.delete_session(&id))?;
    Ok(Viewers {
        particles: session.particle_count,
        frame_bytes: frame_bytes.load(Ordering::Relaxed),
        viewers,
        arms,
        rss_before,
        rss_peak,
        rss_after,
    })
}

/// Lowers the calling thread to idle CPU time (`SCHED_IDLE`): a browser
/// on another machine takes none of the server's CPU. On Linux a policy
/// is a thread's own; elsewhere the viewers keep the server's priority
/// (and cost it more than browsers would).
fn lowest_priority() {
    #[cfg(target_os = "linux")]
    {
        use thread_priority::{
            NormalThreadSchedulePolicy, ThreadPriority, ThreadSchedulePolicy,
            set_thread_priority_and_policy, thread_native_id,
        };
        let idle = ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Idle);
        if let Err(e) =
            set_thread_priority_and_policy(thread_native_id(), ThreadPriority::Min, idle)
        {
            eprintln!("a viewer keeps its priority: {e:?}");
        }
    }
}

/// One simulated browser: polls until `stop`, one poll in flight.
struct Viewer {
    url: String,
    id: String,
    stop: Arc<AtomicBool>,
    frames: Arc<AtomicU64>,
    errors: Arc<AtomicU64>,
    frame_bytes: Arc<AtomicU64>,
}

impl Viewer {
    fn run(self) {
        lowest_priority();
        // One keep-alive connection, as a page's polls reuse theirs.
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .timeout_global(Some(POLL_TIMEOUT))
            .build()
            .into();
        let mut after = 0;
        while !self.stop.load(Ordering::Relaxed) {
            match self.poll(&agent, after) {
                Ok((number, bytes)) => {
                    if bytes > 0 {
                        after = number;
                        self.frames.fetch_add(1, Ordering::Relaxed);
                        self.frame_bytes.store(bytes as u64, Ordering::Relaxed);
                    }
                }
                Err(_) => {
                    self.errors.fetch_add(1, Ordering::Relaxed);
                    // As the page does: wait a little, then poll again.
                    std::thread::sleep(Duration::from_millis(100));
                }
            }
        }
    }

    /// One `NextFrame` poll: the answer's number and its frame's size (0
    /// when no newer frame came).
    fn poll(&self, agent: &ureq::Agent, after: u64) -> Result<(u64, usize)> {
        let request = v1::NextFrameRequest {
            session_id: self.id.clone(),
            after,
            wait_ms: WAIT_MS,
        }
        .encode_to_vec();
        let mut body = Vec::with_capacity(5 + request.len());
        body.push(0);
        body.extend_from_slice(&u32::try_from(request.len())?.to_be_bytes());
        body.extend_from_slice(&request);
        let mut response = agent
            .post(&self.url)
            .header("content-type", "application/grpc-web+proto")
            .header("accept", "application/grpc-web+proto")
            .header("x-grpc-web", "1")
            .send(&body[..])?;
        if let Some(status) = response.headers().get("grpc-status") {
            bail!("refused: grpc-status {status:?}");
        }
        let answer = Bytes::from(
            response
                .body_mut()
                .with_config()
                .limit(MAX_ANSWER)
                .read_to_vec()?,
        );
        let (mut message, mut trailers) = (None, None);
        let mut at = 0;
        while at + 5 <= answer.len() {
            let length = u32::from_be_bytes(answer[at + 1..at + 5].try_into()?) as usize;
            let end = at + 5 + length;
            if end > answer.len() {
                bail!("a frame of {length} bytes cut short");
            }
            if answer[at] & 0x80 != 0 {
                trailers = Some(String::from_utf8_lossy(&answer[at + 5..end]).into_owned());
            } else if message.is_none() {
                // A slice of the answer: the frame is not copied again.
                message = Some(answer.slice(at + 5..end));
            }
            at = end;
        }
        let trailers = trailers.context("an answer without trailers")?;
        if !trailers.split("\r\n").any(|l| l == "grpc-status:0") {
            bail!("failed: {trailers:?}");
        }
        let reply = v1::NextFrameResponse::decode(message.context("an answer without a message")?)?;
        Ok((reply.number, reply.frame.len()))
    }
}
