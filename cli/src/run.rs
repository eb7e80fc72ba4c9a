//! `meshless run SCENE`: the engine in this process, no server.

use crate::output::{Format, FrameFiles, SurfaceFormat};
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use meshless_engine::{BuildOptions, FieldKind, Scene, World};
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
    let start = Instant::now();
    // The writer is joined whatever the steps did, so the frames before a
    // fault (the initial one at least) are on disk when the error is told.
    let stepped = run_steps(&mut world, steps, &files);
    if stepped.is_err() || !world.is_frame_step() {
        files.write(world.frame());
    }
    let written = files.finish();
    let totals = stepped?;
    let written = written?;
    let wall = start.elapsed().as_secs_f64();
    summarise(&args, &world, steps, &totals, wall)?;
    written.print()?;
    Ok(())
}

/// What the steps of a run did, summed.
#[derive(Debug, Default)]
struct Totals {
    substeps: u64,
    /// DFSPH pressure-solve iterations.
    pressure_iterations: u64,
    worst_density_error: f64,
    /// Implicit solids' Newton and CG iterations.
    solid_iterations: u64,
    worst_residual: f64,
    /// Steps whose sub-steps `time.max_substeps` capped.
    capped: u64,
    /// Solves that stopped at their cap above tolerance.
    unconverged: u64,
}

/// Steps `world` `steps` times, queueing frames to `files`, with a
/// progress bar.
fn run_steps(world: &mut World, steps: u64, files: &FrameFiles) -> Result<Totals> {
    let bar = ProgressBar::new(steps).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} steps  {msg}  [{elapsed} < {eta}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut totals = Totals::default();
    for _ in 0..steps {
        let info = match world.step() {
            Ok(info) => info,
            Err(e) => {
                bar.abandon();
                return Err(e.into());
            }
        };
        totals.substeps += u64::from(info.substeps);
        totals.solid_iterations += u64::from(info.solid_iterations);
        totals.pressure_iterations +=
            u64::from(info.solver_iterations.saturating_sub(info.solid_iterations));
        totals.worst_density_error = totals.worst_density_error.max(info.density_error);
        totals.worst_residual = totals.worst_residual.max(info.solid_residual);
        totals.capped += u64::from(info.capped);
        totals.unconverged += u64::from(info.unconverged);
        if world.is_frame_step() {
            files.write(world.frame());
        }
        bar.set_message(format!("t = {:.3} s", world.clock().time));
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(totals)
}

/// The world's kinetic and stored elastic energy (the `kinetic_energy` and
/// `elastic_energy` frame fields, summed).
fn energies(world: &World) -> (f64, f64) {
    let sum = |kind| {
        world
            .field_values(kind)
            .iter()
            .map(|&e| f64::from(e))
            .sum::<f64>()
    };
    (sum(FieldKind::KineticEnergy), sum(FieldKind::ElasticEnergy))
}

/// The run's summary on standard output, with a warning for every step
/// that was not as accurate as the scene asked.
fn summarise(args: &RunArgs, world: &World, steps: u64, totals: &Totals, wall: f64) -> Result<()> {
    let particles = world.particle_count() as f64;
    let substeps = totals.substeps;
    outln!("meshless run: {}", args.scene.display())?;
    let solids: Vec<u64> = world
        .solid_ranges()
        .iter()
        .map(|r| r.count as u64)
        .collect();
    outln!(
        "  particles         {}",
        crate::summary::particle_summary(world.particle_count() as u64, &solids)
    )?;
    outln!(
        "  simulated         {:.3} s in {steps} steps ({substeps} sub-steps)",
        world.clock().time
    )?;
    outln!(
        "  wall time         {wall:.2} s  ({:.1} steps/s, {:.3e} particle-sub-steps/s)",
        steps as f64 / wall,
        particles * substeps as f64 / wall
    )?;
    let (kinetic, elastic) = energies(world);
    let depth = if world.scene().dimension == 2 {
        " per metre of depth"
    } else {
        ""
    };
    outln!(
        "  energy            kinetic {kinetic:.4e} J, elastic {elastic:.4e} J{depth}, at the end"
    )?;
    if totals.pressure_iterations > 0 {
        outln!(
            "  pressure solver   {:.1} iterations per sub-step, worst average density error {:.3} %",
            totals.pressure_iterations as f64 / substeps as f64,
            100.0 * totals.worst_density_error
        )?;
    }
    if totals.solid_iterations > 0 {
        outln!(
            "  implicit solids   {:.1} Newton and CG iterations per step, worst Newton residual {:.1e}",
            totals.solid_iterations as f64 / steps as f64,
            totals.worst_residual
        )?;
    }
    if totals.capped > 0 {
        outln!(
            "  WARNING           {} of {steps} steps hit time.max_substeps: their sub-steps exceeded \
             the stability limit and the state may be wrong; lower time.dt or raise \
             time.max_substeps",
            totals.capped
        )?;
    }
    if totals.unconverged > 0 {
        outln!(
            "  WARNING           {} solves stopped at their iteration cap above tolerance; raise \
             the cap (max_solver_iterations, implicit.max_newton_iterations) or choose a solver \
             that converges",
            totals.unconverged
        )?;
    }
    let total: f64 = world.stages().iter().map(|(_, s)| s.seconds).sum();
    for (stage, stats) in world.stages().iter().filter(|(_, s)| s.runs > 0) {
        outln!(
            "    {:<20} {:5.1} %  ({} runs)",
            stage.name(),
            100.0 * stats.seconds / total.max(1e-12),
            stats.runs
        )?;
    }
    Ok(())
}
