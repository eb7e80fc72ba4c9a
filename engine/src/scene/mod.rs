//! The scene: a validated description of what a world simulates. Loaded
//! from TOML (`scenes/*.toml`) or converted from the protocol's `SceneSpec`
//! by the server; field names match the protocol.
//!
//! This module holds the scene as a whole (domain, time, output, the list
//! of systems), parsing and validation; one file per kind of system holds
//! that system's spec and checks: `fluid.rs`, `body.rs` (rigid bodies and
//! the shapes of bodies and solids), `solid.rs`; `error.rs` the error and
//! its range checks. The scene is data: it never imports the world.
//! [`Scene::build`] (in `world/build.rs`) validates everything first and
//! then creates only the systems and fields the scene names.

mod body;
mod budget;
mod error;
mod fluid;
mod footprint;
mod mesh;
mod modal_solid;
mod shell;
mod solid;
#[cfg(test)]
mod tests;

pub use crate::frame::FieldKind;
pub use body::{MotionKind, OscillationSpec, RigidBodySpec, ShapeSpec, SlipKind};
pub(crate) use body::{body_pose, body_shape, checked_shape, shape_axes, shape_pose};
pub use budget::Budget;
pub use error::SceneError;
pub use fluid::{FluidBlock, FluidSpec, ParticleSpec, SolverKind, WallModel, WallVelocities};
pub use footprint::Footprint;
pub use mesh::{DEFAULT_MAX_MESH_BYTES, MeshData, MeshFiles};
pub use modal_solid::{
    GrabSpec, MAX_MODES, MAX_NODES, ModalSolidSpec, PlaybackSpec, defaults as modal_defaults,
};
pub(crate) use shell::PreparedShell;
pub use shell::{MAX_NODES as MAX_SHELL_NODES, ShellSpec, defaults as shell_defaults};
pub(crate) use solid::SampledSolid;
pub use solid::{
    AnchorSpec, FractureSpec, IntegratorKind, NotchSpec, SolidSpec, SolidSurfaceSpec,
    defaults as solid_defaults,
};

use crate::approx::KernelKind;
use crate::cancel::Cancel;
use crate::efg::ModalSolid;
use crate::geometry::Shape;
use crate::geometry::read::parser_message;
use crate::math::Real;
use crate::surface::SurfaceExtractor;
use error::{check_box, check_positive, check_range, check_vector};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Defaults for every optional scene parameter, shared with the protocol
/// conversion so both front doors build the same world.
pub mod defaults {
    use crate::math::Real;

    /// Earth's, along -y, m/s^2.
    pub const GRAVITY: [Real; 3] = [0.0, -9.81, 0.0];
    /// Sub-steps a step may be split into.
    pub const MAX_SUBSTEPS: u32 = 256;
    /// Courant number of the fluid's stability limit.
    pub const CFL: Real = 0.4;
    /// Support radius as a multiple of the particle spacing.
    pub const SUPPORT_RATIO: Real = 2.0;
    /// Water's rest density, kg/m^3.
    pub const REST_DENSITY: Real = 1000.0;
    /// Tait exponent after Monaghan (Eq. 47).
    pub const GAMMA: Real = 7.0;
    /// Negative pressures clamped (Eq. 54 with zeta = 0).
    pub const NEGATIVE_PRESSURE_SCALE: Real = 0.0;
    /// No XSPH pass (Eq. 53): its velocity smoothing resists every
    /// deformation of the flow. On Monaghan's elliptical drop
    /// (tests/tests/validation_drop.rs) XSPH 0.1, the earlier default,
    /// widened the minor axis by 37 % of its exact change at a support of
    /// 2 spacings, against 21 % without it. A scene that wants the
    /// smoother particle order names it (the dam breaks do).
    pub const XSPH: Real = 0.0;
    /// A frame every step.
    pub const FRAME_EVERY: u32 = 1;
    /// Surface grid cell as a multiple of the particle spacing: two nodes
    /// per spacing resolve the half-spacing band the surface lies in.
    pub const SURFACE_CELL_RATIO: Real = 0.5;
    /// Colour-field level of the surface: halfway between inside (1) and
    /// outside (0), where the particles' volumes end.
    pub const SURFACE_ISO: Real = 0.5;
    /// No physical viscosity.
    pub const VISCOSITY: Real = 0.0;
    /// Monaghan's pair form conserves angular momentum and matches the
    /// analytic decay of a Taylor–Green vortex within a few per cent;
    /// Morris's matches the decay but exerts a torque; Eq. 52's kernel
    /// Laplacian dissipates too little (crate::fluid::ViscosityModel).
    pub const VISCOSITY_MODEL: crate::fluid::ViscosityModel =
        crate::fluid::ViscosityModel::Monaghan;
    /// The weakly compressible solver.
    pub const SOLVER: super::SolverKind = super::SolverKind::Wcsph;
    /// DFSPH: 0.1 % average density error.
    pub const DENSITY_TOLERANCE: Real = 0.001;
    /// DFSPH: 0.1 % average density change per sub-step.
    pub const DIVERGENCE_TOLERANCE: Real = 0.001;
    /// DFSPH: iteration cap of each solve.
    pub const MAX_SOLVER_ITERATIONS: u32 = 100;
    /// Solid walls (ghost layers, Eq. 55).
    pub const WALLS: super::WallModel = super::WallModel::Solid;
    /// Rigid bodies stay in place.
    pub const MOTION: super::MotionKind = super::MotionKind::Static;
    /// The fluid slides along bodies and the domain's walls.
    pub const SLIP: super::SlipKind = super::SlipKind::Free;
    /// The same kernel for densities and pressure gradients keeps the
    /// pressure force the gradient of the internal energy: an undamped
    /// fluid then neither gains nor loses energy, and a tank at rest holds
    /// `rho_0 g d` to 2 %. Müller's poly6/spiky pair (Algorithm 5) gains
    /// energy without XSPH or viscosity and steepens hydrostatic pressure
    /// by a quarter at `h = 2 dx` (tests/tests/validation_tank.rs).
    pub const DENSITY_KERNEL: super::KernelKind = super::KernelKind::CubicSpline;
    /// See [`DENSITY_KERNEL`].
    pub const GRADIENT_KERNEL: super::KernelKind = super::KernelKind::CubicSpline;
}

