//! The fluid of a scene: its blocks and hand-placed particles, its
//! physical and numerical knobs (pressure solver, kernels, walls,
//! viscosity), and their validation.

use super::error::{check_box, check_positive, check_range, check_vector};
use super::{Aabb, Scene, SceneError, SlipKind, defaults};
use crate::approx::KernelKind;
use crate::expression::VectorField;
use crate::fluid::ViscosityModel;
use crate::math::Real;
use crate::neighbors::{GridError, UniformGrid};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// A box filled with fluid particles on a regular lattice.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FluidBlock {
    /// The box the lattice fills.
    pub region: Aabb,
    /// Initial velocity, m/s.
    #[serde(default)]
    pub velocity: [Real; 3],
}

/// One particle placed by hand, besides the blocks' lattices.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParticleSpec {
    /// Where it starts, m.
    pub position: [Real; 3],
    /// Initial velocity, m/s.
    #[serde(default)]
    pub velocity: [Real; 3],
}

/// The pressure solver of a fluid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SolverKind {
    /// Weakly compressible SPH (tutorial Algorithm 5): explicit, the step
    /// limited by the sound speed that `stiffness` sets.
    Wcsph,
    /// Divergence-free SPH (Bender & Koschier 2015): iterated to
    /// `density_tolerance`, the step limited by the flow speed.
    Dfsph,
}

/// How the fluid meets the walls of the domain.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WallModel {
    /// Walls count in densities and push back through pressure, like layers
    /// of ghost particles (tutorial Eq. 55); reflection guards the rest.
    Solid,
    /// Particles are only reflected (tutorial Section 6.4): cheaper, but
    /// particles beside a wall lack density and cling to it.
    Reflect,
}

/// The velocities of moving domain walls, m/s, each along its wall (a
/// component across it is refused): a Couette flow's sliding lid, a
/// conveyor floor. Walls left out stand still.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallVelocities {
    /// The wall at the domain's smallest x.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_x: Option<[Real; 3]>,
    /// The wall at the domain's largest x.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_x: Option<[Real; 3]>,
    /// The wall at the domain's smallest y.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_y: Option<[Real; 3]>,
    /// The wall at the domain's largest y.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_y: Option<[Real; 3]>,
    /// The wall at the domain's smallest z.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_z: Option<[Real; 3]>,
    /// The wall at the domain's largest z.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_z: Option<[Real; 3]>,
}

