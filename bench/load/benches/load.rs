//! `cargo bench -p meshless-load`: the service under load, as tables
//! (see the crate's documentation for what each measures). With
//! `MESHLESS_BENCH_SMOKE=1` every part runs at its smallest size, for CI.
//! `cargo bench -p meshless-load -- NAME...` runs only the parts named
//! (`rpc`, `frame_cost`, `frames`, `slow_subscriber`, `viewers`).

#[path = "../../../engine/benches/common/smoke.rs"]
mod smoke;

use anyhow::{Context, Result};
use meshless_client::Client;
use meshless_load::frames::Payload;
use meshless_load::{frame_cost, frames, rpc, slow_subscriber, viewers};
use meshless_server::ServerConfig;
use meshless_server::config::ViewerPriority;
use std::time::Duration;

/// The scene every measurement through the server drives: 125
/// particles, a frame per step, so `Step(1)` is mostly the service's own
/// cost.
const SMALL_TANK: &str = include_str!("../../../tests/fixtures/small_tank.toml");

/// The parts, by the names that select them.
const PARTS: &[&str] = &["rpc", "frame_cost", "frames", "slow_subscriber", "viewers"];

fn main() -> Result<()> {
    // The parts named on the command line (cargo adds `--bench`), or all.
    let named: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    if let Some(unknown) = named.iter().find(|n| !PARTS.contains(&n.as_str())) {
        anyhow::bail!("no part {unknown:?} in this bench: name one of {PARTS:?}");
    }
    let runs = |part: &str| named.is_empty() || named.iter().any(|n| n == part);
    // The server on its own runtime, as in its own process; the load
    // generator on another.
    let server_runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("server")
        .enable_all()
        .build()?;
    let server = server_runtime.block_on(meshless_server::start(ServerConfig::ephemeral()))?;
    let url = format!("http://{}", server.grpc_addr);
    let zenoh = server.zenoh_locators.clone();
    let load_runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("load")
        .enable_all()
        .build()?;
    load_runtime.block_on(async {
        if runs("rpc") {
            rpc_table(&url).await?;
        }
        if runs("frame_cost") {
            frame_cost_table()?;
        }
        if runs("frames") {
            frames_table().await?;
        }
        if runs("slow_subscriber") {
            slow_subscriber_table(&url, &zenoh).await?;
        }
        anyhow::Ok(())
    })?;
    server_runtime.block_on(server.stop())?;
    // A server of its own, with the viewer's listener; off the load
    // runtime, since its viewers are threads that block.
    if runs("viewers") {
        viewers_table()?;
    }
    Ok(())
}

/// Prints one row of the RPC table.
fn rpc_row(call: &str, load: &str, latencies: &rpc::Latencies) {
    println!(
        "| {call} | {load} | {:.0} | {:.3} | {:.3} | {:.3} | {} |",
        latencies.rate(),
        latencies.quantile_ms(0.5),
        latencies.quantile_ms(0.99),
        latencies.quantile_ms(1.0),
        latencies.errors
    );
}

