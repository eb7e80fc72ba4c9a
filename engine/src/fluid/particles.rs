//! A fluid's particles: the state as structure of arrays and the passes
//! every pressure solver shares: neighbour search -> densities -> viscosity
//! -> XSPH -> integration with reflection off the domain's walls, plus the
//! rigid bodies' motion and the checks of a sub-step's result.
//!
//! The pressure solvers (`pressure/`) run these passes in their own order
//! and add their own; what is theirs (parameters, scratch) they keep.

use super::pressure::SolveInfo;
use super::{BoxWalls, Tait, ViscosityModel};
use crate::approx::{Kernel, KernelKind};
use crate::expression::VectorField;
use crate::linalg::linop::par_sum;
use crate::math::{Real, Vector};
use crate::neighbors::{CandidateSearch, NeighborList, Periodic, UniformGrid};
use crate::rigid::{BodyState, BoundaryParams, RigidBodies};
use rayon::prelude::*;

/// Physical and numerical parameters of one fluid, shared by every
/// pressure solver (each solver keeps its own knobs, see
/// [`super::Pressure`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FluidParams {
    /// Kernel support radius h, m.
    pub support_radius: Real,
    /// Kernel of the density sum and XSPH averages (poly6 in Algorithm 5).
    pub density_kernel: Kernel,
    /// Kernel of the pressure gradient (spiky in Algorithm 5).
    pub gradient_kernel: Kernel,
    /// The equation of state (tutorial Eq. 47): its rest density is every
    /// solver's rho_0, its stiffness the weakly compressible solver's.
    pub eos: Tait,
    /// XSPH factor xi (Eq. 53); 0 skips the XSPH pass.
    pub xsph: Real,
    /// Dynamic viscosity mu, Pa s; 0 skips the viscosity pass.
    pub viscosity: Real,
    /// How the viscous Laplacian is approximated.
    pub viscosity_model: ViscosityModel,
    /// Mass of every particle, kg.
    pub mass: Real,
    /// Initial particle spacing, m.
    pub spacing: Real,
}

impl FluidParams {
    /// The particle mass that gives the interior of a cubic lattice of
    /// `spacing` exactly the rest density under the density sum with
    /// `kernel`, so the fluid starts at rest (the tutorial's advice on
    /// initial states).
    pub fn lattice_mass(spacing: Real, kernel: &Kernel, rest_density: Real) -> Real {
        let reach = (kernel.support() / spacing).ceil() as i64;
        let depth = if kernel.dim() == 2 { 0 } else { reach };
        let mut sum = 0.0;
        for i in -reach..=reach {
            for j in -reach..=reach {
                for k in -depth..=depth {
                    let d2 = ((i * i + j * j + k * k) as Real) * spacing * spacing;
                    sum += kernel.value_sq(d2);
                }
            }
        }
        rest_density / sum
    }

    /// What rigid bodies in this fluid take from it: its spacing, particle
    /// mass, rest density and kernels.
    pub fn boundary(&self) -> BoundaryParams {
        BoundaryParams {
            spacing: self.spacing,
            mass: self.mass,
            rest_density: self.eos.rest_density,
            density_kernel: self.density_kernel,
            gradient_kernel: self.gradient_kernel,
        }
    }
}