/// One wall's scene name and velocity, if it moves.
pub type NamedWallVelocity = (&'static str, Option<[Real; 3]>);

impl WallVelocities {
    /// Each wall's velocity, `[axis][0 below, 1 above]`, with its scene
    /// name; unset walls stand still.
    pub fn by_wall(&self) -> [[NamedWallVelocity; 2]; 3] {
        [
            [("min_x", self.min_x), ("max_x", self.max_x)],
            [("min_y", self.min_y), ("max_y", self.max_y)],
            [("min_z", self.min_z), ("max_z", self.max_z)],
        ]
    }

    /// Whether every wall stands still (nothing to write in a scene).
    pub fn is_still(&self) -> bool {
        self.by_wall().iter().flatten().all(|(_, v)| v.is_none())
    }
}

/// A weakly compressible SPH fluid (Adams–Wicke tutorial, Algorithm 5).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FluidSpec {
    /// Initial particle spacing, m.
    pub spacing: Real,
    /// Kernel support radius h, m; default `2 * spacing`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub support_radius: Option<Real>,
    /// Rest density rho_0, kg/m^3.
    #[serde(default = "default_rest_density")]
    pub rest_density: Real,
    /// Tait stiffness K, Pa (Eq. 47); required by the WCSPH solver.
    #[serde(default)]
    pub stiffness: Real,
    /// Tait exponent gamma (Eq. 47).
    #[serde(default = "default_gamma")]
    pub gamma: Real,
    /// Factor zeta on negative pressures (Eq. 54).
    #[serde(default = "default_negative_pressure_scale")]
    pub negative_pressure_scale: Real,
    /// XSPH factor xi (Eq. 53); 0 runs no XSPH pass.
    #[serde(default = "default_xsph")]
    pub xsph: Real,
    /// Dynamic viscosity mu, Pa s; 0 runs no viscosity pass.
    #[serde(default = "default_viscosity")]
    pub viscosity: Real,
    /// The SPH form of the viscous Laplacian.
    #[serde(default = "default_viscosity_model")]
    pub viscosity_model: ViscosityModel,
    /// How the fluid meets the domain's walls.
    #[serde(default = "default_walls")]
    pub walls: WallModel,
    /// Whether `solid` walls hold the fluid back along them (`no`, through
    /// the fluid's viscosity) or let it slide (`free`).
    #[serde(default = "default_wall_slip")]
    pub wall_slip: SlipKind,
    /// Velocities of moving no-slip walls.
    #[serde(default, skip_serializing_if = "WallVelocities::is_still")]
    pub wall_velocity: WallVelocities,
    /// The pressure solver.
    #[serde(default = "default_solver")]
    pub solver: SolverKind,
    /// DFSPH: largest average density error accepted (fraction of rho_0).
    #[serde(default = "default_density_tolerance")]
    pub density_tolerance: Real,
    /// DFSPH: largest average density change accepted by the
    /// divergence-free solve, per sub-step at CFL 0.4 however short the
    /// sub-steps are (fraction of rho_0).
    #[serde(default = "default_divergence_tolerance")]
    pub divergence_tolerance: Real,
    /// DFSPH: iteration cap of each solve.
    #[serde(default = "default_max_solver_iterations")]
    pub max_solver_iterations: u32,
    /// Kernel of densities and XSPH averages.
    #[serde(default = "default_density_kernel")]
    pub density_kernel: KernelKind,
    /// Kernel of the pressure gradient.
    #[serde(default = "default_gradient_kernel")]
    pub gradient_kernel: KernelKind,
    /// Boxes filled with particles on a lattice of `spacing`.
    #[serde(default)]
    pub blocks: Vec<FluidBlock>,
    /// Single particles besides the blocks (a measured state, a velocity
    /// field); they take the blocks' particle mass.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub particles: Vec<ParticleSpec>,
    /// The blocks' initial velocity as three formulas in `x`, `y`, `z`
    /// (see [`crate::expression`]), replacing each block's uniform
    /// `velocity`; hand-placed particles keep theirs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity_field: Option<[String; 3]>,
    /// A body force per unit mass, m/s^2, as three formulas in `x`, `y`,
    /// `z`, added to gravity at every particle and sub-step (a pressure
    /// gradient driving a periodic channel, a swirl).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub body_force: Option<[String; 3]>,
}

impl FluidSpec {
    /// The support radius h, with its default applied.
    pub fn support_radius(&self) -> Real {
        self.support_radius
            .unwrap_or(defaults::SUPPORT_RATIO * self.spacing)
    }

    /// Lattice points per axis of a block in `dim` dimensions. Points sit
    /// at the centres of spacing-sized cells, so adjacent blocks tile
    /// without overlap; in 2D there is one layer, at z = 0.
    fn lattice_dims(&self, block: &FluidBlock, dim: usize) -> [f64; 3] {
        [0, 1, 2].map(|a| {
            if a < dim {
                (block.region.extent(a) / self.spacing + 1e-9)
                    .floor()
                    .max(0.0)
            } else {
                1.0
            }
        })
    }

    /// Number of particles the blocks and single particles create in
    /// `dim` dimensions.
    pub fn particle_count(&self, dim: usize) -> f64 {
        self.blocks
            .iter()
            .map(|b| self.lattice_dims(b, dim).iter().product::<f64>())
            .sum::<f64>()
            + self.particles.len() as f64
    }

    /// Lattice positions of all blocks in `dim` dimensions, with each
    /// particle's block index.
    pub fn lattice(&self, dim: usize) -> impl Iterator<Item = ([Real; 3], usize)> + '_ {
        self.blocks.iter().enumerate().flat_map(move |(b, block)| {
            let [nx, ny, nz] = self.lattice_dims(block, dim).map(|n| n as usize);
            let s = self.spacing;
            let min = block.region.min;
            let z = move |k: usize| {
                if dim == 2 {
                    0.0
                } else {
                    min[2] + (k as Real + 0.5) * s
                }
            };
            (0..nz).flat_map(move |k| {
                (0..ny).flat_map(move |j| {
                    (0..nx).map(move |i| {
                        (
                            [
                                min[0] + (i as Real + 0.5) * s,
                                min[1] + (j as Real + 0.5) * s,
                                z(k),
                            ],
                            b,
                        )
                    })
                })
            })
        })
    }
}

