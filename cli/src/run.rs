//! `meshless run SCENE`: the engine in this process, no server.

use crate::output::{Format, FrameFiles, SurfaceFormat};
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use meshless_engine::{BuildOptions, Scene};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// A TOML scene file, e.g. scenes/dam_break.toml.
    scene: PathBuf,
    /// Simulated time to run, in seconds.
    #[arg(long, default_value_t = 1.0)]
    until: f64,
    /// Folder for the frame files.
    #[arg(long, short, default_value = "out/run")]
    output: PathBuf,
    #[arg(long, value_enum, default_value = "vtk")]
    format: Format,
    /// Format of the surface files, written beside the frames as
    /// surface_STEP.EXT when the scene asks for a fluid surface (`[output]
    /// surface`) and as solidSYSTEM_STEP.EXT, with normals, for each solid
    /// that embeds one (a solid's surface).
    #[arg(long, value_enum, default_value = "obj")]
    surface_format: SurfaceFormat,
    /// Worker threads for the engine (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

pub fn run(args: RunArgs) -> Result<()> {
    if !(args.until.is_finite() && args.until > 0.0) {
        anyhow::bail!(
            "--until must be a positive number of seconds, got {}",
            args.until
        );
    }
    if let Some(threads) = args.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global()
            .context("--threads")?;
    }
    let scene = Scene::from_toml_file(&args.scene)?;
    let mut world = scene.build(&BuildOptions::default())?;
    let steps = (args.until / scene.time.dt - 1e-9).ceil() as u64;
    let files = FrameFiles::start(&args.output, args.format, args.surface_format)?;
    files.write(world.frame());

    let bar = ProgressBar::new(steps).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} steps  {msg}  [{elapsed} < {eta}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let start = Instant::now();
    let (mut substeps, mut iterations, mut worst_error) = (0u64, 0u64, 0.0f64);
    for _ in 0..steps {
        let info = world.step()?;
        substeps += u64::from(info.substeps);
        iterations += u64::from(info.solver_iterations);
        worst_error = worst_error.max(info.density_error);
        if world.is_frame_step() {
            files.write(world.frame());
        }
        bar.set_message(format!("t = {:.3} s", world.clock().time));
        bar.inc(1);
    }
    if !world.is_frame_step() {
        files.write(world.frame());
    }
    bar.finish_and_clear();
    let wall = start.elapsed().as_secs_f64();
    let written = files.finish()?;
    let particles = world.particle_count() as f64;
    println!("meshless run: {}", args.scene.display());
    let solids: Vec<u64> = world
        .solid_ranges()
        .iter()
        .map(|r| r.count as u64)
        .collect();
    println!(
        "  particles         {}",
        crate::command::particle_summary(world.particle_count() as u64, &solids)
    );
    println!(
        "  simulated         {:.3} s in {steps} steps ({substeps} sub-steps)",
        world.clock().time
    );
    println!(
        "  wall time         {wall:.2} s  ({:.1} steps/s, {:.3e} particle-sub-steps/s)",
        steps as f64 / wall,
        particles * substeps as f64 / wall
    );
    if iterations > 0 {
        println!(
            "  pressure solver   {:.1} iterations per sub-step, worst average density error {:.3} %",
            iterations as f64 / substeps as f64,
            100.0 * worst_error
        );
    }
    let total: f64 = world.stages().iter().map(|(_, s)| s.seconds).sum();
    for (stage, stats) in world.stages().iter().filter(|(_, s)| s.runs > 0) {
        println!(
            "    {:<20} {:5.1} %  ({} runs)",
            stage.name(),
            100.0 * stats.seconds / total.max(1e-12),
            stats.runs
        );
    }
    written.print();
    Ok(())
}
