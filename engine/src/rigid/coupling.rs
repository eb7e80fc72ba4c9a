//! Rigid bodies as fluid boundaries, after Akinci, Ihmsen, Akinci,
//! Solenthaler and Teschner, "Versatile rigid-fluid coupling for
//! incompressible SPH" (SIGGRAPH 2012), the particle form of the
//! tutorial's ghost particles (Eq. 55-57).
//!
//! Each body's surface carries one layer of samples `b`, half a spacing
//! beneath it. A sample stands
//! for the fluid volume it displaces, `V_b = 1 / sum_k W(x_b - x_k)` over
//! the samples `k` of its own body (Akinci Eq. 4): dense sampling then does
//! not overcount. With `psi_b = rho_0 V_b` (Akinci Eq. 5) the boundary
//! enters the fluid like particles of mass `psi_b`:
//!
//! - density: `rho_i += sum_b psi_b W(x_i - x_b)` (Akinci Eq. 6);
//! - pressure: `a_i -= sum_b psi_b (p_i / rho_i^2) grad W(x_i - x_b)`
//!   (Akinci Eq. 10): the boundary's share of `-(p_i / rho_i^2) grad rho_i`,
//!   with the fluid's own pressure and not doubled, for the reason
//!   [`crate::fluid::BoxWalls`] gives;
//! - no-slip (per body): the Laplacian viscosity of Morris et al. (1997) in
//!   the form of Monaghan (2005) with the body's surface velocity `v_b`,
//!   `a_i += 2 (d + 2) nu sum_b (psi_b / rho_i)
//!   ((v_i - v_b) . x_ib) / (|x_ib|^2 + 0.01 h^2) grad W(x_ib)`,
//!   `nu = mu / rho_0`. Each term acts along `x_ib`, so it exerts no torque
//!   about the pair and conserves angular momentum; free slip omits it.
//!   One layer at the body's velocity drags less than the domain walls'
//!   ghost lattice with Morris's extrapolation, and the fluid stands
//!   farther off the samples than a lattice's half spacing: each particle's
//!   terms are scaled by [`GhostDepth`]'s ratio of the friction-weighted
//!   volume its neighbourhood misses to what the samples supply, times the
//!   lattice's mean extrapolation at its distance from the surface (a
//!   no-slip container's spin-down went from 16.4 % to 9.3 % of `L_0` off
//!   the Bessel series);
//! - DFSPH: the boundary density gradient `sum_b psi_b grad W(x_i - x_b)`
//!   joins the walls' in the factor `alpha_i`, the pressure push, and the
//!   density change `sum_b psi_b (v_i - v_b) . grad W(x_i - x_b)`
//!   (Bender & Koschier 2017, Section 4.3).
//!
//! Two-way coupling (Akinci Eq. 11): every boundary force on a fluid
//! particle acts, reversed, on the body at the sample, so the body's force
//! and torque are sums over its samples; with gravity they drive
//! [`RigidBody::advance`]. A reflection constraint backs all this up: a
//! fluid particle found in a body is put back on its surface and loses its
//! velocity into it (tutorial Section 6.4), the impulse going to the body.

use super::body::{BodyState, RigidBody, Slip};
use super::ghosts::GhostDepth;
use crate::approx::Kernel;
use crate::math::{Real, Vector};
use crate::neighbors::{CandidateSearch, NeighborList, UniformGrid};
use rayon::prelude::*;
use std::ops::Range;

/// Force and torque (about the body's centre) per body.
type Loads = Vec<(Vector, Vector)>;

/// Particles per partial sum of the loads. Partial sums over fixed chunks,
/// added in order, keep the loads independent of how rayon splits the
/// work: summed in another order they round differently, and a body
/// rocking on a film of particles turns that rounding into a different
/// motion from run to run.
const LOAD_CHUNK: usize = 512;

fn no_loads(n: usize) -> Loads {
    vec![(Vector::zeros(), Vector::zeros()); n]
}

fn add_loads(mut a: Loads, b: Loads) -> Loads {
    for (x, y) in a.iter_mut().zip(b) {
        x.0 += y.0;
        x.1 += y.1;
    }
    a
}