/// Limits a host puts on the worlds it builds, and the files it lets
/// scenes read.
#[derive(Debug, Clone)]
pub struct BuildOptions {
    /// Largest particle count a scene may create.
    pub max_particles: u64,
    /// Which mesh files a scene may name by path.
    pub mesh_files: MeshFiles,
    /// Largest mesh, file or inline, in bytes.
    pub max_mesh_bytes: u64,
    /// Raised to stop a check under way: a modal solid's precompute
    /// (octree, assembly, eigensolve) is the one long part of a check,
    /// and watches it between stages and inside the eigensolver. A host
    /// raises it when the client that asked has gone.
    pub cancel: Cancel,
    /// Where a modal solid's precompute reserves its estimated memory
    /// before it allocates it; by default nothing is reserved.
    pub budget: Budget,
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self {
            max_particles: 5_000_000,
            mesh_files: MeshFiles::Host,
            max_mesh_bytes: DEFAULT_MAX_MESH_BYTES,
            cancel: Cancel::new(),
            budget: Budget::default(),
        }
    }
}

/// An axis-aligned box.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Aabb {
    /// The lower corner, m.
    pub min: [Real; 3],
    /// The upper corner, m.
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

/// One physical system of a scene, tagged by its `kind`.
///
/// Deserialised by hand (see the `Deserialize` impl below) rather than by
/// serde's internally tagged enums, which buffer the table and so lose the
/// name of a field whose value has the wrong type.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SystemSpec {
    /// An SPH fluid (at most one per scene).
    Fluid(FluidSpec),
    /// A rigid body in the fluid, or a static obstacle for solids.
    RigidBody(RigidBodySpec),
    /// An elastic MLS solid.
    Solid(SolidSpec),
    /// An elastic solid in its lowest modes: Element-Free Galerkin on
    /// octree nodes with modal warping (Guo–Qin).
    ModalSolid(ModalSolidSpec),
    /// A thin Kirchhoff-Love shell on a conformal chart (Guo–Qin).
    Shell(ShellSpec),
}