/// A fluid's particles as structure of arrays, with what the shared
/// passes read (kernels, walls, bodies, neighbour lists) and the buffers
/// they reuse every sub-step.
#[derive(Debug, Clone)]
pub struct Fluid {
    /// The parameters it was built with.
    pub params: FluidParams,
    /// x_i, m, one per slot (see [`Fluid::ids`] for the particle in a slot).
    pub positions: Vec<Vector>,
    /// v_i, m/s.
    pub velocities: Vec<Vector>,
    /// rho_i from the last density pass, kg/m^3.
    pub densities: Vec<Real>,
    /// p_i from the last pressure pass, Pa.
    pub pressures: Vec<Real>,
    pub(in crate::fluid) accelerations: Vec<Vector>,
    pub(in crate::fluid) smoothed_velocities: Vec<Vector>,
    /// Solid walls of the domain, when the scene asks for them.
    pub(in crate::fluid) walls: Option<BoxWalls>,
    /// A body force per unit mass besides gravity, when the scene names
    /// one.
    pub(in crate::fluid) body_force: Option<VectorField>,
    /// The kernel of the viscosity pass, when the scene has viscosity.
    pub(in crate::fluid) viscosity_kernel: Option<Kernel>,
    /// Rigid bodies in the fluid, when the scene has any.
    pub(in crate::fluid) rigid: Option<RigidBodies>,
    pub(in crate::fluid) grid: UniformGrid,
    /// Periodic axes of the domain, when the scene names any.
    pub(in crate::fluid) periodic: Option<Periodic>,
    pub(in crate::fluid) neighbors: NeighborList,
    /// Each slot's particle id (its index in the scene's order, kept
    /// while others leave): the arrays are kept in Z order (see
    /// `reorder.rs`).
    pub(in crate::fluid) ids: Vec<u32>,
    /// Each slot's rank among the live ids, the place frames list it at;
    /// empty while the ids are exactly `0..len` (no particle removed), when
    /// the rank is the id.
    pub(in crate::fluid) ranks: Vec<u32>,
    /// The id the next particle would get: ids are never reused, so a
    /// particle keeps its identity from frame to frame.
    pub(in crate::fluid) next_id: u32,
    pub(in crate::fluid) substeps_since_reorder: u32,
    pub(in crate::fluid) max_acceleration: Real,
    /// What the last sub-step's pressure solve achieved.
    pub(in crate::fluid) last_solve: SolveInfo,
}

impl Fluid {
    /// A fluid with the given particles; `grid` must cover the domain with
    /// cells of at least the support radius and wrap around the same
    /// `periodic` axes. Densities and pressures start at rest: the
    /// fluid's system computes them with its solver.
    pub(in crate::fluid) fn new(
        params: FluidParams,
        positions: Vec<Vector>,
        velocities: Vec<Vector>,
        walls: Option<BoxWalls>,
        grid: UniformGrid,
        periodic: Option<Periodic>,
    ) -> Self {
        let n = positions.len();
        Self {
            params,
            positions,
            velocities,
            densities: vec![params.eos.rest_density; n],
            pressures: vec![0.0; n],
            accelerations: vec![Vector::zeros(); n],
            smoothed_velocities: if params.xsph > 0.0 {
                vec![Vector::zeros(); n]
            } else {
                Vec::new()
            },
            walls,
            body_force: None,
            viscosity_kernel: (params.viscosity > 0.0).then(|| match params.viscosity_model {
                ViscosityModel::Morris | ViscosityModel::Monaghan => params.gradient_kernel,
                ViscosityModel::KernelLaplacian => Kernel::new(
                    KernelKind::Viscosity,
                    params.density_kernel.dim(),
                    params.support_radius,
                ),
            }),
            rigid: None,
            grid,
            periodic,
            neighbors: NeighborList::default(),
            ids: (0..n as u32).collect(),
            ranks: Vec::new(),
            next_id: n as u32,
            substeps_since_reorder: 0,
            max_acceleration: 0.0,
            last_solve: SolveInfo::default(),
        }
    }

