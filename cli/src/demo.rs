//! `meshless demo`: the whole service in one process. An embedded server
//! (gRPC on a free loopback port, zenoh peer on another) runs the dam
//! break; this command drives it as any remote client would: gRPC for
//! control and status, zenoh for frames. The server's browser viewer
//! shows the run live at the address the demo prints first.

use crate::output::{Format, FrameFiles, SurfaceFormat};
use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use meshless_client::{Client, ZenohLink, v1};
use meshless_server::ServerConfig;
use meshless_wire::frame::frame_from_proto;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use tokio_stream::StreamExt;

/// The scene the demo runs unless told otherwise.
const DAM_BREAK: &str = include_str!("../../scenes/dam_break.toml");

/// Longest wait for any sign of progress before giving up.
const STALL: Duration = Duration::from_secs(60);

#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Scene file to run instead of the built-in dam break.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Simulated time to run, in seconds.
    #[arg(long, default_value_t = 1.0)]
    until: f64,
    /// Folder for the frame files.
    #[arg(long, short, default_value = "out/demo")]
    output: PathBuf,
    #[arg(long, value_enum, default_value = "vtk")]
    format: Format,
    /// Format of the surface files, when the scene asks for a fluid surface
    /// or a solid embeds one.
    #[arg(long, value_enum, default_value = "obj")]
    surface_format: SurfaceFormat,
    /// Address of the browser viewer, which shows the run live; port 0
    /// picks a free one.
    #[arg(long, default_value = "127.0.0.1:0")]
    http_addr: std::net::SocketAddr,
    /// Once the run is done, keep the server and its viewer up (to reset,
    /// run and grab the session from the page) until Ctrl-C.
    #[arg(long)]
    serve: bool,
}

pub async fn demo(args: DemoArgs) -> Result<()> {
    let scene = match &args.scene {
        Some(path) => meshless_client::read_scene_file(path)?,
        None => DAM_BREAK.to_owned(),
    };
    let server = meshless_server::start(ServerConfig {
        http_addr: Some(args.http_addr),
        ..ServerConfig::ephemeral()
    })
    .await?;
    let mut result = drive(&args, &scene, &server).await;
    if result.is_ok() && args.serve {
        outln!("serving until Ctrl-C")?;
        result = tokio::signal::ctrl_c().await.context("waiting for Ctrl-C");
    }
    server.stop().await?;
    result
}

async fn drive(
    args: &DemoArgs,
    scene: &str,
    server: &meshless_server::RunningServer,
) -> Result<()> {
    let url = format!("http://{}", server.grpc_addr);
    let client = Client::connect(&url).await?;
    let info = client.server_info().await?;
    let session = client.create_session_toml(scene).await?;
    let id = session.id.clone();
    if let Some(http) = server.http_addr {
        outln!("watch it live: http://{http}/?session={id}")?;
    }
    outln!(
        "embedded server at {url} (zenoh {}); session {id}: {}, {} particles",
        info.zenoh_locators.join(","),
        session.name,
        session.particle_count
    )?;

    let link = ZenohLink::connect(&info.zenoh_locators).await?;
    let frames = link.frames(&session).await?;
    let files = FrameFiles::start(&args.output, args.format, args.surface_format)?;
    let mut received = 0usize;
    let mut last_step = 0;
    // Each solid's particle count, which the frames carry.
    let mut solids = Vec::new();
    if let Some(first) = link.latest_message(&id).await? {
        let first = frame_from_proto(first)?;
        last_step = first.step;
        solids = first.solids.iter().map(|r| r.count as u64).collect();
        files.write(first);
        received += 1;
    }
    let mut statuses = client.watch_status(&id).await?;

    let bar = ProgressBar::new((args.until * 1000.0).round() as u64).with_style(
        ProgressStyle::with_template("{bar:40} {msg}  [{elapsed} < {eta}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let start = Instant::now();
    client.run_until(&id, args.until, None).await?;
    let mut final_step = None;
    loop {
        if final_step.is_some_and(|s| last_step >= s) {
            break;
        }
        tokio::select! {
            frame = frames.recv_message() => {
                let frame = frame_from_proto(frame?)?;
                last_step = frame.step;
                bar.set_position((frame.time * 1000.0).round() as u64);
                bar.set_message(format!("t = {:.3} s, step {}", frame.time, frame.step));
                files.write(frame);
                received += 1;
            }
            status = statuses.next() => {
                let status = status.context("status stream ended")??;
                match v1::SessionState::try_from(status.state) {
                    Ok(v1::SessionState::Finished) => final_step = Some(status.step),
                    Ok(v1::SessionState::Faulted) => bail!("the session faulted: {}", status.reason),
                    Ok(v1::SessionState::Closed) => bail!("the session was deleted"),
                    _ => {}
                }
            }
            () = tokio::time::sleep(STALL) => bail!("no frame or status for {} s", STALL.as_secs()),
        }
    }
    let wall = start.elapsed().as_secs_f64();
    bar.finish_and_clear();
    let written = files.finish()?;
    let end = client.get_session(&id).await?;
    let status = end.status.unwrap_or_default();
    let frame_every = end
        .scene
        .and_then(|s| s.output)
        .and_then(|o| o.frame_every)
        .unwrap_or(1);
    let published = status.step / u64::from(frame_every) + 1;
    link.close().await;

    outln!("meshless demo: {}", session.name)?;
    outln!(
        "  particles         {}",
        crate::summary::particle_summary(session.particle_count, &solids)
    )?;
    outln!(
        "  simulated         {:.3} s in {} steps",
        status.time,
        status.step
    )?;
    outln!(
        "  wall time         {wall:.2} s  ({:.1} steps/s, {:.3e} particle-steps/s)",
        status.step as f64 / wall,
        session.particle_count as f64 * status.step as f64 / wall
    )?;
    outln!(
        "  frames received   {received} of {published} over zenoh (key {}/frames)",
        session.zenoh_key_prefix
    )?;
    written.print()?;
    Ok(())
}