/// What the boundary samples take from the fluid they bound: they are
/// spaced like its particles, stand for its rest density and enter its
/// sums through its kernels. A plain copy of those fluid parameters, so
/// that the bodies need not know the fluid's type.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundaryParams {
    /// The fluid's particle spacing, m: the samples' spacing.
    pub spacing: Real,
    /// The fluid's particle mass, kg (the ghost lattice the no-slip
    /// samples stand for, [`GhostDepth`]).
    pub mass: Real,
    /// The fluid's rest density rho_0, kg/m^3 (`psi_b = rho_0 V_b`).
    pub rest_density: Real,
    /// The fluid's density kernel (sample volumes, Akinci Eq. 4 and 6).
    pub density_kernel: Kernel,
    /// The fluid's gradient kernel (pressure and friction, Akinci Eq. 10).
    pub gradient_kernel: Kernel,
}

/// The rigid bodies of a fluid with their boundary samples, flat over all
/// bodies, and the fluid-to-sample neighbour lists.
#[derive(Debug, Clone)]
pub struct RigidBodies {
    bodies: Vec<RigidBody>,
    /// Samples of body `k`: `ranges[k]` into the flat arrays.
    ranges: Vec<Range<usize>>,
    /// Body-frame sample positions.
    local: Vec<Vector>,
    /// World positions and velocities of the samples.
    positions: Vec<Vector>,
    velocities: Vec<Vector>,
    /// `psi_b = rho_0 V_b`, kg.
    psi: Vec<Real>,
    /// Largest distance of a point of a body's surface from its centre
    /// (near the domain, for planes), per body.
    reach: Vec<Real>,
    /// Body index of each sample.
    body_of: Vec<u32>,
    grid: UniformGrid,
    /// Whether the grid must be rebuilt: samples moved since it was built.
    stale: bool,
    /// Samples within the support radius of each fluid particle.
    neighbors: NeighborList,
    density_kernel: Kernel,
    gradient_kernel: Kernel,
    rest_density: Real,
    /// Depth of the samples beneath the surface, m.
    inset: Real,
    /// The scale that makes the one layer of samples drag like the full
    /// ghost lattice of a no-slip wall, by distance from the surface.
    depth: GhostDepth,
    /// Loads the fluid exerted since the bodies last advanced.
    loads: Loads,
    /// Fluid particles the reflection constraint had to put back, since
    /// the bodies were built.
    projections: usize,
    /// Scratch of [`Self::advance`]: one moved body's samples, world frame.
    moved_samples: Vec<Vector>,
}

impl RigidBodies {
    /// Samples every body's surface at the fluid's spacing and computes
    /// the sample volumes with its density kernel. Planes are sampled only
    /// within the support radius of the box `[min, max]`. `grid` must cover
    /// that box with cells of the support radius.
    pub fn new(
        bodies: Vec<RigidBody>,
        fluid: &BoundaryParams,
        min: &Vector,
        max: &Vector,
        grid: UniformGrid,
    ) -> Self {
        let (spacing, rest_density) = (fluid.spacing, fluid.rest_density);
        let (density_kernel, gradient_kernel) = (fluid.density_kernel, fluid.gradient_kernel);
        let h = density_kernel.support();
        let (centre, half) = ((min + max) * 0.5, (max - min) * 0.5);
        let mut set = Self {
            ranges: Vec::with_capacity(bodies.len()),
            local: Vec::new(),
            positions: Vec::new(),
            velocities: Vec::new(),
            psi: Vec::new(),
            reach: Vec::with_capacity(bodies.len()),
            body_of: Vec::new(),
            grid,
            stale: true,
            neighbors: NeighborList::default(),
            density_kernel,
            gradient_kernel,
            rest_density,
            loads: no_loads(bodies.len()),
            projections: 0,
            moved_samples: Vec::new(),
            inset: 0.5 * spacing,
            depth: GhostDepth::new(spacing, fluid.mass, rest_density, &gradient_kernel),
            bodies,
        };
        for (k, body) in set.bodies.iter().enumerate() {
            let around = body.to_local(&centre);
            // Samples sit half a spacing inside the surface: the fluid keeps
            // about a spacing from them, so it meets the true surface as a
            // lattice meets a wall, half a spacing off (see BoxWalls).
            let inset = if body.hollow { -0.5 } else { 0.5 } * spacing;
            let sampled = body
                .shape
                .inset(inset)
                .unwrap_or_else(|| body.shape.clone());
            let samples = sampled.sample_surface(spacing, body.dim, &around, half.norm() + h);
            let start = set.local.len();
            let near_domain = |p: &Vector| {
                let x = body.state.position + body.state.orientation.transform_vector(p);
                (0..body.dim).all(|a| x[a] > min[a] - h && x[a] < max[a] + h)
            };
            let bounded = body.shape.volume(body.dim).is_some();
            set.local
                .extend(samples.into_iter().filter(|p| bounded || near_domain(p)));
            set.ranges.push(start..set.local.len());
            set.body_of.resize(set.local.len(), k as u32);
            // Every surface point lies within `sqrt(3) inset` of a sample.
            set.reach.push(
                set.local[start..]
                    .iter()
                    .map(|p| p.norm())
                    .fold(0.0, Real::max)
                    + (3.0 as Real).sqrt() * set.inset,
            );
        }
        set.place_samples();
        set.psi = sample_volumes(&set.positions, &set.ranges, &set.density_kernel)
            .into_iter()
            .map(|v| rest_density * v)
            .collect();
        if std::env::var("MESHLESS_PROBE").is_ok() {
            for r in &set.ranges {
                let psi: Real = set.psi[r.clone()].iter().sum::<Real>() / r.len() as Real;
                let radii: Vec<Real> = set.local[r.clone()]
                    .iter()
                    .take(5)
                    .map(|p| p.norm())
                    .collect();
                eprintln!(
                    "PROBE samples {} mean psi {psi} rho0 {rest_density} spacing {spacing} radii {radii:?} mass {}",
                    r.len(),
                    fluid.mass
                );
            }
        }
        set
    }