    /// The rigid bodies in the fluid, if any.
    pub fn bodies(&self) -> Option<&RigidBodies> {
        self.rigid.as_ref()
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether the fluid has no particle.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Neighbour pairs (ordered, self-pairs included) of the last search.
    pub fn neighbor_pairs(&self) -> usize {
        self.neighbors.pair_count()
    }

    /// What the last sub-step's pressure solve achieved (zero for WCSPH,
    /// which does not iterate).
    pub fn last_solve(&self) -> SolveInfo {
        self.last_solve
    }

    /// Adds the scene's body force at each particle to its acceleration.
    pub(in crate::fluid) fn add_body_force(&mut self) {
        if let Some(force) = &self.body_force {
            let planar = self.params.density_kernel.dim() == 2;
            self.accelerations
                .par_iter_mut()
                .zip(self.positions.par_iter())
                .for_each(|(a, x)| {
                    let mut f = force.eval(x);
                    if planar {
                        f.z = 0.0;
                    }
                    *a += f;
                });
        }
    }

    /// Kinetic energy `sum m |v|^2 / 2`, J (per metre of depth in 2D).
    pub fn kinetic_energy(&self) -> Real {
        let m = self.params.mass;
        par_sum(self.velocities.len(), |k| {
            0.5 * m * self.velocities[k].norm_squared()
        })
    }

    /// Potential energy in `gravity`, `-sum m g . x`, J: zero where the
    /// positions are at the origin.
    pub fn potential_energy(&self, gravity: &Vector) -> Real {
        let m = self.params.mass;
        -par_sum(self.positions.len(), |k| {
            m * gravity.dot(&self.positions[k])
        })
    }

    /// The id (index in the scene's order) of the particle in `slot`.
    pub fn id_of(&self, slot: usize) -> usize {
        self.ids[slot] as usize
    }

    /// Total mass, kg.
    pub fn total_mass(&self) -> Real {
        self.params.mass * self.len() as Real
    }

    /// The largest density as a multiple of the rest density.
    pub fn max_compression(&self) -> (usize, Real) {
        let rest = self.params.eos.rest_density;
        self.densities
            .par_iter()
            .enumerate()
            .map(|(k, rho)| (k, rho / rest))
            .reduce(|| (0, 0.0), |a, b| if b.1 > a.1 { b } else { a })
    }

    /// Whether anything besides gravity can put energy into the fluid: a
    /// body force, moving walls or bodies that move (kinematic ones drive
    /// it, dynamic ones hand it their own energy).
    pub fn has_energy_source(&self) -> bool {
        self.body_force.is_some()
            || self.walls.as_ref().is_some_and(BoxWalls::moving)
            || self
                .rigid
                .as_ref()
                .is_some_and(|r| r.bodies().iter().any(|b| b.moves()))
    }

    /// The largest speed of a particle or of a body's surface: what the
    /// CFL conditions of the solvers bound.
    pub(in crate::fluid) fn max_speed(&self) -> Real {
        self.velocities
            .par_iter()
            .map(|v| v.norm_squared())
            .reduce(|| 0.0, Real::max)
            .sqrt()
            .max(self.rigid.as_ref().map_or(0.0, RigidBodies::max_speed))
    }

    /// `dt` bounded, with viscosity, by the diffusion condition
    /// `0.125 (h/2)^2 rho_0 / mu` (Morris et al. 1997), which every solver
    /// obeys.
    pub(in crate::fluid) fn viscous_limit(&self, mut dt: Real) -> Real {
        let h = self.params.support_radius;
        if self.params.viscosity > 0.0 {
            // Morris et al. state the condition with the smoothing length
            // of kernels whose support is twice it, so here with `h / 2`;
            // the support radius itself made a Taylor–Green vortex blow up
            // (tests/tests/validation_periodic.rs).
            let smoothing = 0.5 * h;
            // Monaghan's form acts on compression with three times the
            // viscosity (its limit is `nu (Lap v + 2 grad div v)`), so its
            // fastest mode decays three times as fast.
            let stiffer = match self.params.viscosity_model {
                ViscosityModel::Monaghan => 3.0,
                ViscosityModel::Morris | ViscosityModel::KernelLaplacian => 1.0,
            };
            dt = dt.min(
                0.125 * smoothing * smoothing * self.params.eos.rest_density
                    / (stiffer * self.params.viscosity),
            );
        }
        dt
    }

    pub(in crate::fluid) fn find_neighbors(&mut self) {
        self.grid.rebuild(&self.positions);
        self.neighbors.build_periodic(
            &self.grid,
            &self.positions,
            self.params.support_radius,
            self.periodic,
        );
        if let Some(rigid) = &mut self.rigid {
            rigid.find_neighbors(&self.positions);
        }
    }

    /// Advances the rigid bodies by `dt` under the loads the fluid put on
    /// them, then puts fluid particles that ended up in a body back out.
    pub(in crate::fluid) fn move_bodies(
        &mut self,
        dt: Real,
        gravity: &Vector,
        min: &Vector,
        max: &Vector,
    ) {
        if let Some(rigid) = &mut self.rigid {
            rigid.advance(dt, gravity, min, max);
            rigid.enforce(
                &mut self.positions,
                &mut self.velocities,
                self.params.mass,
                dt,
            );
        }
    }

    /// `rho_i = sum_j m_j omega(|x_i - x_j|)` (Algorithm 5; poly6 by
    /// default), plus the walls' ghost layers (Eq. 55).
    pub(in crate::fluid) fn compute_densities(&mut self) {
        self.compute_densities_with(false);
    }

    /// The densities with the walls' ghost layers tabulated
    /// (`mirrored = false`, [`BoxWalls::density`]) or made of the fluid's
    /// own mirror images (`true`, [`BoxWalls::mirrors`]):
    /// `rho_i = sum_j m_j (omega(|x_i - x_j|) + sum_S omega(|x_i - S x_j|))`.
    pub(in crate::fluid) fn compute_densities_with(&mut self, mirrored: bool) {
        let (positions, neighbors, kernel, mass, walls, rigid) = (
            &self.positions,
            &self.neighbors,
            &self.params.density_kernel,
            self.params.mass,
            self.walls.as_ref(),
            self.rigid.as_ref(),
        );
        self.densities
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, rho)| {
                let xi = positions[i];
                let own = neighbors
                    .pairs(i, positions)
                    .map(|(_, r)| kernel.value_sq(r.norm_squared()))
                    .sum::<Real>();
                let wall = match walls {
                    Some(w) if mirrored => {
                        let mut sum = 0.0;
                        w.mirrors(&xi, |planes| {
                            for (j, r) in neighbors.pairs(i, positions) {
                                let image = BoxWalls::mirrored(planes, &r, &xi, &positions[j]);
                                sum += kernel.value_sq(image.norm_squared());
                            }
                        });
                        mass * sum
                    }
                    Some(w) => w.density(&xi),
                    None => 0.0,
                };
                *rho = mass * own + wall + rigid.map_or(0.0, |r| r.density(i, &xi));
            });
    }

    /// XSPH artificial viscosity (tutorial Eq. 53, Monaghan 1989) in its
    /// difference form:
    /// `v_i <- v_i + xi sum_j (2 m / (rho_i + rho_j)) (v_j - v_i) omega_ij`.
    ///
    /// Eq. 53 blends `v_i` with the SPH average `sum_j (m_j / rho_j) v_j
    /// omega_ij`; both agree where that average reproduces constants
    /// (`sum_j (m_j / rho_j) omega_ij = 1`), but where the neighbourhood is
    /// cut (free surfaces, walls) the average falls short and Eq. 53 as
    /// written brakes uniform motion, every sub-step. The difference form
    /// leaves uniform motion alone and, with the pair-symmetric density,
    /// conserves momentum.
    pub(in crate::fluid) fn apply_xsph(&mut self) {
        let (positions, velocities, densities, neighbors, kernel, mass) = (
            &self.positions,
            &self.velocities,
            &self.densities,
            &self.neighbors,
            &self.params.density_kernel,
            self.params.mass,
        );
        let xi = self.params.xsph;
        self.smoothed_velocities
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, out)| {
                let (vi, rho_i) = (velocities[i], densities[i]);
                let correction =
                    neighbors
                        .pairs(i, positions)
                        .fold(Vector::zeros(), |acc, (j, r)| {
                            let w = kernel.value_sq(r.norm_squared());
                            acc + (velocities[j] - vi) * (2.0 * mass / (rho_i + densities[j]) * w)
                        });
                *out = vi + correction * xi;
            });
        std::mem::swap(&mut self.velocities, &mut self.smoothed_velocities);
    }

    /// Eq. 58-59 (symplectic Euler), then reflection off the walls.
    pub(in crate::fluid) fn integrate(&mut self, dt: Real, min: &Vector, max: &Vector) {
        self.record_max_acceleration();
        let periodic = self.periodic.as_ref();
        self.positions
            .par_iter_mut()
            .zip(self.velocities.par_iter_mut())
            .zip(self.accelerations.par_iter())
            .for_each(|((x, v), a)| {
                *v += a * dt;
                *x += *v * dt;
                confine(x, v, min, max, periodic);
            });
    }

    /// Keeps the largest acceleration for the force condition of the next
    /// sub-step's limit.
    pub(in crate::fluid) fn record_max_acceleration(&mut self) {
        self.max_acceleration = self
            .accelerations
            .par_iter()
            .map(|a| a.norm_squared())
            .reduce(|| 0.0, Real::max)
            .sqrt();
    }

    /// The first particle whose state cannot go on: a position, velocity,
    /// density or pressure that is not finite or does not fit a frame's
    /// f32, or a speed above `max_speed` (the solver's limit: beyond it
    /// its model is void; this is how an unstable run shows before it
    /// overflows).
    pub(in crate::fluid) fn first_invalid(&self, max_speed: Real) -> Option<Invalid> {
        const MAX: Real = f32::MAX as Real;
        let bad_vector = |v: &Vector| v.iter().any(|c| !c.is_finite() || c.abs() >= MAX);
        // NaN fails `is_finite`; infinities and huge values fail the bound.
        let bad_scalar = |s: &Real| !s.is_finite() || s.abs() >= MAX;
        let found = |quantity, i: Option<usize>, value: Real| {
            i.map(|slot| Invalid {
                quantity,
                particle: self.ids[slot] as usize,
                value,
            })
        };
        let i = self.positions.par_iter().position_first(bad_vector);
        if let Some(v) = found("position", i, i.map_or(0.0, |i| self.positions[i].norm())) {
            return Some(v);
        }
        let i = self
            .velocities
            .par_iter()
            .position_first(|v| bad_vector(v) || v.norm() > max_speed);
        if let Some(v) = found("velocity", i, i.map_or(0.0, |i| self.velocities[i].norm())) {
            return Some(v);
        }
        let i = self.densities.par_iter().position_first(bad_scalar);
        if let Some(v) = found("density", i, i.map_or(0.0, |i| self.densities[i])) {
            return Some(v);
        }
        let i = self.pressures.par_iter().position_first(bad_scalar);
        if let Some(v) = found("pressure", i, i.map_or(0.0, |i| self.pressures[i])) {
            return Some(v);
        }
        let (k, quantity, value) = self.rigid.as_ref()?.first_invalid()?;
        Some(Invalid {
            quantity,
            particle: k,
            value,
        })
    }

    /// Copies the evolving state into `backup`, reusing its buffers.
    pub(in crate::fluid) fn save(&self, backup: &mut FluidState) {
        backup.positions.clone_from(&self.positions);
        backup.velocities.clone_from(&self.velocities);
        backup.densities.clone_from(&self.densities);
        backup.pressures.clone_from(&self.pressures);
        backup.max_acceleration = self.max_acceleration;
        backup.substeps_since_reorder = self.substeps_since_reorder;
        if let Some(rigid) = &self.rigid {
            rigid.save(&mut backup.bodies);
        }
    }

    /// Puts back a state saved by [`Fluid::save`], with the neighbour
    /// lists of its positions (the solver rebuilds what it derives from
    /// them).
    pub(in crate::fluid) fn restore(&mut self, backup: &FluidState) {
        self.positions.clone_from(&backup.positions);
        self.velocities.clone_from(&backup.velocities);
        self.densities.clone_from(&backup.densities);
        self.pressures.clone_from(&backup.pressures);
        self.max_acceleration = backup.max_acceleration;
        self.substeps_since_reorder = backup.substeps_since_reorder;
        if let Some(rigid) = &mut self.rigid {
            rigid.restore(&backup.bodies);
        }
        self.find_neighbors();
    }
}

