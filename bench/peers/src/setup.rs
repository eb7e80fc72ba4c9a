//! The one dam break every engine runs, and what a run measured.

/// A water column in a closed box, stepped with DFSPH at a fixed time step
/// (PERFORMANCE.md's benchmark: a 1 x 2 x 1 m column in a 4 x 3 x 1 m box,
/// steps of 1/240 s).
#[derive(Debug, Clone, Copy)]
pub struct DamBreak {
    /// Lattice spacing of the fluid, m; particle radius is half of it and
    /// the kernel support radius twice it in all three engines.
    pub spacing: f64,
    /// Fixed time step, s (no CFL sub-stepping).
    pub dt: f64,
    /// Largest average predicted density error, fraction of rho_0.
    pub tolerance: f64,
    /// Largest average density change per step of the divergence solve,
    /// fraction of rho_0.
    pub divergence_tolerance: f64,
    pub max_iterations: u32,
    pub rest_density: f64,
    pub domain: ([f64; 3], [f64; 3]),
    pub column: ([f64; 3], [f64; 3]),
    /// Steps run before timing starts (the column starts to fall).
    pub warmup: usize,
    /// Timed steps.
    pub steps: usize,
}

impl DamBreak {
    pub fn support_radius(&self) -> f64 {
        2.0 * self.spacing
    }

    /// The fluid lattice, as meshless builds it (`FluidSpec::lattice`):
    /// centres at `min + (i + 1/2) spacing` along each axis.
    pub fn lattice(&self) -> Vec<[f64; 3]> {
        let (min, max) = self.column;
        let n = [0, 1, 2].map(|a| ((max[a] - min[a]) / self.spacing + 1e-9).floor() as usize);
        let s = self.spacing;
        let mut points = Vec::with_capacity(n[0] * n[1] * n[2]);
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    points.push([
                        min[0] + (i as f64 + 0.5) * s,
                        min[1] + (j as f64 + 0.5) * s,
                        min[2] + (k as f64 + 0.5) * s,
                    ]);
                }
            }
        }
        points
    }
}

/// What one engine did over the timed steps.
#[derive(Debug, Clone)]
pub struct Run {
    pub engine: &'static str,
    pub particles: usize,
    pub threads: usize,
    pub steps: usize,
    /// Wall-clock seconds of the timed steps only.
    pub seconds: f64,
    /// CPU seconds of all the engine's threads over the same steps.
    pub cpu_seconds: f64,
    /// Ordered fluid-fluid neighbour pairs within the support radius, self
    /// pairs excluded, summed over the timed steps.
    pub fluid_pairs: f64,
    /// Pressure (constant-density) solver iterations over the timed steps,
    /// where the engine reports them.
    pub pressure_iterations: Option<u64>,
    /// Divergence solver iterations over the timed steps.
    pub divergence_iterations: Option<u64>,
    /// Mean over the timed steps of the solver's own final average
    /// predicted density error, where the engine reports it.
    pub solver_error: Option<f64>,
    /// Mean over the timed steps of `mean_i max(rho_i / rho_0 - 1, 0)`
    /// from each engine's own density sum (its kernel, mass and boundary)
    /// at the positions a step ended on.
    pub density_error: f64,
    /// Mean over the timed steps of `mean_i rho_i / rho_0`, from the same
    /// density sums: below 1 where the fluid has expanded (a spray), so it
    /// tells whether the engines compare on the same flow.
    pub mean_density: f64,
    /// Seconds per stage, where the engine times them.
    pub stages: Vec<(&'static str, f64)>,
}

impl Run {
    pub fn rate(&self) -> f64 {
        self.particles as f64 * self.steps as f64 / self.seconds
    }

    /// Particle-steps per CPU-second: on a machine other jobs share, wall
    /// time counts their time too; CPU time counts only this run's.
    pub fn per_core(&self) -> f64 {
        self.particles as f64 * self.steps as f64 / self.cpu_seconds
    }

    /// The means of `max(rho / rho_0 - 1, 0)` (the compression the
    /// tolerance bounds) and of `rho / rho_0` over `densities`.
    pub fn density_stats(densities: impl Iterator<Item = f64>, rest: f64) -> (f64, f64) {
        let (mut compression, mut ratio, mut n) = (0.0, 0.0, 0usize);
        for rho in densities {
            compression += (rho / rest - 1.0).max(0.0);
            ratio += rho / rest;
            n += 1;
        }
        let n = n.max(1) as f64;
        (compression / n, ratio / n)
    }
}

/// CPU seconds this process's threads have run, from the scheduler's
/// per-thread nanosecond counters (`/proc/self/task/*/schedstat`, first
/// field); 0 where the file system does not provide them.
pub fn cpu_seconds() -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return 0.0;
    };
    tasks
        .flatten()
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .sum::<f64>()
        * 1e-9
}