impl SystemSpec {
    /// The kind as scene files spell it (`kind = "..."`).
    pub fn kind_name(&self) -> &'static str {
        match self {
            Self::Fluid(_) => "fluid",
            Self::RigidBody(_) => "rigid_body",
            Self::Solid(_) => "solid",
            Self::ModalSolid(_) => "modal_solid",
            Self::Shell(_) => "shell",
        }
    }

    /// The shape the system fills or is (a fluid fills blocks: none).
    pub fn shape(&self) -> Option<&ShapeSpec> {
        match self {
            Self::RigidBody(RigidBodySpec { shape, .. })
            | Self::Solid(SolidSpec { shape, .. })
            | Self::ModalSolid(ModalSolidSpec { shape, .. })
            | Self::Shell(ShellSpec { shape, .. }) => Some(shape),
            Self::Fluid(_) => None,
        }
    }

    /// The fluid, if this is one.
    pub fn as_fluid(&self) -> Option<&FluidSpec> {
        match self {
            Self::Fluid(fluid) => Some(fluid),
            Self::RigidBody(_) | Self::Solid(_) | Self::ModalSolid(_) | Self::Shell(_) => None,
        }
    }

    /// [`Self::as_fluid`], to change it.
    pub fn as_fluid_mut(&mut self) -> Option<&mut FluidSpec> {
        match self {
            Self::Fluid(fluid) => Some(fluid),
            Self::RigidBody(_) | Self::Solid(_) | Self::ModalSolid(_) | Self::Shell(_) => None,
        }
    }

    /// The elastic solid, if this is one.
    pub fn as_solid(&self) -> Option<&SolidSpec> {
        match self {
            Self::Solid(solid) => Some(solid),
            Self::Fluid(_) | Self::RigidBody(_) | Self::ModalSolid(_) | Self::Shell(_) => None,
        }
    }

    /// The modal solid, if this is one.
    pub fn as_modal_solid(&self) -> Option<&ModalSolidSpec> {
        match self {
            Self::ModalSolid(solid) => Some(solid),
            Self::Fluid(_) | Self::RigidBody(_) | Self::Solid(_) | Self::Shell(_) => None,
        }
    }

    /// The shell, if this is one.
    pub fn as_shell(&self) -> Option<&ShellSpec> {
        match self {
            Self::Shell(shell) => Some(shell),
            Self::Fluid(_) | Self::RigidBody(_) | Self::Solid(_) | Self::ModalSolid(_) => None,
        }
    }

    /// The rigid body, if this is one.
    pub fn as_rigid_body(&self) -> Option<&RigidBodySpec> {
        match self {
            Self::RigidBody(body) => Some(body),
            Self::Fluid(_) | Self::Solid(_) | Self::ModalSolid(_) | Self::Shell(_) => None,
        }
    }
}

impl<'de> Deserialize<'de> for SystemSpec {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        const KINDS: &[&str] = &["fluid", "rigid_body", "solid", "modal_solid", "shell"];
        let mut table = toml::Table::deserialize(deserializer)?;
        let kind = match table.remove("kind") {
            Some(toml::Value::String(kind)) => kind,
            Some(other) => {
                return Err(D::Error::custom(format!(
                    "`kind` must be a string ({}), got a {}",
                    KINDS.join(", "),
                    other.type_str()
                )));
            }
            None => return Err(D::Error::missing_field("kind")),
        };
        /// The spec in `table`, an error naming the path of the field
        /// that failed.
        fn spec<T: serde::de::DeserializeOwned, E: serde::de::Error>(
            table: toml::Table,
        ) -> Result<T, E> {
            serde_path_to_error::deserialize(toml::Value::Table(table)).map_err(|e| {
                let path = e.path().to_string();
                let inner = e.into_inner();
                if path == "." {
                    E::custom(inner.message())
                } else {
                    E::custom(format!("`{path}`: {}", inner.message()))
                }
            })
        }
        match kind.as_str() {
            "fluid" => spec(table).map(Self::Fluid),
            "rigid_body" => spec(table).map(Self::RigidBody),
            "solid" => spec(table).map(Self::Solid),
            "modal_solid" => spec(table).map(Self::ModalSolid),
            "shell" => spec(table).map(Self::Shell),
            _ => Err(D::Error::unknown_variant(&kind, KINDS)),
        }
    }
}

/// What a system's check reads of the scene around it: the dimension
/// and the domain, not the other systems.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SceneContext<'a> {
    /// 2 or 3.
    pub dimension: usize,
    /// The simulation domain.
    pub domain: &'a Aabb,
    /// m/s^2.
    pub gravity: crate::math::Vector,
    /// The scene's time step, s.
    pub dt: Real,
}

/// A validated scene with what validation made (each body's engine
/// shape, each solid's particles and surface, the memory estimate), ready
/// to build.
#[derive(Debug, Clone)]
pub struct Checked {
    pub(crate) scene: Scene,
    pub(crate) systems: Vec<Prepared>,
    footprint: Footprint,
}

/// What the check made of one system that its build takes over, so that
/// nothing is read, sampled or embedded twice.
#[derive(Debug, Clone, Default)]
pub(crate) enum Prepared {
    /// A fluid (built from its spec), or an entry already taken.
    #[default]
    Nothing,
    /// A rigid body's engine shape.
    Body(Shape),
    /// A solid's particles and embedded surface.
    Solid(SampledSolid),
    /// A modal solid, discretised and reduced.
    Modal(Box<ModalSolid>),
    /// A shell, discretised and at rest.
    Shell(Box<PreparedShell>),
}