/// The part of a fluid a step changes, kept to undo a failed step.
#[derive(Debug, Clone, Default)]
pub struct FluidState {
    positions: Vec<Vector>,
    velocities: Vec<Vector>,
    densities: Vec<Real>,
    pressures: Vec<Real>,
    max_acceleration: Real,
    /// So that a step taken again after a cancelled one sorts the
    /// particles when the first attempt would have.
    substeps_since_reorder: u32,
    bodies: Vec<BodyState>,
    /// The pressure solver's (see `PressureSolver::save`).
    pub(in crate::fluid) warm_start: Vec<Real>,
}

/// A particle quantity that left its valid range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Invalid {
    /// What left its range ("position", "velocity", "density", ...).
    pub quantity: &'static str,
    /// The particle (or, for a body quantity, the body's index among the
    /// fluid's bodies).
    pub particle: usize,
    /// The offending value (a norm for vectors).
    pub value: Real,
}

/// Keeps a particle in the domain: wraps it around the periodic axes, then
/// reflects it off the walls of the others.
#[inline]
pub(in crate::fluid) fn confine(
    x: &mut Vector,
    v: &mut Vector,
    min: &Vector,
    max: &Vector,
    periodic: Option<&Periodic>,
) {
    if let Some(p) = periodic {
        // Wrapped coordinates lie in [min, max), where reflection is a
        // no-op: only the walled axes reflect.
        p.wrap(x);
    }
    reflect(x, v, min, max);
}

