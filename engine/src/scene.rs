//! The scene: a validated description of what a world simulates. Loaded
//! from TOML (`scenes/*.toml`) or converted from the protocol's `SceneSpec`
//! by the server; field names match the protocol.
//!
//! [`Scene::build`] validates everything first and then creates only the
//! systems and fields the scene names.

use crate::approx::KernelKind;
use crate::fluid::ViscosityModel;
use crate::geometry::{MeshError, MeshSolid, Shape, TriMesh};
use crate::math::Real;
use crate::neighbors::{GridError, UniformGrid};
use crate::surface::SurfaceExtractor;
use crate::world::World;
use serde::{Deserialize, Serialize};
use std::path::Path;

mod solid;
pub(crate) use solid::build_solid;
pub use solid::{
    AnchorSpec, IntegratorKind, SolidSpec, SolidSurfaceSpec, defaults as solid_defaults,
};

/// Defaults for every optional scene parameter, shared with the protocol
/// conversion so both front doors build the same world.
pub mod defaults {
    use crate::math::Real;

    pub const GRAVITY: [Real; 3] = [0.0, -9.81, 0.0];
    pub const MAX_SUBSTEPS: u32 = 256;
    pub const CFL: Real = 0.4;
    /// Support radius as a multiple of the particle spacing.
    pub const SUPPORT_RATIO: Real = 2.0;
    pub const REST_DENSITY: Real = 1000.0;
    pub const GAMMA: Real = 7.0;
    pub const NEGATIVE_PRESSURE_SCALE: Real = 0.0;
    pub const XSPH: Real = 0.1;
    pub const FRAME_EVERY: u32 = 1;
    /// Surface grid cell as a multiple of the particle spacing: two nodes
    /// per spacing resolve the half-spacing band the surface lies in.
    pub const SURFACE_CELL_RATIO: Real = 0.5;
    /// Colour-field level of the surface: halfway between inside (1) and
    /// outside (0), where the particles' volumes end.
    pub const SURFACE_ISO: Real = 0.5;
    pub const VISCOSITY: Real = 0.0;
    /// Morris's form matches the analytic decay of a Taylor–Green vortex
    /// within a few per cent; Eq. 52's kernel Laplacian dissipates too
    /// little (crate::fluid::ViscosityModel).
    pub const VISCOSITY_MODEL: crate::fluid::ViscosityModel = crate::fluid::ViscosityModel::Morris;
    pub const SOLVER: super::SolverKind = super::SolverKind::Wcsph;
    pub const DENSITY_TOLERANCE: Real = 0.001;
    pub const DIVERGENCE_TOLERANCE: Real = 0.001;
    pub const MAX_SOLVER_ITERATIONS: u32 = 100;
    pub const WALLS: super::WallModel = super::WallModel::Solid;
    pub const MOTION: super::MotionKind = super::MotionKind::Static;
    pub const SLIP: super::SlipKind = super::SlipKind::Free;
    /// The same kernel for densities and pressure gradients keeps the
    /// pressure force the gradient of the internal energy: an undamped
    /// fluid then neither gains nor loses energy, and a tank at rest holds
    /// `rho_0 g d` to 2 %. Müller's poly6/spiky pair (Algorithm 5) gains
    /// energy without XSPH or viscosity and steepens hydrostatic pressure
    /// by a quarter at `h = 2 dx` (tests/tests/validation_tank.rs).
    pub const DENSITY_KERNEL: super::KernelKind = super::KernelKind::CubicSpline;
    pub const GRADIENT_KERNEL: super::KernelKind = super::KernelKind::CubicSpline;
}

/// Limits a host puts on the worlds it builds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BuildOptions {
    /// Largest particle count a scene may create.
    pub max_particles: u64,
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self {
            max_particles: 5_000_000,
        }
    }
}

/// Why a scene was rejected. Every variant names the offending field and
/// says what to change.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SceneError {
    /// A field is out of its allowed range.
    #[error("{field}: {message}")]
    Invalid { field: String, message: String },
    /// The scene would create more particles than the host allows.
    #[error(
        "the scene creates {count} particles, above this host's limit of {limit}; \
         increase `spacing` or shrink the fluid blocks"
    )]
    TooManyParticles { count: u64, limit: u64 },
    /// The scene file could not be read or parsed.
    #[error("{0}")]
    Parse(String),
}

impl SceneError {
    fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Invalid {
            field: field.into(),
            message: message.into(),
        }
    }

    /// Appends why the range is what it is.
    fn with_hint(self, hint: &str) -> Self {
        match self {
            Self::Invalid { field, message } => Self::Invalid {
                field,
                message: format!("{message} ({hint})"),
            },
            other => other,
        }
    }
}

/// An axis-aligned box.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Aabb {
    pub min: [Real; 3],
    pub max: [Real; 3],
}

impl Aabb {
    fn extent(&self, axis: usize) -> Real {
        self.max[axis] - self.min[axis]
    }

    fn contains(&self, other: &Aabb, tolerance: Real, dim: usize) -> bool {
        (0..dim).all(|a| {
            other.min[a] >= self.min[a] - tolerance && other.max[a] <= self.max[a] + tolerance
        })
    }

    fn overlaps(&self, other: &Aabb, dim: usize) -> bool {
        (0..dim).all(|a| self.min[a] < other.max[a] && other.min[a] < self.max[a])
    }
}

/// Time stepping.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeSpec {
    /// Time advanced by one step, seconds; split into sub-steps when above
    /// the stability limit.
    pub dt: Real,
    /// Upper bound on sub-steps per step.
    #[serde(default = "default_max_substeps")]
    pub max_substeps: u32,
    /// Courant number of the stability limit, in (0, 1].
    #[serde(default = "default_cfl")]
    pub cfl: Real,
}

/// A particle field a frame can carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FieldKind {
    Position,
    Velocity,
    Density,
    Pressure,
}

impl FieldKind {
    /// Scalars per particle.
    pub fn components(self) -> usize {
        match self {
            Self::Position | Self::Velocity => 3,
            Self::Density | Self::Pressure => 1,
        }
    }