    /// The bodies, in scene order.
    pub fn bodies(&self) -> &[RigidBody] {
        &self.bodies
    }

    /// Samples of body `k`, world frame.
    pub fn samples(&self, k: usize) -> &[Vector] {
        &self.positions[self.ranges[k].clone()]
    }

    /// Fluid particles put back out of a body by the reflection
    /// constraint since the bodies were built.
    pub fn projections(&self) -> usize {
        self.projections
    }

    /// World positions and velocities of every sample from its body's
    /// state.
    fn place_samples(&mut self) {
        self.positions.resize(self.local.len(), Vector::zeros());
        self.velocities.resize(self.local.len(), Vector::zeros());
        for (body, range) in self.bodies.iter().zip(&self.ranges) {
            let s = &body.state;
            for b in range.clone() {
                let arm = s.orientation.transform_vector(&self.local[b]);
                self.positions[b] = s.position + arm;
                self.velocities[b] = s.velocity + s.angular_velocity.cross(&arm);
            }
        }
    }

    /// Lists the samples near each fluid particle; re-indexes the samples
    /// only when a body moved since the last call.
    pub fn find_neighbors(&mut self, fluid: &[Vector]) {
        if self.stale {
            self.grid.rebuild(&self.positions);
            self.stale = false;
        }
        let h = self.density_kernel.support();
        self.neighbors
            .build_between(&self.grid, fluid, &self.positions, h, None);
    }

    /// `sum_b psi_b W(x_i - x_b)`: the density the bodies add at fluid
    /// particle `i` at `xi`.
    #[inline]
    pub fn density(&self, i: usize, xi: &Vector) -> Real {
        let kernel = &self.density_kernel;
        self.neighbors
            .of(i)
            .iter()
            .map(|&b| {
                self.psi[b as usize]
                    * kernel.value_sq((xi - self.positions[b as usize]).norm_squared())
            })
            .sum()
    }

    /// `sum_b psi_b grad W(x_i - x_b)` (gradient kernel): the gradient of
    /// the density the bodies add, pointing into them.
    #[inline]
    pub fn density_gradient(&self, i: usize, xi: &Vector) -> Vector {
        let kernel = &self.gradient_kernel;
        self.neighbors
            .of(i)
            .iter()
            .fold(Vector::zeros(), |acc, &b| {
                let r = xi - self.positions[b as usize];
                acc + kernel.gradient(&r, r.norm()) * self.psi[b as usize]
            })
    }