/// Mirrors a particle that crossed a wall back inside and flips its normal
/// velocity ("reflect them off solid boundaries", tutorial Section 6.4).
#[inline]
fn reflect(x: &mut Vector, v: &mut Vector, min: &Vector, max: &Vector) {
    for a in 0..3 {
        if x[a] < min[a] {
            x[a] = min[a] + (min[a] - x[a]);
            v[a] = v[a].abs();
        } else if x[a] > max[a] {
            x[a] = max[a] - (x[a] - max[a]);
            v[a] = -v[a].abs();
        }
        // A particle fast enough to cross the whole box stays inside.
        x[a] = x[a].clamp(min[a], max[a]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The calibrated mass gives interior lattice particles the rest
    /// density, for every kernel fit for densities.
    #[test]
    fn lattice_mass_gives_rest_density() {
        let spacing = 0.05;
        let h = 0.1;
        for kind in [
            KernelKind::Poly6,
            KernelKind::CubicSpline,
            KernelKind::WendlandC2,
            KernelKind::Spiky,
        ] {
            let kernel = Kernel::new_3d(kind, h);
            let mass = FluidParams::lattice_mass(spacing, &kernel, 1000.0);
            assert!(
                (interior_density(spacing, &kernel, mass) - 1000.0).abs() < 1e-9,
                "{kind:?}"
            );
        }
    }

    fn interior_density(spacing: Real, kernel: &Kernel, mass: Real) -> Real {
        let mut positions = Vec::new();
        for i in 0..9 {
            for j in 0..9 {
                for k in 0..9 {
                    positions.push(Vector::new(i as Real, j as Real, k as Real) * spacing);
                }
            }
        }
        let centre = 4 * 81 + 4 * 9 + 4;
        positions
            .iter()
            .map(|x| mass * kernel.value_sq((x - positions[centre]).norm_squared()))
            .sum()
    }

    #[test]
    fn reflection_keeps_particles_inside() {
        let min = Vector::zeros();
        let max = Vector::repeat(1.0);
        let mut x = Vector::new(-0.1, 1.2, 0.5);
        let mut v = Vector::new(-2.0, 3.0, 0.0);
        reflect(&mut x, &mut v, &min, &max);
        assert!((x - Vector::new(0.1, 0.8, 0.5)).norm() < 1e-12);
        assert_eq!(v, Vector::new(2.0, -3.0, 0.0));
        let mut x = Vector::new(-50.0, 0.5, 0.5);
        reflect(&mut x, &mut v, &min, &max);
        assert!(x.x >= 0.0 && x.x <= 1.0);
    }
}
