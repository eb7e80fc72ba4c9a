//! The peer benchmark of issue 3: one dam break (same spacing, support
//! radius, fixed time step and density tolerance) in meshless, salva3d and
//! SPlisHSPlasH, at about 15k and 150k particles, on one thread and on all
//! cores, in one run. Prints a markdown table, the ratios and meshless's
//! stage split; writes the rows as CSV.
//!
//!     scripts/bench-peers            # sets up SPlisHSPlasH, builds, runs
//!
//! Options: `--python PATH` and `--box-obj PATH` (SPlisHSPlasH; without
//! them it is skipped), `--volume-maps` (also SPlisHSPlasH with volume-map
//! boundaries), `--spacings 0.05,0.0237`, `--warmup 12`, `--steps 12`,
//! `--threads 1,N`, `--csv target/bench-peers.csv`,
//! `--engines meshless,salva3d,splishsplash`. With `MESHLESS_BENCH_SMOKE=1`
//! (`engine/benches/common/smoke.rs`) the defaults shrink to one column of
//! 250 particles, one warm-up and one timed step, on one thread.

mod meshless;
mod report;
mod salva;
mod setup;
mod splishsplash;

// The smoke-mode switch all benchmarks share (engine/benches/common/).
#[path = "../../../engine/benches/common/smoke.rs"]
mod smoke;

use setup::{DamBreak, Run};
use std::path::PathBuf;

struct Options {
    python: Option<PathBuf>,
    box_obj: Option<PathBuf>,
    volume_maps: bool,
    spacings: Vec<f64>,
    warmup: usize,
    steps: usize,
    threads: Vec<usize>,
    csv: PathBuf,
    /// Which of `meshless`, `salva3d`, `splishsplash` run.
    engines: Vec<String>,
}

fn parse() -> Result<Options, String> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    // Smoke mode (MESHLESS_BENCH_SMOKE=1): a 250-particle column, one
    // warm-up and one timed step, one thread; flags still override.
    let mut o = Options {
        python: None,
        box_obj: None,
        volume_maps: false,
        spacings: smoke::pick(vec![0.05, 0.0237], vec![0.2]),
        warmup: smoke::pick(12, 1),
        steps: smoke::pick(12, 1),
        threads: smoke::pick(if cores > 1 { vec![1, cores] } else { vec![1] }, vec![1]),
        csv: PathBuf::from("target/bench-peers.csv"),
        engines: ["meshless", "salva3d", "splishsplash"]
            .map(String::from)
            .to_vec(),
    };
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        let mut value = || args.next().ok_or(format!("{flag} needs a value"));
        let list = |v: String| -> Result<Vec<f64>, String> {
            v.split(',')
                .map(|x| {
                    x.trim()
                        .parse::<f64>()
                        .map_err(|e| format!("{flag} {x}: {e}"))
                })
                .collect()
        };
        match flag.as_str() {
            "--python" => o.python = Some(value()?.into()),
            "--box-obj" => o.box_obj = Some(value()?.into()),
            "--volume-maps" => o.volume_maps = true,
            "--spacings" => o.spacings = list(value()?)?,
            "--warmup" => o.warmup = value()?.parse().map_err(|e| format!("{flag}: {e}"))?,
            "--steps" => o.steps = value()?.parse().map_err(|e| format!("{flag}: {e}"))?,
            "--threads" => o.threads = list(value()?)?.into_iter().map(|t| t as usize).collect(),
            "--csv" => o.csv = value()?.into(),
            "--engines" => o.engines = value()?.split(',').map(|e| e.trim().into()).collect(),
            other => return Err(format!("unknown option {other} (see src/main.rs)")),
        }
    }
    Ok(o)
}

fn main() {
    let options = match parse() {
        Ok(o) => o,
        Err(e) => {
            eprintln!("bench-peers: {e}");
            std::process::exit(2);
        }
    };
    let mut runs: Vec<Run> = Vec::new();
    let mut notes: Vec<String> = Vec::new();
    for &spacing in &options.spacings {
        let d = DamBreak {
            spacing,
            dt: 1.0 / 240.0,
            tolerance: 0.001,
            divergence_tolerance: 0.001,
            max_iterations: 100,
            rest_density: 1000.0,
            domain: ([0.0; 3], [4.0, 3.0, 1.0]),
            column: ([0.0; 3], [1.0, 2.0, 1.0]),
            warmup: options.warmup,
            steps: options.steps,
        };
        for &threads in &options.threads {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a thread pool");
            let wanted = |engine: &str| options.engines.iter().any(|e| e == engine);
            if wanted("meshless") {
                let (run, capped) = pool.install(|| meshless::run(&d, threads));
                if capped > 0 {
                    notes.push(format!(
                        "meshless, spacing {spacing}, {threads} thread(s): {capped} of {} steps \
                         exceeded its CFL limit (held at dt anyway)",
                        d.steps
                    ));
                }
                report::progress(&run);
                runs.push(run);
            }
            if wanted("salva3d") {
                let run = pool.install(|| salva::run(&d, threads));
                report::progress(&run);
                runs.push(run);
            }
            if !wanted("splishsplash") {
                continue;
            }
            if let (Some(python), Some(box_obj)) = (&options.python, &options.box_obj) {
                let mut boundaries = vec![splishsplash::Boundary::Particles];
                if options.volume_maps {
                    boundaries.push(splishsplash::Boundary::VolumeMaps);
                }
                for boundary in boundaries {
                    match splishsplash::run(&d, threads, python, box_obj, boundary) {
                        Ok(run) => {
                            report::progress(&run);
                            runs.push(run);
                        }
                        Err(e) => notes.push(format!("{}: {e}", boundary.engine())),
                    }
                }
            }
        }
    }
    let sph_wanted = options.engines.iter().any(|e| e == "splishsplash");
    if sph_wanted && (options.python.is_none() || options.box_obj.is_none()) {
        notes.push(
            "SPlisHSPlasH skipped: no --python and --box-obj (scripts/bench-peers sets them)"
                .into(),
        );
    }
    report::print(&runs, &notes, options.warmup);
    if let Err(e) = report::write_csv(&runs, &options.csv) {
        eprintln!("bench-peers: cannot write {}: {e}", options.csv.display());
    } else {
        println!("\nrows written to {}", options.csv.display());
    }
}
