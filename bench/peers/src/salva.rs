//! The dam break in salva3d 0.11: its DFSPH with the cubic spline for
//! densities and gradients, the box as one layer of boundary particles
//! (Akinci et al. 2012 volumes, which salva computes itself).
//!
//! salva3d reports neither iteration counts nor its density error, and its
//! neighbour lists are private: the benchmark counts fluid-fluid pairs and
//! recomputes salva's own density sum (`compute_densities` of its DFSPH:
//! fluid masses plus boundary volumes times rho_0, its cubic spline) from
//! the positions a step ended on, outside the timing.

use crate::setup::{DamBreak, Run, cpu_seconds};
use meshless_engine::math::Vector as MVector;
use meshless_engine::neighbors::{CandidateSearch, NeighborList, UniformGrid};
use salva3d::LiquidWorld;
use salva3d::kernel::{CubicSplineKernel, Kernel};
use salva3d::math::{Real, Vector};
use salva3d::object::interaction_groups::InteractionGroups;
use salva3d::object::{Boundary, Fluid};
use salva3d::solver::{DFSPHSolver, DfsphParameters};
use std::collections::BTreeSet;
use std::time::Instant;

/// Points on the six faces of the domain box, a square lattice of about
/// `spacing` on each (spacing rounded so nodes fall on the edges).
pub fn box_surface(d: &DamBreak) -> Vec<Vector<Real>> {
    let (lo, hi) = d.domain;
    let n = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / d.spacing).round().max(1.0) as i64);
    let mut nodes = BTreeSet::new();
    for i in 0..=n[0] {
        for j in 0..=n[1] {
            for k in 0..=n[2] {
                let on_face = i == 0 || j == 0 || k == 0 || i == n[0] || j == n[1] || k == n[2];
                if on_face {
                    nodes.insert([i, j, k]);
                }
            }
        }
    }
    nodes
        .into_iter()
        .map(|c| {
            let at = |a: usize| lo[a] + (hi[a] - lo[a]) * c[a] as f64 / n[a] as f64;
            Vector::new(at(0) as Real, at(1) as Real, at(2) as Real)
        })
        .collect()
}

pub fn run(d: &DamBreak, threads: usize) -> Run {
    let parameters = DfsphParameters {
        max_pressure_iter: d.max_iterations as usize,
        // salva compares the average of rho / rho_0 - 1, a fraction.
        max_density_error: d.tolerance as Real,
        max_divergence_iter: d.max_iterations as usize,
        // salva's divergence tolerance is in percent of rho_0 per step.
        max_divergence_error: (100.0 * d.divergence_tolerance) as Real,
        // Its own minimum iteration counts (1 and 1) are kept.
        ..DfsphParameters::default()
    };
    let solver = DFSPHSolver::<CubicSplineKernel, CubicSplineKernel>::with_parameters(parameters);
    let radius = (d.spacing / 2.0) as Real;
    // Support radius = particle radius * smoothing factor * 2 = 2 spacing.
    let mut world = LiquidWorld::new(solver, radius, 2.0, 1.0);
    let positions = d
        .lattice()
        .into_iter()
        .map(|p| Vector::new(p[0] as Real, p[1] as Real, p[2] as Real))
        .collect();
    world.add_fluid(Fluid::new(
        positions,
        radius,
        d.rest_density as Real,
        InteractionGroups::default(),
    ));
    world.add_boundary(Boundary::new(box_surface(d), InteractionGroups::default()));
    let gravity = Vector::new(0.0, -9.81, 0.0);
    let dt = d.dt as Real;
    for _ in 0..d.warmup {
        world.step(dt, &gravity);
    }
    let mut density = Densities::new(d);
    let (mut seconds, mut cpu, mut pairs) = (0.0, 0.0, 0.0);
    let (mut density_error, mut mean_density) = (0.0, 0.0);
    for _ in 0..d.steps {
        let (start, start_cpu) = (Instant::now(), cpu_seconds());
        world.step(dt, &gravity);
        seconds += start.elapsed().as_secs_f64();
        cpu += cpu_seconds() - start_cpu;
        let ((error, mean), fluid_pairs) = density.measure(&world, d);
        density_error += error;
        mean_density += mean;
        pairs += fluid_pairs as f64;
    }
    Run {
        engine: "salva3d",
        particles: world.fluids().as_slice()[0].num_particles(),
        threads,
        steps: d.steps,
        seconds,
        cpu_seconds: cpu,
        fluid_pairs: pairs,
        pressure_iterations: None,
        divergence_iterations: None,
        solver_error: None,
        density_error: density_error / d.steps as f64,
        mean_density: mean_density / d.steps as f64,
        stages: Vec::new(),
    }
}

/// salva's density sum, recomputed with meshless's neighbour grid.
struct Densities {
    grid: UniformGrid,
    lists: NeighborList,
    points: Vec<MVector>,
}

impl Densities {
    fn new(d: &DamBreak) -> Self {
        let h = d.support_radius();
        let (lo, hi) = d.domain;
        let pad = MVector::repeat(h);
        let grid = UniformGrid::new(MVector::from(lo) - pad, MVector::from(hi) + pad, h)
            .expect("the benchmark box fits a grid");
        Self {
            grid,
            lists: NeighborList::default(),
            points: Vec::new(),
        }
    }

    /// Mean compression of the fluid and its fluid-fluid pairs.
    /// The density statistics of [`Run::density_stats`] and the fluid pairs.
    fn measure(&mut self, world: &LiquidWorld, d: &DamBreak) -> ((f64, f64), usize) {
        let fluid = &world.fluids().as_slice()[0];
        let boundary = &world.boundaries().as_slice()[0];
        let nf = fluid.num_particles();
        let to_f64 = |p: &Vector<Real>| MVector::new(p.x.into(), p.y.into(), p.z.into());
        self.points.clear();
        self.points.extend(fluid.positions.iter().map(to_f64));
        self.points.extend(boundary.positions.iter().map(to_f64));
        self.grid.rebuild(&self.points);
        let h = d.support_radius();
        self.lists.build(&self.grid, &self.points, h);
        let rho0 = fluid.density0;
        let mut pairs = 0;
        let densities = (0..nf).map(|i| {
            let mut rho: Real = 0.0;
            for &j in self.lists.of(i) {
                let j = j as usize;
                let r = (self.points[i] - self.points[j]).norm() as Real;
                let w = CubicSplineKernel::scalar_apply(r, h as Real);
                if j < nf {
                    rho += fluid.particle_mass(j) * w;
                    pairs += usize::from(j != i);
                } else {
                    rho += boundary.volumes[j - nf] * rho0 * w;
                }
            }
            f64::from(rho)
        });
        let stats = Run::density_stats(densities, d.rest_density);
        (stats, pairs)
    }
}