    /// Lower-case name, as in scene files and exported files.
    pub fn name(self) -> &'static str {
        match self {
            Self::Position => "position",
            Self::Velocity => "velocity",
            Self::Density => "density",
            Self::Pressure => "pressure",
        }
    }
}

/// What frames carry and how often they are produced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSpec {
    /// Fields besides positions, which every frame carries.
    #[serde(default)]
    pub fields: Vec<FieldKind>,
    /// A frame every this many steps.
    #[serde(default = "default_frame_every")]
    pub frame_every: u32,
    /// The fluid's surface mesh in every frame; none when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface: Option<SurfaceSpec>,
}

impl Default for OutputSpec {
    fn default() -> Self {
        Self {
            fields: Vec::new(),
            frame_every: defaults::FRAME_EVERY,
            surface: None,
        }
    }
}

/// The fluid surface each frame carries: the iso-surface of the SPH colour
/// field, meshed by marching cubes (see [`crate::surface`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurfaceSpec {
    /// Grid cell, m; default half the fluid's particle spacing. Halving it
    /// gives four times the triangles and eight times the field nodes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cell: Option<Real>,
    /// Colour-field level of the surface, in (0, 1).
    #[serde(default = "default_surface_iso")]
    pub iso: Real,
}

impl SurfaceSpec {
    /// The grid cell, with its default for a fluid of `spacing` applied.
    pub fn cell(&self, spacing: Real) -> Real {
        self.cell.unwrap_or(defaults::SURFACE_CELL_RATIO * spacing)
    }
}

/// A box filled with fluid particles on a regular lattice.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FluidBlock {
    pub region: Aabb,
    /// Initial velocity, m/s.
    #[serde(default)]
    pub velocity: [Real; 3],
}

/// One particle placed by hand, besides the blocks' lattices.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParticleSpec {
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
    /// The pressure solver.
    #[serde(default = "default_solver")]
    pub solver: SolverKind,
    /// DFSPH: largest average density error accepted (fraction of rho_0).
    #[serde(default = "default_density_tolerance")]
    pub density_tolerance: Real,
    /// DFSPH: largest average density change per sub-step accepted by the
    /// divergence-free solve (fraction of rho_0).
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
    #[serde(default)]
    pub blocks: Vec<FluidBlock>,
    /// Single particles besides the blocks (a measured state, a velocity
    /// field); they take the blocks' particle mass.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub particles: Vec<ParticleSpec>,
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

/// One physical system of a scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SystemSpec {
    Fluid(FluidSpec),
    RigidBody(RigidBodySpec),
    Solid(SolidSpec),
}

/// The solid shape of a rigid body, in its body frame, centred on the
/// body's position (see [`crate::geometry::Shape`]). In 2D a shape stands
/// for its cross-section in the plane z = 0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeSpec {
    /// Half the side lengths, m (z ignored in 2D).
    Box {
        half_extents: [Real; 3],
    },
    Sphere {
        radius: Real,
    },
    /// A cylinder of length `2 half_length` along the body's y axis with
    /// hemispherical caps of `radius`.
    Capsule {
        half_length: Real,
        radius: Real,
    },
    /// The half-space `normal . x <= offset` in the body frame; `normal`
    /// points out of the solid (it need not be unit length).
    Plane {
        normal: [Real; 3],
        #[serde(default)]
        offset: Real,
    },
    /// A closed triangle mesh read from an OBJ or PLY file (3D only), its
    /// coordinates multiplied by `scale` (default 1). The body's
    /// `position` is where the mesh's centroid (its centre of mass) goes
    /// and `orientation` turns the mesh about it from the axes of the file.
    ///
    /// A relative `path` is taken from the directory of the scene file when
    /// the scene is read with [`Scene::from_toml_file`] (which rewrites it
    /// so), otherwise from the working directory of the process that builds
    /// the world; a server reads it on its own machine.
    Mesh {
        path: String,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        scale: Option<Real>,
    },
}

/// How a rigid body moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MotionKind {
    /// Fixed in place.
    Static,
    /// Prescribed: constant `velocity` and `angular_velocity` plus an
    /// optional `oscillation`, whatever the fluid does.
    Kinematic,
    /// Moved by gravity and the fluid, which it moves in turn; needs a
    /// `density`.
    Dynamic,
}

/// The tangential condition where the fluid meets a body.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SlipKind {
    /// The fluid slides along the surface freely.
    Free,
    /// The fluid sticks to the surface through a viscous wall term.
    No,
}

/// A prescribed displacement `amplitude sin(2 pi frequency t)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OscillationSpec {
    /// m, world frame.
    pub amplitude: [Real; 3],
    /// Hz.
    pub frequency: Real,
}

/// A rigid body in the fluid: a boundary the fluid cannot enter, sampled
/// with particles on its surface (Akinci et al. 2012). Needs a fluid in the
/// scene, whose spacing and kernels it uses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigidBodySpec {
    pub shape: ShapeSpec,
    /// Centre (of mass), m; z is ignored in 2D.
    pub position: [Real; 3],
    /// Rotation vector (axis times angle in radians) from the shape's
    /// frame to the world; in 2D only about z.
    #[serde(default)]
    pub orientation: [Real; 3],
    #[serde(default = "default_motion")]
    pub motion: MotionKind,
    /// kg/m^3; required by dynamic bodies, which take their mass and
    /// inertia from it and their shape.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub density: Option<Real>,
    /// Initial (dynamic) or constant (kinematic) velocity, m/s.
    #[serde(default)]
    pub velocity: [Real; 3],
    /// Initial (dynamic) or constant (kinematic) angular velocity about
    /// the centre, rad/s, world frame.
    #[serde(default)]
    pub angular_velocity: [Real; 3],
    /// Kinematic only: added to the path.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub oscillation: Option<OscillationSpec>,
    #[serde(default = "default_slip")]
    pub slip: SlipKind,
    /// Dynamic viscosity of the no-slip wall term, Pa s; default: the
    /// fluid's viscosity.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub viscosity: Option<Real>,
    /// The fluid fills the inside of the shape, which is then a container
    /// (static or kinematic only).
    #[serde(default)]
    pub hollow: bool,
}