/// Most hand-placed particles one cell of side `spacing` may hold. A
/// lattice puts one there and a compressed measured state a few; more
/// means coincident or piled-up input, whose neighbour lists (every
/// particle near every other) would grow with the square of the pile.
pub const MAX_PARTICLES_PER_CELL: usize = 8;

impl Scene {
    /// The checks every fluid position passes, whether a scene places it
    /// by hand or a snapshot restores it (a snapshot may be forged; its
    /// checksum catches corruption only): finite, inside the domain, and
    /// not piled into one spot. Bins the positions into cells of side
    /// `spacing` (one pass, memory linear in their number) and names the
    /// first crowded cell's first particle, which bounds the neighbours
    /// of every particle before any neighbour search runs. Returns the
    /// neighbour pairs the layout makes, by estimate
    /// (`footprint::pairs_in_cells`), for a memory reservation.
    /// `field` names position `i` in errors.
    ///
    /// # Errors
    /// [`SceneError::Invalid`] naming the first offending position.
    pub fn check_fluid_positions(
        &self,
        fluid: &FluidSpec,
        positions: impl IntoIterator<Item = [Real; 3]>,
        field: &dyn Fn(usize) -> String,
    ) -> Result<Real, SceneError> {
        let positions = positions.into_iter();
        let mut cells: HashMap<[i64; 3], (usize, usize)> =
            HashMap::with_capacity(positions.size_hint().0);
        for (i, position) in positions.enumerate() {
            check_vector(&field(i), position)?;
            let outside = (0..self.dimension)
                .find(|&a| position[a] < self.domain.min[a] || position[a] > self.domain.max[a]);
            if let Some(a) = outside {
                let axis = ["x", "y", "z"][a];
                return Err(SceneError::invalid(
                    field(i),
                    format!(
                        "lies outside the domain: {axis} = {} is not in [{}, {}]; move the particle \
                         inside or widen the domain",
                        position[a], self.domain.min[a], self.domain.max[a]
                    ),
                ));
            }
            // Saturating casts: positions are finite and inside the domain.
            let cell = std::array::from_fn(|a| {
                ((position[a] - self.domain.min[a]) / fluid.spacing).floor() as i64
            });
            let (first, count) = cells.entry(cell).or_insert((i, 0));
            *count += 1;
            if *count > MAX_PARTICLES_PER_CELL {
                return Err(SceneError::invalid(
                    field(*first),
                    format!(
                        "more than {MAX_PARTICLES_PER_CELL} particles lie within one spacing \
                         ({}) of each other here ({} and {} among them); place particles about \
                         a spacing apart",
                        fluid.spacing,
                        field(*first),
                        field(i)
                    ),
                ));
            }
        }
        Ok(super::footprint::pairs_in_cells(
            cells.into_iter().map(|(cell, (_, count))| (cell, count)),
            fluid.support_radius() / fluid.spacing,
            self.dimension,
        ))
    }