impl Checked {
    /// The memory the built world will hold, by estimate.
    pub fn footprint(&self) -> Footprint {
        self.footprint
    }
}

/// Longest piece of a TOML parser's message a scene error repeats.
const MAX_PARSE_MESSAGE_CHARS: usize = 300;

/// A TOML error as a scene error says it: where (line and column) and
/// what, without the offending line itself (a 60 MB line would make a
/// 180 MB message), and with what to change when the file nests too deep.
fn toml_error(text: &str, error: &toml::de::Error) -> String {
    // The parser quotes unknown keys and values in full.
    let mut message = parser_message(error.message(), MAX_PARSE_MESSAGE_CHARS);
    if message.contains("recursion") || message.contains("recurse") {
        message.push_str(
            " (arrays or inline tables nested too deeply; a scene needs a few levels at most)",
        );
    }
    match error.span() {
        Some(span) => {
            let before = text.get(..span.start).unwrap_or(text);
            let line = before.matches('\n').count() + 1;
            let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            format!("TOML parse error at line {line}, column {column}: {message}")
        }
        None => format!("TOML parse error: {message}"),
    }
}

/// Longest scene name: names are listed back to every client, so one
/// client's megabyte name must not swell every other client's answers.
pub const MAX_NAME_CHARS: usize = 256;

/// A complete scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// A name for people, at most [`MAX_NAME_CHARS`] characters; the
    /// engine does not read it.
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
    /// Time stepping.
    pub time: TimeSpec,
    /// The physical systems, addressed by their index (`systems[k]`).
    pub systems: Vec<SystemSpec>,
    /// What frames carry.
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
fn default_frame_every() -> u32 {
    defaults::FRAME_EVERY
}
fn default_surface_iso() -> Real {
    defaults::SURFACE_ISO
}