    /// `sum_b psi_b v_b . grad W(x_i - x_b)`: the part of the density
    /// change at fluid particle `i` due to the bodies' motion.
    #[inline]
    pub fn velocity_flux(&self, i: usize, xi: &Vector) -> Real {
        let kernel = &self.gradient_kernel;
        self.neighbors.of(i).iter().fold(0.0, |acc, &b| {
            let b = b as usize;
            let r = xi - self.positions[b];
            acc + self.velocities[b].dot(&kernel.gradient(&r, r.norm())) * self.psi[b]
        })
    }

    /// Adds the bodies' forces on the fluid to `accelerations` and keeps
    /// their reactions for the bodies: pressure (when `pressures` is
    /// given, for WCSPH; DFSPH pushes through [`Self::density_gradient`])
    /// and the no-slip viscosity of the bodies that have it.
    #[allow(clippy::too_many_arguments)]
    pub fn add_forces(
        &mut self,
        positions: &[Vector],
        fluid_neighbors: &NeighborList,
        velocities: &[Vector],
        densities: &[Real],
        pressures: Option<&[Real]>,
        mass: Real,
        accelerations: &mut [Vector],
    ) {
        let viscous = self
            .bodies
            .iter()
            .any(|b| matches!(b.slip, Slip::No { .. }));
        if pressures.is_none() && !viscous {
            return;
        }
        let this = &*self;
        let kernel = &this.gradient_kernel;
        let h = kernel.support();
        let dim = kernel.dim() as Real;
        // 2 (d + 2) nu per body, 0 for free slip.
        let coefficient: Vec<Real> = this
            .bodies
            .iter()
            .map(|b| match b.slip {
                Slip::Free => 0.0,
                Slip::No { viscosity } => 2.0 * (dim + 2.0) * viscosity / this.rest_density,
            })
            .collect();
        let loads = accelerations
            .par_iter_mut()
            .enumerate()
            .fold_chunks(
                LOAD_CHUNK,
                || no_loads(this.bodies.len()),
                |mut loads, (i, a)| {
                    let (xi, vi, rho) = (positions[i], velocities[i], densities[i]);
                    let p = pressures.map_or(0.0, |p| p[i] / (rho * rho));
                    let scale = this.ghost_scale(
                        i,
                        positions,
                        fluid_neighbors,
                        densities,
                        mass,
                        &coefficient,
                    );
                    for &b in this.neighbors.of(i) {
                        let b = b as usize;
                        let k = this.body_of[b] as usize;
                        let r = xi - this.positions[b];
                        let r2 = r.norm_squared();
                        let grad = kernel.gradient(&r, r2.sqrt()) * this.psi[b];
                        let mut push = -grad * p;
                        if coefficient[k] > 0.0 {
                            let relative = (vi - this.velocities[b]).dot(&r) * scale;
                            push += grad * (coefficient[k] / rho * relative / (r2 + 0.01 * h * h));
                        }
                        *a += push;
                        let body = &this.bodies[k];
                        let reaction = -push * mass;
                        loads[k].0 += reaction;
                        loads[k].1 += (this.positions[b] - body.state.position).cross(&reaction);
                    }
                    loads
                },
            )
            .collect::<Vec<_>>()
            .into_iter()
            .fold(no_loads(this.bodies.len()), add_loads);
        self.loads = add_loads(std::mem::take(&mut self.loads), loads);
    }

    /// The scale of the no-slip samples' friction on fluid particle `i`
    /// (see [`GhostDepth`]): the friction-weighted volume its
    /// neighbourhood misses over the volume the samples of no-slip bodies
    /// supply, times the ghost lattice's mean extrapolation at its
    /// distance from the nearest such body; 1 without such samples near.
    fn ghost_scale(
        &self,
        i: usize,
        positions: &[Vector],
        fluid_neighbors: &NeighborList,
        densities: &[Real],
        mass: Real,
        coefficient: &[Real],
    ) -> Real {
        let xi = positions[i];
        let mut supplied = 0.0;
        let mut distance = Real::INFINITY;
        for &b in self.neighbors.of(i) {
            let b = b as usize;
            let k = self.body_of[b] as usize;
            if coefficient[k] > 0.0 {
                supplied += self.psi[b] / self.rest_density
                    * self.depth.weight((xi - self.positions[b]).norm());
                if distance.is_infinite() {
                    distance = self.bodies[k].excluded_distance(&xi);
                }
            }
        }
        if supplied <= 0.0 {
            return 1.0;
        }
        let fluid: Real = fluid_neighbors
            .pairs(i, positions)
            .map(|(j, r)| mass / densities[j] * self.depth.weight(r.norm()))
            .sum();
        let missing = (self.depth.full() - fluid).max(0.0);
        self.depth.extrapolation(distance) * missing / supplied
    }

