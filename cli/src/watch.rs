//! `meshless watch`: frame rate and particle counts of a session's stream,
//! and how many samples on its key were dropped (undecodable, malformed or
//! naming another session: see `meshless_client::Frames`).

use crate::server_arg::ServerArg;
use anyhow::Result;
use meshless_client::ZenohLink;
use std::time::{Duration, Instant};

#[derive(Debug, clap::Args)]
pub struct WatchArgs {
    /// The session to watch.
    session: String,
    #[command(flatten)]
    server: ServerArg,
    /// Zenoh endpoints to subscribe through (default: the server's own).
    #[arg(long, value_delimiter = ',')]
    zenoh: Vec<String>,
    /// A zenoh configuration file (JSON5) to connect with: the CA of
    /// `tls/` endpoints, a client certificate, a user and password.
    #[arg(long, env = "MESHLESS_ZENOH_CONFIG")]
    zenoh_config: Option<std::path::PathBuf>,
    /// Stop after this many frames.
    #[arg(long)]
    frames: Option<u64>,
    /// Stop after this many seconds.
    #[arg(long)]
    seconds: Option<f64>,
}

pub async fn watch(args: WatchArgs) -> Result<()> {
    // The session from the server: it checks that the caller may see it,
    // and holds the key of its sealed frames.
    let client = args.server.connect_for(&args.session).await?;
    let session = client.get_session(&args.session).await?;
    let endpoints = if args.zenoh.is_empty() {
        client.server_info().await?.zenoh_locators
    } else {
        args.zenoh
    };
    let config = match &args.zenoh_config {
        Some(path) => zenoh::Config::from_file(path)
            .map_err(|e| anyhow::anyhow!("--zenoh-config {}: {e}", path.display()))?,
        None => zenoh::Config::default(),
    };
    let link = ZenohLink::connect_with(&endpoints, config).await?;
    let frames = link.frames(&session).await?;
    outln!("watching {} through {}", args.session, endpoints.join(","))?;
    let start = Instant::now();
    let deadline = args.seconds.map(|s| start + Duration::from_secs_f64(s));
    let (mut total, mut window, mut window_start) = (0u64, 0u64, Instant::now());
    let mut ticker = tokio::time::interval(Duration::from_secs(1));
    ticker.tick().await;
    let mut last = None;
    loop {
        let stop_at = deadline.map_or_else(
            || tokio::time::Instant::now() + Duration::from_secs(86_400),
            tokio::time::Instant::from_std,
        );
        tokio::select! {
            frame = frames.recv() => {
                let frame = frame?;
                total += 1;
                window += 1;
                let solids: Vec<u64> = frame.solids.iter().map(|r| r.count).collect();
                last = Some((frame.step, frame.time, frame.particle_count, solids));
                if args.frames.is_some_and(|n| total >= n) {
                    break;
                }
            }
            _ = ticker.tick() => {
                let rate = window as f64 / window_start.elapsed().as_secs_f64();
                let dropped = frames.dropped().total();
                match &last {
                    Some((step, time, particles, solids)) => outln!(
                        "{rate:6.1} frames/s  step {step:>8}  t = {time:9.4} s  particles {}  dropped {dropped}",
                        crate::summary::particle_summary(*particles as u64, solids)
                    )?,
                    None => outln!("{rate:6.1} frames/s  (no frame yet)  dropped {dropped}")?,
                }
                window = 0;
                window_start = Instant::now();
            }
            () = tokio::time::sleep_until(stop_at) => break,
            r = tokio::signal::ctrl_c() => { r?; break; }
        }
    }
    let elapsed = start.elapsed().as_secs_f64();
    let dropped = frames.dropped();
    let last_dropped = dropped
        .last
        .as_ref()
        .map(|(reason, why)| format!(" (last {reason:?}: {why})"))
        .unwrap_or_default();
    outln!(
        "{total} frames in {elapsed:.1} s ({:.1} frames/s), {} dropped{last_dropped}",
        total as f64 / elapsed.max(1e-9),
        dropped.total()
    )?;
    link.close().await;
    Ok(())
}