impl Scene {
    /// Parses a scene from TOML text.
    ///
    /// # Errors
    /// [`SceneError::Parse`] with the line and key of the problem.
    pub fn from_toml_str(text: &str) -> Result<Self, SceneError> {
        toml::from_str(text).map_err(|e| SceneError::Parse(toml_error(text, &e)))
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
                SystemSpec::ModalSolid(solid) => &mut solid.shape,
                SystemSpec::Shell(shell) => &mut shell.shape,
                SystemSpec::Fluid(_) => continue,
            };
            if let ShapeSpec::Mesh {
                path: Some(mesh), ..
            } = shape
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
                        other => body_shape(other, dim, "").ok(),
                    };
                    let volume = shape.as_ref().and_then(|s| s.volume(dim)).unwrap_or(0.0);
                    volume / solid.spacing.powi(dim as i32)
                }
                // Its nodes are known once its octree (or quadtree) is
                // built.
                SystemSpec::ModalSolid(_) | SystemSpec::Shell(_) => 0.0,
            })
            .sum()
    }

    /// Checks every parameter against its allowed range and the host's
    /// limits, without allocating the world.
    ///
    /// # Errors
    /// The first problem found, naming its field.
    pub fn validate(&self, options: &BuildOptions) -> Result<(), SceneError> {
        self.clone().check(options).map(|_| ())
    }

    /// Loads every mesh file the scene names into the shape's `data`,
    /// under `options`' [`MeshFiles`] policy and size limit, so that
    /// nothing after this reads a file.
    ///
    /// # Errors
    /// [`SceneError::Invalid`] naming the shape's `path` or `data`.
    pub fn load_meshes(&mut self, options: &BuildOptions) -> Result<(), SceneError> {
        for (s, system) in self.systems.iter_mut().enumerate() {
            let shape = match system {
                SystemSpec::RigidBody(body) => &mut body.shape,
                SystemSpec::Solid(solid) => &mut solid.shape,
                SystemSpec::ModalSolid(solid) => &mut solid.shape,
                SystemSpec::Shell(shell) => &mut shell.shape,
                SystemSpec::Fluid(_) => continue,
            };
            shape.load_mesh(
                &options.mesh_files,
                options.max_mesh_bytes,
                &format!("systems[{s}].shape"),
            )?;
        }
        Ok(())
    }

    /// Loads the scene's mesh files ([`Self::load_meshes`]), validates
    /// every parameter and estimates the memory the built world will
    /// hold, so that a host can refuse a scene it has no room for before
    /// allocating anything; [`Checked::build`] then builds it without
    /// validating (or reading its meshes) again.
    ///
    /// # Errors
    /// As [`Self::validate`].
    pub fn check(mut self, options: &BuildOptions) -> Result<Checked, SceneError> {
        self.load_meshes(options)?;
        let (systems, footprint) = self.checked_systems(options)?;
        Ok(Checked {
            scene: self,
            systems,
            footprint,
        })
    }

    /// [`Self::validate`], keeping what it made of each system (by system
    /// index) for the build.
    pub(crate) fn checked_systems(
        &self,
        options: &BuildOptions,
    ) -> Result<(Vec<Prepared>, Footprint), SceneError> {
        let name_chars = self.name.chars().count();
        if name_chars > MAX_NAME_CHARS {
            return Err(SceneError::invalid(
                "name",
                format!("is {name_chars} characters long; keep it to {MAX_NAME_CHARS}"),
            ));
        }
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
        let context = self.context();
        let mut fluids = 0;
        let mut solid_particles = 0.0;
        let mut footprint = Footprint::default();
        let mut prepared = Vec::with_capacity(self.systems.len());
        for (s, system) in self.systems.iter().enumerate() {
            prepared.push(Prepared::Nothing);
            if let Some(shape) = system.shape()
                && let ShapeSpec::Mesh {
                    data: Some(data), ..
                } = shape
            {
                footprint.add_mesh(data.content.len());
            }
            match system {
                SystemSpec::Fluid(fluid) => {
                    fluids += 1;
                    if fluids > 1 {
                        return Err(SceneError::invalid(
                            format!("systems[{s}]"),
                            "a scene holds at most one fluid; put all its blocks into the first",
                        ));
                    }
                    self.validate_fluid(&format!("systems[{s}]"), fluid)?;
                    footprint.add_fluid(
                        fluid.particle_count(self.dimension),
                        fluid.support_radius() / fluid.spacing,
                        self.dimension,
                    );
                }
                SystemSpec::RigidBody(body) => {
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
                    let shape = self.validate_body(&format!("systems[{s}]"), body, fluid)?;
                    self.check_periodic_body(s, body, &shape, fluid)?;
                    prepared[s] = Prepared::Body(shape);
                }
                SystemSpec::Solid(solid) => {
                    let sampled =
                        solid.prepare(&format!("systems[{s}]"), &context, options.max_particles)?;
                    // Admitted for all it may grow to.
                    let count = solid.capacity(sampled.particles.len());
                    solid_particles += count as f64;
                    footprint.add_solid(
                        count as f64,
                        solid.support,
                        self.dimension,
                        matches!(solid.integrator, IntegratorKind::Implicit),
                    );
                    prepared[s] = Prepared::Solid(sampled);
                }
                SystemSpec::ModalSolid(spec) => {
                    let solid = spec.prepare(&format!("systems[{s}]"), &context, options)?;
                    solid_particles += solid.len() as f64;
                    footprint.add_modal_solid(&solid);
                    prepared[s] = Prepared::Modal(Box::new(solid));
                }
                SystemSpec::Shell(spec) => {
                    let shell = spec.prepare(&format!("systems[{s}]"), &context, options)?;
                    solid_particles += shell.dynamics.model().node_count() as f64;
                    footprint.add_shell(shell.dynamics.model().node_count(), shell.bytes());
                    prepared[s] = Prepared::Shell(Box::new(shell));
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
        // Formulas are evaluated at every particle: only once the count is
        // known to be within the limit (the fuzzer found a block of 10^19
        // particles with a velocity field trying to list them all).
        for (s, system) in self.systems.iter().enumerate() {
            if let SystemSpec::Fluid(fluid) = system {
                self.check_fields(&format!("systems[{s}]"), fluid)?;
            }
        }
        Ok((prepared, footprint))
    }

    /// What a system's check reads of the scene around it.
    pub(crate) fn context(&self) -> SceneContext<'_> {
        SceneContext {
            dimension: self.dimension,
            domain: &self.domain,
            gravity: crate::math::vector(self.gravity),
            dt: self.time.dt,
        }
    }

    /// The scene's fluid, if it has one.
    pub fn fluid(&self) -> Option<&FluidSpec> {
        self.systems.iter().find_map(SystemSpec::as_fluid)
    }

    /// Whether the scene holds an elastic solid.
    pub fn has_solids(&self) -> bool {
        self.systems
            .iter()
            .any(|s| matches!(s, SystemSpec::Solid(_) | SystemSpec::ModalSolid(_)))
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
}