    /// Keeps the reaction of a DFSPH pressure solve, which changed each
    /// fluid velocity by `-dt (kappa_i / rho_i) sum_b psi_b grad W_ib`:
    /// the body feels `m (kappa_i / rho_i) psi_b grad W_ib` at each sample.
    /// `kappa_over_rho` is `kappa_i / rho_i` summed over the solve's
    /// iterations, as the solver keeps it.
    pub fn add_pressure_reaction(
        &mut self,
        positions: &[Vector],
        kappa_over_rho: &[Real],
        mass: Real,
    ) {
        let this = &*self;
        let kernel = &this.gradient_kernel;
        let loads = (0..positions.len())
            .into_par_iter()
            .fold_chunks(
                LOAD_CHUNK,
                || no_loads(this.bodies.len()),
                |mut loads, i| {
                    let xi = positions[i];
                    let scale = mass * kappa_over_rho[i];
                    if scale == 0.0 {
                        return loads;
                    }
                    for &b in this.neighbors.of(i) {
                        let b = b as usize;
                        let k = this.body_of[b] as usize;
                        let r = xi - this.positions[b];
                        let force = kernel.gradient(&r, r.norm()) * (this.psi[b] * scale);
                        loads[k].0 += force;
                        loads[k].1 +=
                            (this.positions[b] - this.bodies[k].state.position).cross(&force);
                    }
                    loads
                },
            )
            .collect::<Vec<_>>()
            .into_iter()
            .fold(no_loads(this.bodies.len()), add_loads);
        self.loads = add_loads(std::mem::take(&mut self.loads), loads);
    }

    /// Advances every body by `dt` under the loads kept since the last
    /// advance and gravity, keeps dynamic bodies in the box `[min, max]`,
    /// and moves the samples.
    pub fn advance(&mut self, dt: Real, gravity: &Vector, min: &Vector, max: &Vector) {
        let mut moved = false;
        for (k, body) in self.bodies.iter_mut().enumerate() {
            let (force, torque) = self.loads[k];
            body.advance(dt, &force, &torque, gravity);
            if body.moves() {
                moved = true;
                let s = &body.state;
                self.moved_samples.clear();
                self.moved_samples.extend(
                    self.local[self.ranges[k].clone()]
                        .iter()
                        .map(|p| s.position + s.orientation.transform_vector(p)),
                );
                // The samples sit `inset` beneath the surface: walls that
                // far in stop the surface itself.
                let inset = Vector::repeat(self.inset);
                body.contain(&self.moved_samples, &(min + inset), &(max - inset));
            }
        }
        self.loads = no_loads(self.bodies.len());
        if moved {
            self.place_samples();
            self.stale = true;
        }
    }

    /// Turns the loads kept since the last advance into impulses over `dt`
    /// on the dynamic bodies at once (for forces that act at the end of a
    /// sub-step, after the bodies moved), and updates sample velocities.
    pub fn kick(&mut self, dt: Real) {
        let mut kicked = false;
        for (body, (force, torque)) in self.bodies.iter_mut().zip(&self.loads) {
            if force.norm_squared() + torque.norm_squared() > 0.0 {
                body.apply_impulse(&(force * dt), &(torque * dt));
                kicked |= body.moves();
            }
        }
        self.loads = no_loads(self.bodies.len());
        if kicked {
            self.place_samples();
        }
    }

