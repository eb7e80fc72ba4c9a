//! The table, the ratios and the CSV.

use crate::setup::Run;
use std::fmt::Write as _;
use std::path::Path;

/// One line on stderr per finished run, so a long benchmark shows progress.
pub fn progress(run: &Run) {
    eprintln!(
        "  {:<28} {:>7} particles, {} thread(s): {:.2} s ({:.2} CPU-s) for {} steps",
        run.engine, run.particles, run.threads, run.seconds, run.cpu_seconds, run.steps
    );
}

fn per_step(total: Option<u64>, steps: usize) -> String {
    total.map_or("n/a".into(), |t| format!("{:.2}", t as f64 / steps as f64))
}

fn percent(x: Option<f64>) -> String {
    x.map_or("n/a".into(), |x| format!("{:.3} %", 100.0 * x))
}

/// Meshless's run at the same size and thread count as `peer`.
fn meshless_beside<'a>(runs: &'a [Run], peer: &Run) -> Option<&'a Run> {
    runs.iter().find(|r| {
        r.engine == "meshless"
            && r.threads == peer.threads
            && r.particles.abs_diff(peer.particles) * 5 < peer.particles
    })
}

pub fn print(runs: &[Run], notes: &[String], warmup: usize) {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "\n| engine | particles | threads | steps | particle-steps/s (wall) | per core (per CPU-s) | fluid pairs per CPU-s | pressure it./step | divergence it./step | solver density error | measured density error | mean density / rest | meshless per core ÷ this |"
    );
    let _ = writeln!(out, "|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in runs {
        let ratio = meshless_beside(runs, r)
            .filter(|m| m.engine != r.engine)
            .map_or("".into(), |m| format!("{:.2}", m.per_core() / r.per_core()));
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {:.3e} | {:.3e} | {:.3e} | {} | {} | {} | {:.3} % | {:.3} | {} |",
            r.engine,
            r.particles,
            r.threads,
            r.steps,
            r.rate(),
            r.per_core(),
            r.fluid_pairs / r.cpu_seconds,
            per_step(r.pressure_iterations, r.steps),
            per_step(r.divergence_iterations, r.steps),
            percent(r.solver_error),
            100.0 * r.density_error,
            r.mean_density,
            ratio
        );
    }
    let _ = writeln!(
        out,
        "\nTimed: {} steps of 1/240 s after {warmup} warm-up steps, the steps only; per core = particle-steps per CPU-second of the engine's threads.",
        runs.first().map_or(0, |r| r.steps)
    );
    // Linearity: cost per particle-step at the largest size over the smallest.
    let engines: Vec<&str> = runs.iter().fold(Vec::new(), |mut v, r| {
        if !v.contains(&r.engine) {
            v.push(r.engine);
        }
        v
    });
    for engine in engines {
        let mut threads: Vec<usize> = runs.iter().map(|r| r.threads).collect();
        threads.dedup();
        threads.sort_unstable();
        threads.dedup();
        for t in threads {
            let sized: Vec<&Run> = runs
                .iter()
                .filter(|r| r.engine == engine && r.threads == t)
                .collect();
            let small = sized.iter().min_by_key(|r| r.particles);
            let large = sized.iter().max_by_key(|r| r.particles);
            if let (Some(s), Some(l)) = (small, large)
                && s.particles != l.particles
            {
                let _ = writeln!(
                    out,
                    "{engine}, {t} thread(s): cost per particle-step at {} / at {} particles = {:.2} (1.00 is linear)",
                    l.particles,
                    s.particles,
                    s.per_core() / l.per_core()
                );
            }
        }
    }
    for r in runs.iter().filter(|r| !r.stages.is_empty()) {
        let total: f64 = r.stages.iter().map(|(_, s)| s).sum();
        let split: Vec<String> = r
            .stages
            .iter()
            .map(|(name, s)| format!("{name} {:.0} %", 100.0 * s / total))
            .collect();
        let _ = writeln!(
            out,
            "{} stages, {} particles, {} thread(s): {}",
            r.engine,
            r.particles,
            r.threads,
            split.join(", ")
        );
    }
    for note in notes {
        let _ = writeln!(out, "note: {note}");
    }
    print!("{out}");
}

pub fn write_csv(runs: &[Run], path: &Path) -> std::io::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let mut text = String::from(
        "engine,particles,threads,steps,seconds,cpu_seconds,particle_steps_per_s,per_core,fluid_pairs_per_cpu_s,pressure_iterations_per_step,divergence_iterations_per_step,solver_density_error,measured_density_error,mean_density\n",
    );
    let opt = |x: Option<f64>| x.map_or(String::new(), |x| format!("{x:e}"));
    for r in runs {
        let steps = r.steps as f64;
        let _ = writeln!(
            text,
            "{},{},{},{},{:e},{:e},{:e},{:e},{:e},{},{},{},{:e},{:e}",
            r.engine,
            r.particles,
            r.threads,
            r.steps,
            r.seconds,
            r.cpu_seconds,
            r.rate(),
            r.per_core(),
            r.fluid_pairs / r.cpu_seconds,
            opt(r.pressure_iterations.map(|i| i as f64 / steps)),
            opt(r.divergence_iterations.map(|i| i as f64 / steps)),
            opt(r.solver_error),
            r.density_error,
            r.mean_density
        );
    }
    std::fs::write(path, text)
}
