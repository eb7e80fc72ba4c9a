//! `cargo bench -p meshless-load`: the service under load, as three
//! tables (see the crate's documentation for what each measures). With
//! `MESHLESS_BENCH_SMOKE=1` every part runs at its smallest size, for CI.

#[path = "../../../engine/benches/common/smoke.rs"]
mod smoke;

use anyhow::{Context, Result};
use meshless_client::Client;
use meshless_load::frames::Payload;
use meshless_load::{frame_cost, frames, rpc, slow_subscriber};
use meshless_server::ServerConfig;
use std::time::Duration;

/// The scene every measurement through the server drives: 125
/// particles, a frame per step, so `Step(1)` is mostly the service's own
/// cost.
const SMALL_TANK: &str = include_str!("../../../tests/fixtures/small_tank.toml");

fn main() -> Result<()> {
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
        rpc_table(&url).await?;
        frame_cost_table()?;
        frames_table().await?;
        slow_subscriber_table(&url, &zenoh).await
    })?;
    server_runtime.block_on(server.stop())
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