    /// The reflection constraint: every fluid particle in a body is put
    /// (just outside) on its surface and loses its velocity into the body (relative to the
    /// body's surface), the impulse kept for the body (see [`Self::kick`]).
    pub fn enforce(
        &mut self,
        positions: &mut [Vector],
        velocities: &mut [Vector],
        mass: Real,
        dt: Real,
    ) {
        let this = &*self;
        let margin = 1e-6 * this.inset;
        let (loads, hits) = positions
            .par_iter_mut()
            .zip(velocities.par_iter_mut())
            .fold_chunks(
                LOAD_CHUNK,
                || (no_loads(this.bodies.len()), 0usize),
                |(mut loads, mut hits), (x, v)| {
                    for (k, body) in this.bodies.iter().enumerate() {
                        if !body.hollow && (*x - body.state.position).norm() > this.reach[k] + 1e-9
                        {
                            continue;
                        }
                        let d = body.excluded_distance(x);
                        if d >= 0.0 {
                            continue;
                        }
                        hits += 1;
                        let n = body.fluid_normal(x);
                        // Just outside, so that round-off cannot leave it in.
                        *x -= n * (d - margin);
                        let approach = (*v - body.point_velocity(x)).dot(&n);
                        if approach < 0.0 {
                            *v -= n * approach;
                            let impulse = n * (approach * mass);
                            loads[k].0 += impulse / dt;
                            loads[k].1 += (*x - body.state.position).cross(&impulse) / dt;
                        }
                    }
                    (loads, hits)
                },
            )
            .collect::<Vec<_>>()
            .into_iter()
            .fold((no_loads(this.bodies.len()), 0), |a, b| {
                (add_loads(a.0, b.0), a.1 + b.1)
            });
        self.projections += hits;
        self.loads = add_loads(std::mem::take(&mut self.loads), loads);
        self.kick(dt);
    }

    /// The largest speed of any body's surface.
    pub fn max_speed(&self) -> Real {
        self.bodies
            .iter()
            .zip(&self.reach)
            .map(|(b, &r)| b.max_speed(r))
            .fold(0.0, Real::max)
    }

    /// The first body whose state is not finite: its index and the
    /// offending quantity.
    pub fn first_invalid(&self) -> Option<(usize, &'static str, Real)> {
        self.bodies.iter().enumerate().find_map(|(k, b)| {
            let s = &b.state;
            let bad = |v: &Vector| {
                v.iter()
                    .any(|c| !c.is_finite() || c.abs() >= f32::MAX as Real)
            };
            if bad(&s.position) {
                Some((k, "body position", s.position.norm()))
            } else if bad(&s.velocity) || bad(&s.angular_velocity) {
                Some((k, "body velocity", s.velocity.norm()))
            } else {
                None
            }
        })
    }

    /// Copies the bodies' states into `backup`.
    pub fn save(&self, backup: &mut Vec<BodyState>) {
        backup.clear();
        backup.extend(self.bodies.iter().map(|b| b.state));
    }

    /// Puts back states saved by [`Self::save`].
    pub fn restore(&mut self, backup: &[BodyState]) {
        for (body, state) in self.bodies.iter_mut().zip(backup) {
            body.state = *state;
        }
        self.loads = no_loads(self.bodies.len());
        self.place_samples();
        self.stale = true;
    }
}

/// `V_b = 1 / sum_k W(x_b - x_k)` over the samples of each body (Akinci
/// Eq. 4), the sum found through a grid over the body's samples.
fn sample_volumes(positions: &[Vector], ranges: &[Range<usize>], kernel: &Kernel) -> Vec<Real> {
    let h = kernel.support();
    let mut volumes = vec![0.0; positions.len()];
    for range in ranges {
        let samples = &positions[range.clone()];
        if samples.is_empty() {
            continue;
        }
        let (lo, hi) = samples
            .iter()
            .fold((samples[0], samples[0]), |(lo, hi), p| {
                (lo.inf(p), hi.sup(p))
            });
        // A body's samples span at most the domain plus a margin, which the
        // fluid's own grid already fits.
        let mut grid = match UniformGrid::new(lo, hi + Vector::repeat(h), h) {
            Ok(grid) => grid,
            Err(_) => UniformGrid::new(lo, hi, (hi - lo).max() + h).expect("one cell"),
        };
        grid.rebuild(samples);
        volumes[range.clone()]
            .par_iter_mut()
            .enumerate()
            .for_each(|(b, volume)| {
                let xb = samples[b];
                let mut sum = 0.0;
                grid.for_each_candidate(&xb, |k| {
                    sum += kernel.value_sq((xb - samples[k as usize]).norm_squared());
                });
                *volume = 1.0 / sum;
            });
    }
    volumes
}