    /// No-slip walls need solid walls and viscosity; moving walls need
    /// no slip, a wall to move and a velocity along it.
    fn check_walls(&self, at: &str, fluid: &FluidSpec) -> Result<(), SceneError> {
        if fluid.wall_slip == SlipKind::No {
            if fluid.walls != WallModel::Solid {
                return Err(SceneError::invalid(
                    format!("{at}.wall_slip"),
                    "needs `walls = \"solid\"`: reflecting walls have no ghost layers to hold \
                     the fluid back",
                ));
            }
            if fluid.viscosity <= 0.0 {
                return Err(SceneError::invalid(
                    format!("{at}.wall_slip"),
                    "acts through the fluid's viscosity, which is 0; set `viscosity`",
                ));
            }
        }
        let periodic = self.periodic_axes();
        for (a, walls) in fluid.wall_velocity.by_wall().iter().enumerate() {
            for &(name, velocity) in walls {
                let Some(velocity) = velocity else { continue };
                let field = format!("{at}.wall_velocity.{name}");
                check_vector(&field, velocity)?;
                if fluid.wall_slip != SlipKind::No {
                    return Err(SceneError::invalid(
                        field,
                        "moves a free-slip wall, which cannot drag the fluid; set `wall_slip = \"no\"`",
                    ));
                }
                if a >= self.dimension || periodic[a] {
                    return Err(SceneError::invalid(
                        field,
                        "names a wall the domain does not have (a periodic axis, or z in 2D)",
                    ));
                }
                if velocity[a] != 0.0 {
                    return Err(SceneError::invalid(
                        field,
                        format!(
                            "has a component {} across the wall; a wall moves only along itself",
                            crate::math::Brief(velocity[a])
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Formulas parse, use only `x`, `y`, `z`, and are finite at every
    /// lattice point (the body force at least where the fluid starts).
    /// Call only once the particle count is known to be within the limit:
    /// this visits every particle.
    pub(super) fn check_fields(&self, at: &str, fluid: &FluidSpec) -> Result<(), SceneError> {
        for (name, texts) in [
            ("velocity_field", &fluid.velocity_field),
            ("body_force", &fluid.body_force),
        ] {
            let Some(texts) = texts else { continue };
            let field = VectorField::parse(texts).map_err(|(a, e)| {
                SceneError::invalid(format!("{at}.{name}[{a}]"), e.to_string())
            })?;
            let points = fluid
                .lattice(self.dimension)
                .map(|(x, _)| crate::math::vector(x));
            if let Some(bad) = field.first_non_finite(points) {
                return Err(SceneError::invalid(
                    format!("{at}.{name}"),
                    format!("{bad} (particle {} of the blocks)", bad.index),
                ));
            }
        }
        Ok(())
    }

    pub(super) fn validate_fluid(&self, at: &str, fluid: &FluidSpec) -> Result<(), SceneError> {
        check_positive(&format!("{at}.spacing"), fluid.spacing)?;
        let h = fluid.support_radius();
        check_range(
            &format!("{at}.support_radius"),
            h,
            fluid.spacing,
            5.0 * fluid.spacing,
        )
        .map_err(|e| match e {
            SceneError::Invalid { field, message } => SceneError::Invalid {
                field,
                message: format!("{message} (between 1 and 5 times `spacing`)"),
            },
            other => other,
        })?;
        check_positive(&format!("{at}.rest_density"), fluid.rest_density)?;
        if fluid.solver == SolverKind::Wcsph {
            check_positive(&format!("{at}.stiffness"), fluid.stiffness).map_err(|e| match e {
                SceneError::Invalid { field, message } => SceneError::Invalid {
                    field,
                    message: format!("{message} (the wcsph solver needs the Tait stiffness)"),
                },
                other => other,
            })?;
        }
        // Every knob is checked whichever solver reads it: a NaN the other
        // solver ignores would still be stored, echoed and compared
        // (found by the `requests` fuzz target: a NaN divergence
        // tolerance on a WCSPH fluid made the scene unequal to itself).
        // Water's bulk modulus is 2.2e9 Pa; beyond 1e12 the explicit
        // sub-steps would be needlessly tiny and pressures overflow frames.
        check_range(&format!("{at}.stiffness"), fluid.stiffness, 0.0, 1e12)?;
        check_range(
            &format!("{at}.density_tolerance"),
            fluid.density_tolerance,
            1e-6,
            0.1,
        )?;
        check_range(
            &format!("{at}.divergence_tolerance"),
            fluid.divergence_tolerance,
            1e-6,
            0.1,
        )?;
        if fluid.max_solver_iterations == 0 || fluid.max_solver_iterations > 10_000 {
            return Err(SceneError::invalid(
                format!("{at}.max_solver_iterations"),
                format!("must be in [1, 10000], got {}", fluid.max_solver_iterations),
            ));
        }
        check_range(&format!("{at}.gamma"), fluid.gamma, 1.0, 10.0)?;
        check_range(
            &format!("{at}.negative_pressure_scale"),
            fluid.negative_pressure_scale,
            0.0,
            1.0,
        )?;
        check_range(&format!("{at}.xsph"), fluid.xsph, 0.0, 1.0)?;
        // Honey is about 10 Pa s; beyond 1e4 the diffusion limit of the
        // explicit step makes sub-steps vanishingly small.
        check_range(&format!("{at}.viscosity"), fluid.viscosity, 0.0, 1e4)?;
        self.check_walls(at, fluid)?;
        if fluid.density_kernel == KernelKind::Viscosity {
            return Err(SceneError::invalid(
                format!("{at}.density_kernel"),
                "viscosity is infinite at zero distance; use poly6, cubic_spline, wendland_c2 or spiky",
            ));
        }
        if fluid.blocks.is_empty() && fluid.particles.is_empty() {
            return Err(SceneError::invalid(
                format!("{at}.blocks"),
                "is empty and so is `particles`; add at least one block of fluid",
            ));
        }
        for (i, particle) in fluid.particles.iter().enumerate() {
            check_vector(&format!("{at}.particles[{i}].velocity"), particle.velocity)?;
        }
        self.check_fluid_positions(fluid, fluid.particles.iter().map(|p| p.position), &|i| {
            format!("{at}.particles[{i}].position")
        })?;
        let domain = Aabb {
            min: self.domain.min,
            max: self.domain.max,
        };
        for (b, block) in fluid.blocks.iter().enumerate() {
            let field = format!("{at}.blocks[{b}]");
            check_box(&format!("{field}.region"), &block.region, self.dimension)?;
            check_vector(&format!("{field}.velocity"), block.velocity)?;
            if !domain.contains(&block.region, 1e-9 * fluid.spacing, self.dimension) {
                return Err(SceneError::invalid(
                    format!("{field}.region"),
                    "must lie inside the domain",
                ));
            }
            if fluid.lattice_dims(block, self.dimension).contains(&0.0) {
                return Err(SceneError::invalid(
                    format!("{field}.region"),
                    format!(
                        "holds no particle at spacing {}; make it at least one spacing wide on every axis",
                        fluid.spacing
                    ),
                ));
            }
            if let Some(o) = fluid.blocks[..b]
                .iter()
                .position(|other| other.region.overlaps(&block.region, self.dimension))
            {
                return Err(SceneError::invalid(
                    format!("{field}.region"),
                    format!("overlaps {at}.blocks[{o}]; particles would coincide"),
                ));
            }
        }
        let (min, max) = self.simulation_box(h);
        let periodic = self.periodic_axes();
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            let period = max[a] - min[a];
            let needed = UniformGrid::MIN_PERIODIC_CELLS as Real * h;
            if periodic[a] && period < needed {
                return Err(SceneError::invalid(
                    format!("periodic.{axis}"),
                    format!(
                        "the domain spans {period} m along {axis}, below {} support radii \
                         ({needed} m); widen the domain or make {axis} non-periodic",
                        UniformGrid::MIN_PERIODIC_CELLS
                    ),
                ));
            }
        }
        UniformGrid::with_periodic(min, max, h, periodic)
            .map_err(|e: GridError| SceneError::invalid("domain", e.to_string()))?;
        Ok(())
    }
}

fn default_rest_density() -> Real {
    defaults::REST_DENSITY
}
fn default_gamma() -> Real {
    defaults::GAMMA
}
fn default_negative_pressure_scale() -> Real {
    defaults::NEGATIVE_PRESSURE_SCALE
}
fn default_xsph() -> Real {
    defaults::XSPH
}
fn default_viscosity() -> Real {
    defaults::VISCOSITY
}
fn default_viscosity_model() -> ViscosityModel {
    defaults::VISCOSITY_MODEL
}
fn default_solver() -> SolverKind {
    defaults::SOLVER
}
fn default_density_tolerance() -> Real {
    defaults::DENSITY_TOLERANCE
}
fn default_divergence_tolerance() -> Real {
    defaults::DIVERGENCE_TOLERANCE
}
fn default_max_solver_iterations() -> u32 {
    defaults::MAX_SOLVER_ITERATIONS
}
fn default_walls() -> WallModel {
    defaults::WALLS
}
fn default_wall_slip() -> SlipKind {
    defaults::SLIP
}
fn default_density_kernel() -> KernelKind {
    defaults::DENSITY_KERNEL
}
fn default_gradient_kernel() -> KernelKind {
    defaults::GRADIENT_KERNEL
}