/// A complete scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    #[serde(default)]
    pub name: String,
    /// 2 or 3. In 2D particles live in the plane z = 0 and the z extents
    /// of the domain and blocks are ignored.
    #[serde(default = "default_dimension")]
    pub dimension: usize,
    /// The simulation box; particles reflect off its walls.
    pub domain: Aabb,
    /// Periodic axes `[x, y, z]` of the domain: particles leaving through
    /// one face re-enter through the opposite one, and those axes have no
    /// walls. Ignored along z in 2D.
    #[serde(default, skip_serializing_if = "is_not_periodic")]
    pub periodic: [bool; 3],
    /// m/s^2.
    #[serde(default = "default_gravity")]
    pub gravity: [Real; 3],
    pub time: TimeSpec,
    pub systems: Vec<SystemSpec>,
    #[serde(default)]
    pub output: OutputSpec,
}

fn is_not_periodic(axes: &[bool; 3]) -> bool {
    !axes.contains(&true)
}
fn default_dimension() -> usize {
    3
}
fn default_gravity() -> [Real; 3] {
    defaults::GRAVITY
}
fn default_max_substeps() -> u32 {
    defaults::MAX_SUBSTEPS
}
fn default_cfl() -> Real {
    defaults::CFL
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
fn default_density_kernel() -> KernelKind {
    defaults::DENSITY_KERNEL
}
fn default_gradient_kernel() -> KernelKind {
    defaults::GRADIENT_KERNEL
}
fn default_frame_every() -> u32 {
    defaults::FRAME_EVERY
}
fn default_motion() -> MotionKind {
    defaults::MOTION
}
fn default_slip() -> SlipKind {
    defaults::SLIP
}
fn default_surface_iso() -> Real {
    defaults::SURFACE_ISO
}

/// Checks that `value` is finite and inside `[lo, hi]` (`hi` may be infinite).
fn check_range(field: &str, value: Real, lo: Real, hi: Real) -> Result<(), SceneError> {
    if !value.is_finite() {
        return Err(SceneError::invalid(
            field,
            format!("must be a finite number, got {value}"),
        ));
    }
    if value < lo || value > hi {
        let range = if hi.is_infinite() {
            format!(">= {lo}")
        } else {
            format!("in [{lo}, {hi}]")
        };
        return Err(SceneError::invalid(
            field,
            format!("must be {range}, got {value}"),
        ));
    }
    Ok(())
}

fn check_positive(field: &str, value: Real) -> Result<(), SceneError> {
    check_range(field, value, 0.0, Real::INFINITY)?;
    if value == 0.0 {
        return Err(SceneError::invalid(field, "must be > 0, got 0"));
    }
    Ok(())
}

fn check_vector(field: &str, v: [Real; 3]) -> Result<(), SceneError> {
    for (axis, value) in ["x", "y", "z"].iter().zip(v) {
        if !value.is_finite() {
            return Err(SceneError::invalid(
                format!("{field}.{axis}"),
                format!("must be a finite number, got {value}"),
            ));
        }
    }
    Ok(())
}

/// Checks a box in the first `dim` axes (in 2D its z extent is ignored).
fn check_box(field: &str, b: &Aabb, dim: usize) -> Result<(), SceneError> {
    check_vector(&format!("{field}.min"), b.min)?;
    check_vector(&format!("{field}.max"), b.max)?;
    for (a, axis) in ["x", "y", "z"].iter().enumerate().take(dim) {
        if b.max[a] <= b.min[a] {
            return Err(SceneError::invalid(
                field,
                format!(
                    "is empty: max.{axis} ({}) must exceed min.{axis} ({})",
                    b.max[a], b.min[a]
                ),
            ));
        }
    }
    Ok(())
}

/// Reads the mesh of a `shape = { type = "mesh" }` at field `at`, scales
/// it and puts it in its principal frame. Every failure names
/// `{at}.path` (or `{at}` for a bad mesh) and the file it tried.
pub(crate) fn mesh_shape(path: &str, scale: Option<Real>, at: &str) -> Result<Shape, SceneError> {
    let field = format!("{at}.path");
    let file = Path::new(path);
    let mut mesh = TriMesh::from_path(file).map_err(|e| {
        let tried = std::path::absolute(file).unwrap_or_else(|_| file.to_path_buf());
        SceneError::invalid(
            &field,
            format!("cannot load the mesh (tried {}): {e}", tried.display()),
        )
    })?;
    let scale = scale.unwrap_or(1.0);
    for v in &mut mesh.vertices {
        *v *= scale;
    }
    let solid = MeshSolid::new(&mesh).map_err(|e| {
        let what = match e {
            MeshError::NotClosed {
                boundary,
                non_manifold,
                misoriented,
            } => format!(
                "{path}: the mesh must be closed to bound a solid, but {} edges are open \
                 ({boundary} boundary, {non_manifold} non-manifold, {misoriented} misoriented); \
                 close the holes, weld duplicated vertices and orient the faces outward",
                boundary + non_manifold + misoriented
            ),
            other => format!("{path}: {other}"),
        };
        SceneError::invalid(&field, what)
    })?;
    Ok(Shape::Mesh(solid))
}

impl Scene {
    /// Parses a scene from TOML text.
    ///
    /// # Errors
    /// [`SceneError::Parse`] with the line and key of the problem.
    pub fn from_toml_str(text: &str) -> Result<Self, SceneError> {
        toml::from_str(text).map_err(|e| SceneError::Parse(e.to_string()))
    }

    /// Reads and parses a scene file.
    ///
    /// # Errors
    /// [`SceneError::Parse`] naming the file.
    ///
    /// Relative mesh paths (`shape = { type = "mesh", path = ... }`) are
    /// resolved against the scene file's directory, so a scene finds its
    /// meshes wherever it is run from.
    pub fn from_toml_file(path: &Path) -> Result<Self, SceneError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| SceneError::Parse(format!("cannot read {}: {e}", path.display())))?;
        let mut scene = Self::from_toml_str(&text)
            .map_err(|e| SceneError::Parse(format!("{}: {e}", path.display())))?;
        let base = path.parent().unwrap_or(Path::new(""));
        for system in &mut scene.systems {
            let shape = match system {
                SystemSpec::RigidBody(body) => &mut body.shape,
                SystemSpec::Solid(solid) => &mut solid.shape,
                SystemSpec::Fluid(_) => continue,
            };
            if let ShapeSpec::Mesh { path: mesh, .. } = shape
                && Path::new(mesh.as_str()).is_relative()
            {
                *mesh = base.join(mesh.as_str()).to_string_lossy().into_owned();
            }
        }
        Ok(scene)
    }

    /// The scene as TOML text.
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# cannot serialise scene: {e}"))
    }

    /// Total particle count over all systems.
    pub fn particle_count(&self) -> f64 {
        self.systems
            .iter()
            .map(|s| match s {
                SystemSpec::Fluid(f) => f.particle_count(self.dimension),
                SystemSpec::RigidBody(_) => 0.0,
                // The volume over the lattice cell, or the bounding cube's
                // count for a mesh, whose volume needs its file.
                SystemSpec::Solid(solid) => {
                    let dim = self.dimension;
                    let shape = match &solid.shape {
                        ShapeSpec::Mesh { .. } => None,
                        other => crate::world::body_shape(other, dim, "").ok(),
                    };
                    let volume = shape.as_ref().and_then(|s| s.volume(dim)).unwrap_or(0.0);
                    volume / solid.spacing.powi(dim as i32)
                }
            })
            .sum()
    }

    /// Checks every parameter against its allowed range and the host's
    /// limits, without allocating the world.
    ///
    /// # Errors
    /// The first problem found, naming its field.
    pub fn validate(&self, options: &BuildOptions) -> Result<(), SceneError> {
        self.checked_shapes(options).map(|_| ())
    }

    /// [`Self::validate`], keeping the engine shape of each rigid body
    /// (by system index; `None` for other systems), so that a mesh file is
    /// read once per build.
    fn checked_shapes(&self, options: &BuildOptions) -> Result<Vec<Option<Shape>>, SceneError> {
        if !(self.dimension == 2 || self.dimension == 3) {
            return Err(SceneError::invalid(
                "dimension",
                format!("must be 2 or 3, got {}", self.dimension),
            ));
        }
        check_box("domain", &self.domain, self.dimension)?;
        check_vector("gravity", self.gravity)?;
        check_positive("time.dt", self.time.dt)?;
        if self.time.max_substeps == 0 || self.time.max_substeps > 1_000_000 {
            return Err(SceneError::invalid(
                "time.max_substeps",
                format!("must be in [1, 1000000], got {}", self.time.max_substeps),
            ));
        }
        check_positive("time.cfl", self.time.cfl)?;
        check_range("time.cfl", self.time.cfl, 0.0, 1.0)?;
        if self.output.frame_every == 0 {
            return Err(SceneError::invalid(
                "output.frame_every",
                "must be >= 1, got 0",
            ));
        }
        if self.systems.is_empty() {
            return Err(SceneError::invalid(
                "systems",
                "is empty; name at least one system (kind = \"fluid\")",
            ));
        }
        let mut fluids = 0;
        let mut solid_particles = 0.0;
        let mut shapes = Vec::with_capacity(self.systems.len());
        for (s, system) in self.systems.iter().enumerate() {
            shapes.push(None);
            match system {
                SystemSpec::Fluid(fluid) => {
                    fluids += 1;
                    if fluids > 1 {
                        return Err(SceneError::invalid(
                            format!("systems[{s}]"),
                            "a scene holds at most one fluid; put all its blocks into the first",
                        ));
                    }
                    self.validate_fluid(&format!("systems[{s}]"), fluid)?
                }
                SystemSpec::RigidBody(body) => {
                    if self.periodic_axes().contains(&true) {
                        return Err(SceneError::invalid(
                            format!("systems[{s}]"),
                            "rigid bodies do not wrap around periodic faces; make the domain \
                             non-periodic (periodic = [false, false, false]) or remove the body",
                        ));
                    }
                    let fluid = self.fluid();
                    if fluid.is_none() && !(self.has_solids() && body.motion == MotionKind::Static)
                    {
                        return Err(SceneError::invalid(
                            format!("systems[{s}]"),
                            "a rigid body is a boundary of the fluid and takes its spacing and \
                             kernels from it; add a system with kind = \"fluid\" (without a \
                             fluid, a static body is an obstacle for solids)",
                        ));
                    }
                    shapes[s] = Some(self.validate_body(&format!("systems[{s}]"), body, fluid)?);
                }
                SystemSpec::Solid(solid) => {
                    let (shape, count) = self.validate_solid(&format!("systems[{s}]"), solid)?;
                    solid_particles += count as f64;
                    shapes[s] = Some(shape);
                }
            }
        }
        if let Some(surface) = &self.output.surface {
            self.validate_surface(surface)?;
        }
        let count = self
            .fluid()
            .map_or(0.0, |f| f.particle_count(self.dimension))
            + solid_particles;
        if count > options.max_particles as f64 {
            return Err(SceneError::TooManyParticles {
                count: count.min(u64::MAX as f64) as u64,
                limit: options.max_particles,
            });
        }
        Ok(shapes)
    }

    /// The scene's fluid, if it has one.
    pub fn fluid(&self) -> Option<&FluidSpec> {
        self.systems.iter().find_map(|s| match s {
            SystemSpec::Fluid(f) => Some(f),
            SystemSpec::RigidBody(_) | SystemSpec::Solid(_) => None,
        })
    }

    /// Whether the scene holds an elastic solid.
    pub fn has_solids(&self) -> bool {
        self.systems
            .iter()
            .any(|s| matches!(s, SystemSpec::Solid(_)))
    }

    /// Checks a shape's parameters and makes its engine shape (reading
    /// its mesh).
    fn checked_shape(&self, shape_at: &str, spec: &ShapeSpec) -> Result<Shape, SceneError> {
        checked_shape(shape_at, spec, self.dimension)
    }

    /// Checks a rigid body and makes its engine shape (reading its mesh).
    /// Without a fluid the body is a static obstacle for solids.
    fn validate_body(
        &self,
        at: &str,
        body: &RigidBodySpec,
        fluid: Option<&FluidSpec>,
    ) -> Result<Shape, SceneError> {
        let dim = self.dimension;
        let planar = dim == 2;
        let shape_at = format!("{at}.shape");
        let shape = self.checked_shape(&shape_at, &body.shape)?;
        if let (Shape::Mesh(solid), Some(fluid)) = (&shape, fluid) {
            let candidates = crate::geometry::surface_candidates(solid.area(), fluid.spacing);
            if candidates > crate::geometry::MAX_SAMPLES as Real {
                return Err(SceneError::invalid(
                    format!("{shape_at}.path"),
                    format!(
                        "the mesh's surface ({} m^2) is too large to sample at the fluid's \
                         spacing {} m; scale it down or raise the spacing",
                        solid.area(),
                        fluid.spacing
                    ),
                ));
            }
        }
        check_vector(&format!("{at}.position"), body.position)?;
        check_vector(&format!("{at}.orientation"), body.orientation)?;
        check_vector(&format!("{at}.velocity"), body.velocity)?;
        check_vector(&format!("{at}.angular_velocity"), body.angular_velocity)?;
        if planar {
            for (field, v) in [
                ("orientation", body.orientation),
                ("angular_velocity", body.angular_velocity),
            ] {
                if v[0] != 0.0 || v[1] != 0.0 {
                    return Err(SceneError::invalid(
                        format!("{at}.{field}"),
                        "in 2D a body only turns about z; set x and y to 0",
                    ));
                }
            }
        }
        let plane = matches!(body.shape, ShapeSpec::Plane { .. });
        let domain_diagonal = (0..dim)
            .map(|a| self.domain.extent(a).powi(2))
            .sum::<Real>()
            .sqrt();
        if !plane {
            let inside = (0..dim).all(|a| {
                body.position[a] > self.domain.min[a] && body.position[a] < self.domain.max[a]
            });
            if !inside {
                return Err(SceneError::invalid(
                    format!("{at}.position"),
                    format!("{:?} must lie inside the domain", body.position),
                ));
            }
            let size = shape.bounding_radius(dim);
            if size > domain_diagonal {
                return Err(SceneError::invalid(
                    shape_at,
                    format!(
                        "reaches {size} m from its centre, beyond the domain's diagonal \
                         ({domain_diagonal} m); make it smaller"
                    ),
                ));
            }
        } else {
            // The plane must cut the domain, or it has no surface there.
            let pose = crate::world::body_pose(body, &shape, dim);
            let corners = (0..1 << dim).map(|c: usize| {
                crate::math::Vector::from_fn(|a, _| {
                    if a >= dim {
                        0.0
                    } else if c >> a & 1 == 1 {
                        self.domain.max[a]
                    } else {
                        self.domain.min[a]
                    }
                })
            });
            let sides: Vec<Real> = corners
                .map(|x| {
                    let local = pose.1.inverse_transform_vector(&(x - pose.0));
                    shape.signed_distance(&local, dim)
                })
                .collect();
            if sides.iter().all(|&d| d < 0.0) || sides.iter().all(|&d| d > 0.0) {
                return Err(SceneError::invalid(
                    at,
                    "the plane misses the domain (every corner lies on one side); move it \
                     with position or shape.offset",
                ));
            }
        }
        let moving = body.velocity != [0.0; 3]
            || body.angular_velocity != [0.0; 3]
            || body.oscillation.is_some();
        match body.motion {
            MotionKind::Static => {
                if moving {
                    return Err(SceneError::invalid(
                        format!("{at}.motion"),
                        "a static body has no velocity, angular velocity or oscillation; \
                         use motion = \"kinematic\" to prescribe them",
                    ));
                }
            }
            MotionKind::Kinematic => {
                if let Some(o) = &body.oscillation {
                    check_vector(&format!("{at}.oscillation.amplitude"), o.amplitude)?;
                    check_positive(&format!("{at}.oscillation.frequency"), o.frequency)?;
                }
                if plane && body.angular_velocity != [0.0; 3] {
                    return Err(SceneError::invalid(
                        format!("{at}.angular_velocity"),
                        "a plane is infinite and cannot turn; set it to 0",
                    ));
                }
            }
            MotionKind::Dynamic => {
                if plane {
                    return Err(SceneError::invalid(
                        format!("{at}.motion"),
                        "a plane is infinite and has no mass; make it static or kinematic",
                    ));
                }
                if body.hollow {
                    return Err(SceneError::invalid(
                        format!("{at}.hollow"),
                        "a hollow body (a container) can be static or kinematic, not dynamic",
                    ));
                }
                if body.oscillation.is_some() {
                    return Err(SceneError::invalid(
                        format!("{at}.oscillation"),
                        "only kinematic bodies follow an oscillation",
                    ));
                }
                let Some(density) = body.density else {
                    return Err(SceneError::invalid(
                        format!("{at}.density"),
                        "is required by a dynamic body (kg/m^3; water is 1000)",
                    ));
                };
                check_positive(&format!("{at}.density"), density)?;
                // Lighter than this, the explicit coupling is stiff beyond any
                // sub-step: the body's acceleration outruns the fluid's.
                let rest_density = fluid.map_or(solid_defaults::DENSITY, |f| f.rest_density);
                check_range(&format!("{at}.density"), density, 1e-3 * rest_density, 1e6)?;
            }
        }
        if body.motion != MotionKind::Dynamic && body.density.is_some() {
            return Err(SceneError::invalid(
                format!("{at}.density"),
                "only dynamic bodies have a density; remove it or set motion = \"dynamic\"",
            ));
        }
        if let Some(mu) = body.viscosity {
            check_range(&format!("{at}.viscosity"), mu, 0.0, 1e4)?;
        }
        let fluid_viscosity = fluid.map_or(0.0, |f| f.viscosity);
        if body.slip == SlipKind::No && body.viscosity.unwrap_or(fluid_viscosity) <= 0.0 {
            return Err(SceneError::invalid(
                format!("{at}.viscosity"),
                "no-slip needs a viscosity (Pa s) for its wall term: set it here or the \
                 fluid's viscosity",
            ));
        }
        Ok(shape)
    }

    /// The surface needs a 3D fluid, a positive cell, an iso value inside
    /// (0, 1) and a grid over the domain within the node limit.
    fn validate_surface(&self, surface: &SurfaceSpec) -> Result<(), SceneError> {
        if self.dimension != 3 {
            return Err(SceneError::invalid(
                "output.surface",
                "surfaces are meshed in 3D only (marching cubes); remove it or set dimension = 3",
            ));
        }
        let Some(fluid) = self.fluid() else {
            return Err(SceneError::invalid(
                "output.surface",
                "the scene has no fluid to mesh",
            ));
        };
        if let Some(cell) = surface.cell {
            check_positive("output.surface.cell", cell)?;
        }
        if !(surface.iso > 0.0 && surface.iso < 1.0) {
            return Err(SceneError::invalid(
                "output.surface.iso",
                format!(
                    "must lie strictly between 0 and 1 (1 inside the fluid, 0 outside), got {}",
                    surface.iso
                ),
            ));
        }
        let kernel = crate::approx::Kernel::new(
            fluid.density_kernel,
            self.dimension,
            fluid.support_radius(),
        );
        let (min, max) = self.simulation_box(fluid.support_radius());
        SurfaceExtractor::new(kernel, surface.cell(fluid.spacing), surface.iso, min, max)
            .map_err(|e| SceneError::invalid("output.surface.cell", e.to_string()))?;
        Ok(())
    }

    fn validate_fluid(&self, at: &str, fluid: &FluidSpec) -> Result<(), SceneError> {
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
        match fluid.solver {
            SolverKind::Wcsph => {
                check_positive(&format!("{at}.stiffness"), fluid.stiffness).map_err(
                    |e| match e {
                        SceneError::Invalid { field, message } => SceneError::Invalid {
                            field,
                            message: format!(
                                "{message} (the wcsph solver needs the Tait stiffness)"
                            ),
                        },
                        other => other,
                    },
                )?;
                // Water's bulk modulus is 2.2e9 Pa; beyond 1e12 the explicit
                // sub-steps would be needlessly tiny and pressures overflow frames.
                check_range(&format!("{at}.stiffness"), fluid.stiffness, 0.0, 1e12)?;
            }
            SolverKind::Dfsph => {
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
            }
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
            let field = format!("{at}.particles[{i}]");
            check_vector(&format!("{field}.position"), particle.position)?;
            check_vector(&format!("{field}.velocity"), particle.velocity)?;
            let outside = (0..self.dimension).find(|&a| {
                particle.position[a] < self.domain.min[a]
                    || particle.position[a] > self.domain.max[a]
            });
            if let Some(a) = outside {
                let axis = ["x", "y", "z"][a];
                return Err(SceneError::invalid(
                    format!("{field}.position"),
                    format!(
                        "lies outside the domain: {axis} = {} is not in [{}, {}]; move the particle \
                         inside or widen the domain",
                        particle.position[a], self.domain.min[a], self.domain.max[a]
                    ),
                ));
            }
        }
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

    /// The periodic axes in effect: those the scene names, less z in 2D.
    pub fn periodic_axes(&self) -> [bool; 3] {
        let mut axes = self.periodic;
        if self.dimension == 2 {
            axes[2] = false;
        }
        axes
    }

    /// The box particles stay in. In 2D its z extent is `[-h, h]` around
    /// the plane z = 0, whatever the scene says, so nothing acts along z.
    pub fn simulation_box(
        &self,
        support_radius: Real,
    ) -> (crate::math::Vector, crate::math::Vector) {
        let (mut min, mut max) = (
            crate::math::vector(self.domain.min),
            crate::math::vector(self.domain.max),
        );
        if self.dimension == 2 {
            min.z = -support_radius;
            max.z = support_radius;
        }
        (min, max)
    }

    /// Validates the scene and builds its world: only the systems and
    /// fields the scene names.
    ///
    /// # Errors
    /// See [`Scene::validate`].
    pub fn build(&self, options: &BuildOptions) -> Result<World, SceneError> {
        let shapes = self.checked_shapes(options)?;
        Ok(World::new(self.clone(), shapes))
    }
}