async fn rpc_table(url: &str) -> Result<()> {
    let calls = smoke::pick(5_000, 20);
    let workers = smoke::pick(8, 2);
    let rate = smoke::pick(5_000, 100);
    let window = smoke::pick(Duration::from_secs(5), Duration::from_millis(200));
    let client = Client::connect(url).await?;
    let session = client.create_session_toml(SMALL_TANK).await?;
    println!("\nRPCs over gRPC on loopback (ms; rate in calls/s)\n");
    println!("| call | load | rate | p50 | p99 | max | errors |");
    println!("|---|---|---|---|---|---|---|");

    let get = |client: Client, id: String| {
        move || {
            let (client, id) = (client.clone(), id.clone());
            async move { client.get_session(&id).await.map(drop) }
        }
    };
    let sequential = rpc::sequential(calls, get(client.clone(), session.id.clone())).await;
    rpc_row("GetSession", "sequential", &sequential);
    let mut callers = Vec::new();
    for _ in 0..workers {
        let own = Client::connect(url).await?;
        callers.push(get(own, session.id.clone()));
    }
    let concurrent = rpc::closed_loop(callers, calls / workers as u64).await;
    rpc_row(
        "GetSession",
        &format!("{workers} callers, own connections"),
        &concurrent,
    );
    let paced = rpc::open_loop(rate, window, get(client.clone(), session.id.clone())).await;
    rpc_row("GetSession", &format!("{rate}/s, one connection"), &paced);

    let step = |client: Client, id: String| {
        move || {
            let (client, id) = (client.clone(), id.clone());
            async move { client.step(&id, 1).await.map(drop) }
        }
    };
    let step_calls = calls / 5;
    let sequential = rpc::sequential(step_calls, step(client.clone(), session.id.clone())).await;
    rpc_row("Step(1)", "sequential", &sequential);
    let mut callers = Vec::new();
    let mut sessions = Vec::new();
    for _ in 0..workers {
        let own = Client::connect(url).await?;
        let mine = own.create_session_toml(SMALL_TANK).await?;
        callers.push(step(own, mine.id.clone()));
        sessions.push(mine.id);
    }
    let concurrent = rpc::closed_loop(callers, step_calls / workers as u64).await;
    rpc_row(
        "Step(1)",
        &format!("{workers} callers, a session each"),
        &concurrent,
    );
    for id in sessions.iter().chain([&session.id]) {
        client.delete_session(id).await?;
    }
    Ok(())
}

async fn frames_table() -> Result<()> {
    let counts = smoke::pick::<&[usize]>(&[10_000, 100_000, 1_000_000], &[1_000]);
    let window = smoke::pick(Duration::from_secs(5), Duration::from_millis(200));
    println!("\nFrames over zenoh on loopback (positions and velocities, f32)\n");
    println!("| particles | frame MB | puts/s | delivered/s | delivered MB/s |");
    println!("|---|---|---|---|---|");
    for &particles in counts {
        let delivery = frames::deliver(particles, window, Payload::Shared)
            .await
            .with_context(|| format!("{particles}-particle frames"))?;
        println!(
            "| {particles} | {:.2} | {:.0} | {:.1} | {:.0} |",
            delivery.frame_bytes as f64 / 1e6,
            delivery.published as f64 / window.as_secs_f64(),
            delivery.frames_per_s(),
            delivery.mb_per_s()
        );
    }
    println!("\nSealing's cost: frames encoded for every put, plain and sealed (AES-256-GCM)\n");
    println!("| particles | plain delivered/s | sealed delivered/s | sealed / plain |");
    println!("|---|---|---|---|");
    for &particles in counts {
        let plain = frames::deliver(particles, window, Payload::Encoded).await?;
        let sealed = frames::deliver(particles, window, Payload::Sealed).await?;
        println!(
            "| {particles} | {:.1} | {:.1} | {:.3} |",
            plain.frames_per_s(),
            sealed.frames_per_s(),
            sealed.frames_per_s() / plain.frames_per_s().max(f64::MIN_POSITIVE)
        );
    }
    Ok(())
}

/// The server's CPU per frame and reader, before and after frames were
/// encoded once, in this run (ms, medians).
fn frame_cost_table() -> Result<()> {
    let counts = smoke::pick::<&[usize]>(&[100_000, 1_000_000], &[1_000]);
    let reps = smoke::pick(15, 3);
    println!(
        "\nThe server's frame path per frame (ms, median of {reps}): before, each reader \
         converts and encodes; now the compute thread encodes once and readers copy, seal or \
         decode\n"
    );
    println!(
        "| particles | frame MB | before: put | now: encode once | now: put | before: sealed put \
         | now: sealed put | before: GetLatestFrame | now: GetLatestFrame | runtime frames/s \
         before | now |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for &particles in counts {
        let c = frame_cost::measure(particles, reps)?;
        println!(
            "| {particles} | {:.1} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.0} \
             | {:.0} |",
            c.frame_bytes as f64 / 1e6,
            c.before_put,
            c.encode_once,
            c.after_put,
            c.before_sealed,
            c.after_sealed,
            c.before_get,
            c.after_get,
            1e3 / c.before_put.max(f64::MIN_POSITIVE),
            1e3 / c.after_put.max(f64::MIN_POSITIVE),
        );
    }
    Ok(())
}

