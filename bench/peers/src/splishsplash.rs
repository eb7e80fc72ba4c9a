//! The dam break in SPlisHSPlasH: `splishsplash.py` (next to this crate)
//! in a subprocess with `OMP_NUM_THREADS` set to the thread count. It
//! writes the scene from the same parameters and prints one JSON line.

use crate::setup::{DamBreak, Run};
use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// How SPlisHSPlasH's boundary is modelled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Boundary {
    /// Akinci et al. 2012 boundary particles sampled on the box.
    Particles,
    /// Bender et al. 2019 volume maps of the box.
    VolumeMaps,
}

impl Boundary {
    pub fn engine(self) -> &'static str {
        match self {
            Boundary::Particles => "SPlisHSPlasH",
            Boundary::VolumeMaps => "SPlisHSPlasH (volume maps)",
        }
    }

    fn flag(self) -> &'static str {
        match self {
            Boundary::Particles => "particles",
            Boundary::VolumeMaps => "volume-maps",
        }
    }
}

/// Runs the script with `python`; `box_obj` is the wheel's unit box mesh.
pub fn run(
    d: &DamBreak,
    threads: usize,
    python: &Path,
    box_obj: &Path,
    boundary: Boundary,
) -> Result<Run, String> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("splishsplash.py");
    let triple = |v: [f64; 3]| v.map(|x| x.to_string());
    let mut command = Command::new(python);
    command
        .arg(&script)
        .args(["--spacing", &d.spacing.to_string()])
        .args(["--dt", &d.dt.to_string()])
        .args(["--tolerance", &d.tolerance.to_string()])
        .args([
            "--divergence-tolerance",
            &d.divergence_tolerance.to_string(),
        ])
        .args(["--max-iterations", &d.max_iterations.to_string()])
        .args(["--rest-density", &d.rest_density.to_string()])
        .args(["--warmup", &d.warmup.to_string()])
        .args(["--steps", &d.steps.to_string()])
        .arg("--domain-min")
        .args(triple(d.domain.0))
        .arg("--domain-max")
        .args(triple(d.domain.1))
        .arg("--column-min")
        .args(triple(d.column.0))
        .arg("--column-max")
        .args(triple(d.column.1))
        .args(["--boundary", boundary.flag()])
        .arg("--box-obj")
        .arg(box_obj)
        .env("OMP_NUM_THREADS", threads.to_string());
    let output = command
        .output()
        .map_err(|e| format!("cannot start {}: {e}", python.display()))?;
    let stdout = String::from_utf8_lossy(&output.stdout);
    let line = stdout
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .ok_or_else(|| {
            format!(
                "splishsplash.py gave no result ({}): {}",
                output.status,
                String::from_utf8_lossy(&output.stderr)
                    .lines()
                    .rev()
                    .take(5)
                    .collect::<Vec<_>>()
                    .join(" | ")
            )
        })?;
    let v: Value = serde_json::from_str(line).map_err(|e| format!("bad JSON {line}: {e}"))?;
    let num = |key: &str| v[key].as_f64().ok_or_else(|| format!("no {key} in {line}"));
    let steps = num("steps")? as usize;
    Ok(Run {
        engine: boundary.engine(),
        particles: num("particles")? as usize,
        threads,
        steps,
        seconds: num("seconds")?,
        cpu_seconds: num("cpu_seconds")?,
        fluid_pairs: num("fluid_pairs")?,
        pressure_iterations: Some(num("pressure_iterations")? as u64),
        divergence_iterations: Some(num("divergence_iterations")? as u64),
        solver_error: None,
        density_error: num("density_error")?,
        mean_density: num("mean_density")?,
        stages: Vec::new(),
    })
}