/// Checks a shape's parameters and makes its engine shape (reading
/// its mesh).
pub(crate) fn checked_shape(
    shape_at: &str,
    spec: &ShapeSpec,
    dim: usize,
) -> Result<Shape, SceneError> {
    let planar = dim == 2;
    match spec {
        ShapeSpec::Box { half_extents } => {
            check_vector(&format!("{shape_at}.half_extents"), *half_extents)?;
            for (a, axis) in ["x", "y", "z"].iter().enumerate().take(dim) {
                check_positive(&format!("{shape_at}.half_extents.{axis}"), half_extents[a])?;
            }
        }
        ShapeSpec::Sphere { radius } => check_positive(&format!("{shape_at}.radius"), *radius)?,
        ShapeSpec::Capsule {
            half_length,
            radius,
        } => {
            check_positive(&format!("{shape_at}.radius"), *radius)?;
            check_range(
                &format!("{shape_at}.half_length"),
                *half_length,
                0.0,
                Real::INFINITY,
            )?;
        }
        ShapeSpec::Plane { normal, offset } => {
            check_vector(&format!("{shape_at}.normal"), *normal)?;
            check_range(&format!("{shape_at}.offset"), *offset, Real::MIN, Real::MAX)?;
            let in_plane = if planar { 2 } else { 3 };
            if normal[..in_plane].iter().all(|&c| c == 0.0) {
                return Err(SceneError::invalid(
                    format!("{shape_at}.normal"),
                    "must not be zero: it is the direction out of the solid",
                ));
            }
            if planar && normal[2] != 0.0 {
                return Err(SceneError::invalid(
                    format!("{shape_at}.normal"),
                    format!("must lie in the plane in 2D (z = 0), got z = {}", normal[2]),
                ));
            }
        }
        ShapeSpec::Mesh { scale, .. } => {
            if planar {
                return Err(SceneError::invalid(
                    shape_at,
                    "mesh bodies are 3D only; set dimension = 3 or use a box, sphere, \
                     capsule or plane",
                ));
            }
            if let Some(scale) = scale {
                check_positive(&format!("{shape_at}.scale"), *scale)?;
            }
        }
    }
    crate::world::body_shape(spec, dim, shape_at)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = r#"
        name = "small"
        [domain]
        min = [0.0, 0.0, 0.0]
        max = [1.0, 1.0, 1.0]
        [time]
        dt = 0.01
        [[systems]]
        kind = "fluid"
        spacing = 0.1
        stiffness = 1000.0
        [[systems.blocks]]
        region = { min = [0.0, 0.0, 0.0], max = [0.5, 0.5, 0.5] }
    "#;

    fn small() -> Scene {
        Scene::from_toml_str(SMALL).expect("valid scene")
    }

    fn rejected_field(scene: &Scene) -> String {
        match scene.validate(&BuildOptions::default()) {
            Err(SceneError::Invalid { field, .. }) => field,
            other => panic!("expected an invalid field, got {other:?}"),
        }
    }

    fn fluid(scene: &mut Scene) -> &mut FluidSpec {
        match &mut scene.systems[0] {
            SystemSpec::Fluid(f) => f,
            SystemSpec::RigidBody(_) | SystemSpec::Solid(_) => {
                panic!("the first system is the fluid")
            }
        }
    }

    #[test]
    fn toml_defaults_are_applied() {
        let scene = small();
        assert_eq!(scene.gravity, defaults::GRAVITY);
        assert_eq!(scene.time.max_substeps, defaults::MAX_SUBSTEPS);
        let mut s = scene.clone();
        let f = fluid(&mut s);
        assert_eq!(f.support_radius(), 0.2);
        assert_eq!(f.gamma, defaults::GAMMA);
        assert_eq!(scene.particle_count(), 125.0);
        assert_eq!(f.lattice(3).count(), 125);
        assert_eq!(f.lattice(2).count(), 25);
        assert!(f.lattice(2).all(|(x, _)| x[2] == 0.0));
    }

    #[test]
    fn toml_round_trips() {
        let scene = small();
        let again = Scene::from_toml_str(&scene.to_toml_string()).expect("round trip");
        assert_eq!(scene, again);
    }

    /// Each kind of bad value is rejected with the path of its field.
    #[test]
    fn bad_values_name_their_field() {
        let mut s = small();
        fluid(&mut s).spacing = -1.0;
        assert_eq!(rejected_field(&s), "systems[0].spacing");

        let mut s = small();
        fluid(&mut s).support_radius = Some(Real::NAN);
        assert_eq!(rejected_field(&s), "systems[0].support_radius");

        let mut s = small();
        fluid(&mut s).support_radius = Some(0.0);
        assert_eq!(rejected_field(&s), "systems[0].support_radius");

        let mut s = small();
        s.domain.max[1] = s.domain.min[1];
        assert_eq!(rejected_field(&s), "domain");

        let mut s = small();
        s.gravity[2] = Real::INFINITY;
        assert_eq!(rejected_field(&s), "gravity.z");

        let mut s = small();
        s.time.dt = 0.0;
        assert_eq!(rejected_field(&s), "time.dt");

        let mut s = small();
        fluid(&mut s).blocks[0].region.max = [2.0, 0.5, 0.5];
        assert_eq!(rejected_field(&s), "systems[0].blocks[0].region");

        let mut s = small();
        let block = fluid(&mut s).blocks[0].clone();
        fluid(&mut s).blocks.push(block);
        assert_eq!(rejected_field(&s), "systems[0].blocks[1].region");

        let mut s = small();
        fluid(&mut s).particles.push(ParticleSpec {
            position: [0.5, 1.5, 0.5],
            velocity: [0.0; 3],
        });
        assert_eq!(rejected_field(&s), "systems[0].particles[0].position");

        let mut s = small();
        fluid(&mut s).particles.push(ParticleSpec {
            position: [0.5, 0.5, 0.5],
            velocity: [0.0, Real::NAN, 0.0],
        });
        assert_eq!(rejected_field(&s), "systems[0].particles[0].velocity.y");

        // Three support radii (0.6 m) fit in the 1 m box; 0.5 m does not.
        let mut s = small();
        s.periodic = [false, true, false];
        assert!(s.validate(&BuildOptions::default()).is_ok());
        s.domain.max[1] = 0.5;
        fluid(&mut s).blocks[0].region.max[1] = 0.5;
        assert_eq!(rejected_field(&s), "periodic.y");

        let mut s = small();
        s.systems.clear();
        assert_eq!(rejected_field(&s), "systems");

        let mut s = small();
        s.domain.max = [1e6, 1e6, 1e6];
        assert_eq!(rejected_field(&s), "domain");
    }

    /// The stiffness is the WCSPH solver's knob: required there, not for
    /// DFSPH, whose own knobs are range-checked instead.
    #[test]
    fn each_solver_checks_its_own_knobs() {
        let mut s = small();
        fluid(&mut s).stiffness = 0.0;
        assert_eq!(rejected_field(&s), "systems[0].stiffness");
        fluid(&mut s).solver = SolverKind::Dfsph;
        s.validate(&BuildOptions::default())
            .expect("DFSPH needs no stiffness");
        fluid(&mut s).density_tolerance = 0.0;
        assert_eq!(rejected_field(&s), "systems[0].density_tolerance");
        fluid(&mut s).density_tolerance = 0.001;
        fluid(&mut s).max_solver_iterations = 0;
        assert_eq!(rejected_field(&s), "systems[0].max_solver_iterations");
    }

    #[test]
    fn particle_limit_is_enforced_before_allocation() {
        let mut s = small();
        fluid(&mut s).spacing = 0.001;
        fluid(&mut s).support_radius = Some(0.004);
        let err = s
            .validate(&BuildOptions {
                max_particles: 1000,
            })
            .expect_err("limit");
        assert!(
            matches!(err, SceneError::TooManyParticles { limit: 1000, .. }),
            "{err}"
        );
    }

    fn with_body(body: &str) -> Scene {
        Scene::from_toml_str(&format!(
            "{SMALL}\n[[systems]]\nkind = \"rigid_body\"\n{body}"
        ))
        .expect("parses")
    }

    /// A valid body builds; each bad body spec is rejected naming its
    /// field, with the scene path of the body (systems[1]).
    #[test]
    fn bad_bodies_name_their_field() {
        let ball = "shape = { type = \"sphere\", radius = 0.1 }\nposition = [0.7, 0.7, 0.7]";
        let s = with_body(&format!("{ball}\nmotion = \"dynamic\"\ndensity = 500.0"));
        let world = s.build(&BuildOptions::default()).expect("valid body");
        assert_eq!(world.frame().bodies.len(), 1);
        assert_eq!(
            Scene::from_toml_str(&s.to_toml_string()).expect("round trip"),
            s
        );
        let mut periodic = s.clone();
        periodic.periodic = [true, false, false];
        assert_eq!(rejected_field(&periodic), "systems[1]");

        let cases = [
            (
                "shape = { type = \"sphere\", radius = 0.0 }\nposition = [0.5, 0.5, 0.5]",
                "systems[1].shape.radius",
            ),
            (
                "shape = { type = \"box\", half_extents = [0.1, -0.1, 0.1] }\nposition = [0.5, 0.5, 0.5]",
                "systems[1].shape.half_extents.y",
            ),
            (
                "shape = { type = \"capsule\", half_length = -1.0, radius = 0.1 }\nposition = [0.5, 0.5, 0.5]",
                "systems[1].shape.half_length",
            ),
            (
                "shape = { type = \"plane\", normal = [0.0, 0.0, 0.0] }\nposition = [0.5, 0.1, 0.5]",
                "systems[1].shape.normal",
            ),
            (
                "shape = { type = \"plane\", normal = [0.0, 1.0, 0.0] }\nposition = [0.5, 2.0, 0.5]",
                "systems[1]",
            ),
            (
                "shape = { type = \"sphere\", radius = 0.1 }\nposition = [1.5, 0.5, 0.5]",
                "systems[1].position",
            ),
            (
                "shape = { type = \"sphere\", radius = 10.0 }\nposition = [0.5, 0.5, 0.5]",
                "systems[1].shape",
            ),
            (
                &format!("{ball}\nmotion = \"dynamic\""),
                "systems[1].density",
            ),
            (
                &format!("{ball}\nmotion = \"dynamic\"\ndensity = -1.0"),
                "systems[1].density",
            ),
            (&format!("{ball}\ndensity = 500.0"), "systems[1].density"),
            (
                &format!("{ball}\nvelocity = [1.0, 0.0, 0.0]"),
                "systems[1].motion",
            ),
            (
                &format!("{ball}\nmotion = \"dynamic\"\ndensity = 500.0\nhollow = true"),
                "systems[1].hollow",
            ),
            (
                &format!(
                    "{ball}\nmotion = \"kinematic\"\noscillation = {{ amplitude = [0.1, 0.0, 0.0], frequency = 0.0 }}"
                ),
                "systems[1].oscillation.frequency",
            ),
            (&format!("{ball}\nslip = \"no\""), "systems[1].viscosity"),
            (
                &format!("{ball}\norientation = [0.0, 0.0, nan]"),
                "systems[1].orientation.z",
            ),
            (
                "shape = { type = \"plane\", normal = [0.0, 1.0, 0.0] }\nposition = [0.5, 0.1, 0.5]\nmotion = \"dynamic\"\ndensity = 1.0",
                "systems[1].motion",
            ),
        ];
        for (body, field) in cases {
            assert_eq!(rejected_field(&with_body(body)), field, "{body}");
        }

        let mut planar = with_body(&format!("{ball}\norientation = [0.3, 0.0, 0.0]"));
        planar.dimension = 2;
        assert_eq!(rejected_field(&planar), "systems[1].orientation");

        // A body without a fluid.
        let mut lonely = with_body(ball);
        lonely.systems.remove(0);
        assert_eq!(rejected_field(&lonely), "systems[0]");
        // An unknown shape key is a parse error naming it.
        let err = Scene::from_toml_str(&format!(
            "{SMALL}\n[[systems]]\nkind = \"rigid_body\"\nshape = {{ type = \"sphere\", radius = 0.1, radios = 1.0 }}\nposition = [0.5, 0.5, 0.5]"
        ))
        .expect_err("unknown key");
        assert!(err.to_string().contains("radios"), "{err}");
    }

    /// A surface is optional, defaults its cell to half the spacing, and
    /// names its field when out of range, in 2D or too fine for the domain.
    #[test]
    fn surfaces_are_validated() {
        let text = SMALL.replace("[time]", "[output]\nsurface = {}\n[time]");
        let s = Scene::from_toml_str(&text).expect("surface with defaults");
        let surface = s.output.surface.clone().expect("a surface");
        assert_eq!((surface.cell(0.1), surface.iso), (0.05, 0.5));
        s.validate(&BuildOptions::default()).expect("valid");
        assert_eq!(
            Scene::from_toml_str(&s.to_toml_string()).expect("round trip"),
            s
        );
        assert_eq!(small().output.surface, None);

        let with = |cell: Option<Real>, iso: Real| {
            let mut s = s.clone();
            s.output.surface = Some(SurfaceSpec { cell, iso });
            s
        };
        assert_eq!(rejected_field(&with(Some(0.0), 0.5)), "output.surface.cell");
        assert_eq!(
            rejected_field(&with(Some(Real::NAN), 0.5)),
            "output.surface.cell"
        );
        assert_eq!(rejected_field(&with(None, 1.0)), "output.surface.iso");
        assert_eq!(rejected_field(&with(None, 0.0)), "output.surface.iso");
        let err = with(Some(1e-4), 0.5)
            .validate(&BuildOptions::default())
            .expect_err("10^12 nodes");
        assert!(err.to_string().starts_with("output.surface.cell:"), "{err}");
        assert!(err.to_string().contains("limit"), "{err}");

        let mut flat = s.clone();
        flat.dimension = 2;
        let err = flat.validate(&BuildOptions::default()).expect_err("2D");
        assert!(err.to_string().contains("3D only"), "{err}");
    }

    #[test]
    fn unknown_systems_and_keys_are_parse_errors() {
        let text = SMALL.replace("kind = \"fluid\"", "kind = \"plasma\"");
        let err = Scene::from_toml_str(&text).expect_err("unknown system");
        assert!(err.to_string().contains("plasma"), "{err}");

        let text = SMALL.replace("stiffness = 1000.0", "stiffness = 1000.0\nstifness = 1.0");
        let err = Scene::from_toml_str(&text).expect_err("unknown key");
        assert!(err.to_string().contains("stifness"), "{err}");
    }
}