async fn slow_subscriber_table(url: &str, zenoh: &[String]) -> Result<()> {
    // The small tank steps about a thousand times a second, a frame each
    // (3.5 kB): thousands of frames fill the slow reader's zenoh queue
    // (256 samples) and the socket buffers behind it within an arm, so
    // the server's publisher meets the backpressure and must drop.
    let steps = smoke::pick(5_000, 2);
    let rounds = smoke::pick(4, 1);
    let pause = Duration::from_millis(100);
    let client = Client::connect(url).await?;
    let measured =
        slow_subscriber::measure(&client, zenoh, SMALL_TANK, steps, rounds, pause).await?;
    println!(
        "\nA subscriber that takes {} ms over each frame ({} frames read)\n",
        pause.as_millis(),
        measured.frames_read
    );
    println!("| steps/s alone | steps/s watched | ratio |");
    println!("|---|---|---|");
    println!(
        "| {:.1} | {:.1} | {:.3} |",
        measured.alone,
        measured.watched,
        measured.ratio()
    );
    Ok(())
}

/// 20 browser viewers on one session of 100,000 particles (5,000 in smoke
/// mode), in alternating arms that each time the same steps of the session,
/// with the viewer's thread at the simulations' priority and at the default.
fn viewers_table() -> Result<()> {
    let name = |priority: ViewerPriority| match priority {
        ViewerPriority::Idle => "idle",
        ViewerPriority::Normal => "normal",
    };
    let (side, height) = smoke::pick((50, 40), (25, 8));
    let viewers = smoke::pick(20, 2);
    let rounds = smoke::pick(3, 2);
    let steps = smoke::pick(60, 3);
    let scene = viewers::resting_block(side, height);
    let mb = |bytes: u64| bytes as f64 / 1e6;
    // The viewer's thread at the simulations' priority, then on idle
    // CPU time (the default): the trade in one run.
    let mut summary = Vec::new();
    for priority in [ViewerPriority::Normal, ViewerPriority::Idle] {
        let measured = viewers::measure(&scene, viewers, rounds, steps, priority)?;
        println!(
            "\n{viewers} browser viewers polling NextFrame (gRPC-web over HTTP/1.1, wait {} ms, \
             one poll in flight each, on idle CPU time) on one session of {} particles at rest, a \
             frame every step ({:.2} MB), the server's viewer thread at --http-priority {}; \
             each arm resets the session and times steps {} to {}, arms alternating\n",
            viewers::WAIT_MS,
            measured.particles,
            mb(measured.frame_bytes),
            name(priority),
            viewers::SETTLE_STEPS,
            viewers::SETTLE_STEPS + steps
        );
        println!("| arm | viewers | steps/s | frames/s per viewer | failed polls | peak RSS MB |");
        println!("|---|---|---|---|---|---|");
        for (k, arm) in measured.arms.iter().enumerate() {
            println!(
                "| {} | {} | {:.2} | {:.2} | {} | {:.0} |",
                k + 1,
                arm.viewers,
                arm.steps_per_s(),
                arm.frames_per_viewer_s(),
                arm.errors,
                mb(arm.peak_rss)
            );
        }
        summary.push((priority, measured));
    }
    println!();
    println!(
        "| --http-priority | steps/s alone | steps/s with {viewers} viewers | ratio | frames/s per \
         viewer | RSS before MB | peak MB | after MB |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (priority, measured) in &summary {
        println!(
            "| {} | {:.2} | {:.2} | {:.3} | {:.2} | {:.0} | {:.0} | {:.0} |",
            name(*priority),
            measured.alone(),
            measured.watched(),
            measured.ratio(),
            measured.frames_per_viewer_s(),
            mb(measured.rss_before),
            mb(measured.rss_peak),
            mb(measured.rss_after)
        );
    }
    Ok(())
}
