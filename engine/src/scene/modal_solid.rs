//! Modal EFG solids in a scene (Guo–Qin): the TOML/protocol description,
//! its validation, and the build of the engine body, which the check
//! does (the discretisation and eigen-analysis are its admission: a
//! scene whose supports leave a point uncovered is refused before a
//! world exists).

use super::error::{check_box, check_positive, check_range, check_vector};
use super::{Aabb, BuildOptions, SceneContext, SceneError, ShapeSpec};
use crate::approx::mls::Order;
use crate::efg::{
    Anchor, Dynamics, EfgError, EfgParams, FixedSurface, Grab, MassForm, Material, ModalParams,
    ModalSolid, Pose, SkinInput,
};
use crate::geometry::read::{self, MeshFormat};
use crate::geometry::{Ball, ImplicitSurface, MeshSdf, PointSurface, PointSurfaceParams, TriMesh};
use crate::math::{Real, Vector, bounds, vector};
use crate::modal::{Damping, Stabilization};
use nalgebra::Rotation3;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Defaults of the optional modal-solid parameters, shared with the
/// protocol conversion.
pub mod defaults {
    use crate::math::Real;

    /// Support side over octant side: Guo–Qin's choice (Section 4.1.1).
    pub const ALPHA: Real = 3.0;
    /// Gauss points per axis of an integration cell.
    pub const QUADRATURE_ORDER: u32 = 2;
    /// Integration cells per axis of an octant.
    pub const SUBDIVISION: u32 = 2;
    /// Boundary octants cut no finer than interior ones.
    pub const BOUNDARY_REFINEMENT: u32 = 1;
    /// Penalty of fixed regions in units of `E / cell`.
    pub const PENALTY: Real = 1e4;
    /// Guo–Qin Table 1's beam keeps 64.
    pub const MODES: u32 = 64;
    /// Relative accuracy of the eigenpairs.
    pub const EIGEN_TOLERANCE: Real = 1e-10;
    /// Baumgarte rates of the grabs, 1/s: critical (`eta = gamma`), a
    /// violated grab closes with time constant 1/20 s.
    pub const GRAB_RATE: Real = 20.0;
    /// Faces of a box split 4 times (3,072 triangles), a sphere's
    /// icosahedron 4 times (5,120).
    pub const SURFACE_SUBDIVISIONS: u32 = 4;
}

/// Most nodes a modal solid's octree may place, by the estimate made
/// before building it: the eigen-analysis of 3n unknowns is the dearest
/// part of an admission, and a session waits for it.
pub const MAX_NODES: u64 = 200_000;

/// Most modes kept: beyond that the per-step cost is no longer the
/// "reduced" one the method is for.
pub const MAX_MODES: u32 = 1024;

/// A mode shape played back instead of the dynamics: the solid is posed
/// at `amplitude sin(omega t)` of the mode (a rigid mode at 1 Hz).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlaybackSpec {
    /// The mode, 0-based in ascending frequency (a free body's first six
    /// are rigid).
    pub mode: u32,
    /// Its peak amplitude (modes are mass-normalised: kg^-1/2).
    pub amplitude: Real,
}

/// A held material point: its position, orientation or both
/// (Section 5.3.3), in the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GrabSpec {
    /// The material point (rest shape), m.
    pub point: [Real; 3],
    /// Where it should go, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position: Option<[Real; 3]>,
    /// Rotation vector it should turn by (axis times angle), rad.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation: Option<[Real; 3]>,
}

impl GrabSpec {
    /// The engine's grab.
    pub fn grab(&self) -> Grab {
        Grab {
            point: vector(self.point),
            position: self.position.map(vector),
            rotation: self.rotation.map(vector),
        }
    }
}

/// An elastic solid discretised by Element-Free Galerkin on octree nodes
/// and simulated in its lowest modes, with modal warping (Guo–Qin
/// Sections 3-5). Every field that trades speed for accuracy is here:
/// `cell` (octree depth, hence nodes), `alpha`, `basis`,
/// `quadrature_order`, `subdivision`, `boundary_refinement`, `mass`,
/// `modes`, `warping`, and the scene's `time.dt`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModalSolidSpec {
    /// A box, a sphere, a closed mesh (OBJ or PLY) or an oriented point
    /// cloud (a PLY with normals and no faces).
    pub shape: ShapeSpec,
    /// Where the shape's centre goes, m.
    pub position: [Real; 3],
    /// Rotation vector of the shape, rad.
    #[serde(default)]
    pub orientation: [Real; 3],
    /// kg/m^3.
    #[serde(default = "default_density")]
    pub density: Real,
    /// Young's modulus, Pa.
    pub young: Real,
    /// Poisson's ratio, in [0, 0.5).
    #[serde(default = "default_poisson")]
    pub poisson: Real,
    /// Side of the octants at the surface, m: the resolution.
    pub cell: Real,
    /// Levels by which interior octants may be coarser.
    #[serde(default)]
    pub interior_levels: u32,
    /// Support side over octant side.
    #[serde(default = "default_alpha")]
    pub alpha: Real,
    /// MLS basis: linear or quadratic. The quadratic one needs three
    /// layers of nodes under every point: with it raise `alpha` (4.5
    /// builds a box, whose corners at 3 see 2 x 2 x 2 nodes).
    #[serde(default = "default_basis")]
    pub basis: Order,
    /// Gauss points per axis of an integration cell, 1 to 5.
    #[serde(default = "default_quadrature_order")]
    pub quadrature_order: u32,
    /// Integration cells per axis of an octant.
    #[serde(default = "default_subdivision")]
    pub subdivision: u32,
    /// How many times finer boundary octants are cut.
    #[serde(default = "default_boundary_refinement")]
    pub boundary_refinement: u32,
    /// Consistent or lumped mass.
    #[serde(default = "default_mass")]
    pub mass: MassForm,
    /// Penalty of the anchors, in units of `E / cell`.
    #[serde(default = "default_penalty")]
    pub penalty: Real,
    /// `"modal"` (the default: the lowest modes with warping, cheap per
    /// step, linear strain) or `"nonlinear"` (the full EFG state under
    /// Green's strain, Guo–Qin Section 5.1: exact large deformation,
    /// Newton steps; `modes`, `eigen_tolerance`, `warping` and `playback`
    /// do not apply, and grabs hold positions only).
    #[serde(default)]
    pub dynamics: Dynamics,
    /// Modes kept.
    #[serde(default = "default_modes")]
    pub modes: u32,
    /// Relative accuracy of the eigenpairs.
    #[serde(default = "default_eigen_tolerance")]
    pub eigen_tolerance: Real,
    /// Modal warping (large rotations) or linear modes.
    #[serde(default = "default_warping")]
    pub warping: bool,
    /// Rayleigh damping `a` of `C = a M + b K`, 1/s.
    #[serde(default)]
    pub mass_damping: Real,
    /// Rayleigh damping `b` of `C = a M + b K`, s.
    #[serde(default)]
    pub stiffness_damping: Real,
    /// Baumgarte damping `eta` of the grabs, 1/s.
    #[serde(default = "default_grab_rate")]
    pub grab_eta: Real,
    /// Baumgarte stiffness `gamma` of the grabs, 1/s.
    #[serde(default = "default_grab_rate")]
    pub grab_gamma: Real,
    /// Boxes (world frame): the solid's surface inside them is held.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub anchors: Vec<Aabb>,
    /// Points held from the start.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub grabs: Vec<GrabSpec>,
    /// Plays a mode shape back instead of simulating.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub playback: Option<PlaybackSpec>,
    /// Subdivisions of a box's or a sphere's surface carried in frames (a
    /// mesh or point cloud carries its own).
    #[serde(default = "default_surface_subdivisions")]
    pub surface_subdivisions: u32,
}

fn default_density() -> Real {
    super::solid_defaults::DENSITY
}
fn default_poisson() -> Real {
    super::solid_defaults::POISSON
}
fn default_alpha() -> Real {
    defaults::ALPHA
}
fn default_basis() -> Order {
    Order::Linear
}
fn default_quadrature_order() -> u32 {
    defaults::QUADRATURE_ORDER
}
fn default_subdivision() -> u32 {
    defaults::SUBDIVISION
}
fn default_boundary_refinement() -> u32 {
    defaults::BOUNDARY_REFINEMENT
}
fn default_mass() -> MassForm {
    MassForm::Consistent
}
fn default_penalty() -> Real {
    defaults::PENALTY
}
fn default_modes() -> u32 {
    defaults::MODES
}
fn default_eigen_tolerance() -> Real {
    defaults::EIGEN_TOLERANCE
}
fn default_warping() -> bool {
    true
}
fn default_grab_rate() -> Real {
    defaults::GRAB_RATE
}
fn default_surface_subdivisions() -> u32 {
    defaults::SURFACE_SUBDIVISIONS
}

/// The geometry of a modal solid in the world frame: the implicit
/// surface its octree adapts to and its skin (for a mesh, the mesh itself,
/// whose triangles anchors cut; for a box or a sphere, display only).
struct Geometry {
    implicit: Box<dyn ImplicitSurface>,
    skin: SkinInput,
    /// `(min, max)` of the shape (of its points, for a cloud).
    bounds: (Vector, Vector),
}

impl ModalSolidSpec {
    /// The discretisation and reduced-model parameters.
    pub fn params(&self) -> Result<ModalParams, SceneError> {
        let mut efg = EfgParams::new(self.cell);
        efg.interior_levels = self.interior_levels;
        efg.alpha = self.alpha;
        efg.basis = self.basis;
        efg.quadrature_order = self.quadrature_order as usize;
        efg.subdivision = self.subdivision as usize;
        efg.boundary_refinement = self.boundary_refinement as usize;
        efg.mass = self.mass;
        efg.penalty = self.penalty;
        Ok(ModalParams {
            dynamics: self.dynamics,
            efg,
            modes: self.modes as usize,
            tolerance: self.eigen_tolerance,
            warping: self.warping,
            damping: Damping::new(self.mass_damping, self.stiffness_damping)
                .map_err(|e| SceneError::invalid("mass_damping", e.to_string()))?,
            stabilization: Stabilization::new(self.grab_eta, self.grab_gamma)
                .map_err(|e| SceneError::invalid("grab_eta", e.to_string()))?,
        })
    }

    fn material(&self) -> Material {
        Material {
            density: self.density,
            young: self.young,
            poisson: self.poisson,
        }
    }

    /// The pose that takes the shape's own frame to the world.
    fn pose(&self) -> (Vector, Rotation3<Real>) {
        (
            vector(self.position),
            Rotation3::new(vector(self.orientation)),
        )
    }

    /// The shape in the world frame. A mesh is centred on its bounding
    /// box's centre before it is placed.
    fn geometry(&self, at: &str) -> Result<Geometry, SceneError> {
        let (centre, rotation) = self.pose();
        let place = |v: &Vector| centre + rotation * v;
        let shape_at = format!("{at}.shape");
        let (vertices, triangles, normals): (Vec<Vector>, Vec<[u32; 3]>, Vec<Vector>) = match &self
            .shape
        {
            ShapeSpec::Box { half_extents } => {
                let h = vector(*half_extents);
                let m = TriMesh::cuboid(-h, h).subdivided(self.surface_subdivisions);
                (m.vertices, m.triangles, Vec::new())
            }
            ShapeSpec::Sphere { radius } => {
                let m = TriMesh::icosphere(Vector::zeros(), *radius, self.surface_subdivisions);
                (m.vertices, m.triangles, Vec::new())
            }
            ShapeSpec::Capsule { .. } | ShapeSpec::Plane { .. } => {
                return Err(SceneError::invalid(
                    shape_at,
                    "a modal solid is a box, a sphere, a closed mesh or an oriented point \
                         cloud (PLY with normals)",
                ));
            }
            ShapeSpec::Mesh { path, data, scale } => {
                let label = path.clone().unwrap_or_else(|| format!("{shape_at}.data"));
                let Some(data) = data else {
                    return Err(SceneError::invalid(
                        format!("{shape_at}.path"),
                        "the mesh was not loaded; load it first (`Scene::check` does)",
                    ));
                };
                let scale = scale.unwrap_or(1.0);
                let mesh = read::parse(Path::new(&label), data.format, &data.content);
                match mesh {
                    Ok(loaded) if !loaded.mesh.triangles.is_empty() => (
                        loaded.mesh.vertices.iter().map(|v| v * scale).collect(),
                        loaded.mesh.triangles,
                        Vec::new(),
                    ),
                    mesh if data.format == MeshFormat::Ply => {
                        let cloud = read::parse_oriented_points(Path::new(&label), &data.content)
                            .map_err(|e| {
                            let mesh = mesh
                                .err()
                                .map_or_else(|| "it has no faces".to_owned(), |m| m.to_string());
                            SceneError::invalid(
                                format!("{shape_at}.data"),
                                format!(
                                    "{label} is neither a closed mesh ({mesh}) nor an \
                                             oriented point cloud ({e})"
                                ),
                            )
                        })?;
                        (
                            cloud.points.iter().map(|v| v * scale).collect(),
                            Vec::new(),
                            cloud.normals,
                        )
                    }
                    Ok(_) => {
                        return Err(SceneError::invalid(
                            format!("{shape_at}.data"),
                            format!(
                                "{label} has no faces; a point cloud must be a PLY with normals"
                            ),
                        ));
                    }
                    Err(e) => {
                        return Err(SceneError::invalid(
                            format!("{shape_at}.data"),
                            format!("cannot load the mesh: {e}"),
                        ));
                    }
                }
            }
        };
        // Centre meshes and clouds on their bounding box.
        let (min, max) = bounds(&vertices);
        let middle = match self.shape {
            ShapeSpec::Mesh { .. } => (min + max) / 2.0,
            _ => Vector::zeros(),
        };
        let vertices: Vec<Vector> = vertices.iter().map(|v| place(&(v - middle))).collect();
        let normals: Vec<Vector> = normals
            .iter()
            .map(|n| rotation * n.try_normalize(0.0).unwrap_or_default())
            .collect();
        let bounds = bounds(&vertices);
        let field = format!("{shape_at}.data");
        // A box or a sphere is its exact shape, whatever its display
        // surface's resolution: that is only what frames carry.
        let closed = |mesh: &TriMesh| {
            MeshSdf::new(mesh).map_err(|e| {
                SceneError::invalid(
                    &field,
                    format!("the surface must be closed to bound a solid: {e}"),
                )
            })
        };
        let (implicit, normals): (Box<dyn ImplicitSurface>, Vec<Vector>) = match &self.shape {
            ShapeSpec::Box { half_extents } => {
                let h = vector(*half_extents);
                let mut cuboid = TriMesh::cuboid(-h, h);
                cuboid.vertices.iter_mut().for_each(|v| *v = place(v));
                (Box::new(closed(&cuboid)?), Vec::new())
            }
            ShapeSpec::Sphere { radius } => (
                Box::new(Ball {
                    centre,
                    radius: *radius,
                }),
                Vec::new(),
            ),
            _ if triangles.is_empty() => {
                let cloud = PointSurface::new(&vertices, &normals, PointSurfaceParams::default())
                    .map_err(|e| SceneError::invalid(&field, e.to_string()))?;
                (Box::new(cloud), normals)
            }
            _ => {
                let mesh = TriMesh {
                    vertices: vertices.clone(),
                    triangles: triangles.clone(),
                };
                (Box::new(closed(&mesh)?), Vec::new())
            }
        };
        let bounds = match self.shape {
            ShapeSpec::Box { .. } | ShapeSpec::Sphere { .. } => implicit.bounds(),
            _ => bounds,
        };
        let normals = if normals.is_empty() {
            vec![Vector::zeros(); vertices.len()]
        } else {
            normals
        };
        Ok(Geometry {
            implicit,
            skin: SkinInput {
                vertices,
                triangles,
                normals,
            },
            bounds,
        })
    }

    /// The anchored part of the solid's own boundary, anchor by anchor:
    /// a box's faces or a sphere inside the anchor box, by the rule sized by
    /// `cell` ([`FixedSurface::of_box_in_box`]); a mesh's own triangles
    /// (the mesh is the geometry, and its skin is that mesh untouched)
    /// with all three corners inside; a point cloud's points inside, each
    /// standing for `spacing^2`. Never the display surface of a box or a
    /// sphere, whose `surface_subdivisions` is an output resolution.
    ///
    /// # Errors
    /// An anchor that holds none of the boundary (it would hold nothing,
    /// and a free body is not what it asks for), or whose part needs more
    /// points than [`crate::efg::MAX_FIXED_POINTS`].
    fn fixed(
        &self,
        at: &str,
        geometry: &Geometry,
        params: &EfgParams,
    ) -> Result<FixedSurface, SceneError> {
        let (centre, rotation) = self.pose();
        let pose = Pose {
            centre: &centre,
            rotation: &rotation,
        };
        let skin = &geometry.skin;
        let mesh = matches!(self.shape, ShapeSpec::Mesh { .. }).then(|| TriMesh {
            vertices: skin.vertices.clone(),
            triangles: skin.triangles.clone(),
        });
        let mut fixed = FixedSurface::default();
        for (k, anchor) in self.anchors.iter().enumerate() {
            let field = format!("{at}.anchors[{k}]");
            let (min, max) = (vector(anchor.min), vector(anchor.max));
            let inside = Anchor {
                min: &min,
                max: &max,
            };
            let part = match &self.shape {
                ShapeSpec::Box { half_extents } => {
                    FixedSurface::of_box_in_box(&vector(*half_extents), pose, inside, params)
                }
                ShapeSpec::Sphere { radius } => {
                    FixedSurface::of_sphere_in_box(*radius, pose, inside, params)
                }
                _ if skin.triangles.is_empty() => {
                    let area = point_area(&skin.vertices, &geometry.bounds);
                    let points: Vec<Vector> = skin
                        .vertices
                        .iter()
                        .filter(|v| (0..3).all(|j| v[j] >= min[j] && v[j] <= max[j]))
                        .copied()
                        .collect();
                    Ok(FixedSurface {
                        areas: vec![area; points.len()],
                        points,
                    })
                }
                _ => Ok(mesh.as_ref().map_or_else(FixedSurface::default, |mesh| {
                    FixedSurface::of_mesh_in_box(mesh, &min, &max)
                })),
            }
            .map_err(|e| SceneError::invalid(&field, e.to_string()))?;
            if part.area() <= 0.0 {
                let (lo, hi) = geometry.bounds;
                return Err(SceneError::invalid(
                    field,
                    format!(
                        "holds none of the solid's surface, so it would hold nothing; move it \
                         to overlap the surface (the solid spans [{:.4}, {:.4}, {:.4}] to \
                         [{:.4}, {:.4}, {:.4}] m) or remove it",
                        lo.x, lo.y, lo.z, hi.x, hi.y, hi.z
                    ),
                ));
            }
            fixed.points.extend(part.points);
            fixed.areas.extend(part.areas);
        }
        Ok(fixed)
    }
}

/// The area a point of a cloud stands for: the bounding box's surface
/// over the point count, a fair share for a cloud that samples its
/// surface evenly (the penalty only needs its scale).
fn point_area(points: &[Vector], (min, max): &(Vector, Vector)) -> Real {
    let d = max - min;
    2.0 * (d.x * d.y + d.y * d.z + d.z * d.x) / points.len().max(1) as Real
}

impl ModalSolidSpec {
    /// Checks the modal solid against `context` and builds it: the
    /// octree, the EFG assembly and the modes, the expensive part of its
    /// admission.
    pub(super) fn prepare(
        &self,
        at: &str,
        context: &SceneContext,
        options: &BuildOptions,
    ) -> Result<ModalSolid, SceneError> {
        let spec = self;
        if context.dimension != 3 {
            return Err(SceneError::invalid(
                at,
                "modal solids are 3D only; set dimension = 3",
            ));
        }
        let field = |name: &str| format!("{at}.{name}");
        if let ShapeSpec::Box { .. } | ShapeSpec::Sphere { .. } = spec.shape {
            super::checked_shape(&field("shape"), &spec.shape, 3)?;
        }
        if let ShapeSpec::Mesh {
            scale: Some(scale), ..
        } = spec.shape
        {
            check_positive(&field("shape.scale"), scale)?;
        }
        check_vector(&field("position"), spec.position)?;
        check_vector(&field("orientation"), spec.orientation)?;
        check_positive(&field("density"), spec.density)?;
        check_range(&field("density"), spec.density, 1e-3, 1e6)?;
        check_positive(&field("young"), spec.young)?;
        check_range(&field("young"), spec.young, 0.0, 1e13)?;
        check_range(&field("poisson"), spec.poisson, 0.0, 0.4999)
            .map_err(|e| e.with_hint("0.5 is incompressible, which Hooke's law cannot hold"))?;
        check_positive(&field("cell"), spec.cell)?;
        check_range(&field("alpha"), spec.alpha, 2.0, 6.0).map_err(|e| {
            e.with_hint("below 2 a point may be covered by fewer supports than the basis needs")
        })?;
        if spec.basis == Order::Constant {
            return Err(SceneError::invalid(
                field("basis"),
                "a constant basis has no strain; use \"linear\" or \"quadratic\"",
            ));
        }
        for (name, value, max) in [
            ("quadrature_order", spec.quadrature_order, 5),
            ("subdivision", spec.subdivision, 8),
            ("boundary_refinement", spec.boundary_refinement, 8),
        ] {
            if value == 0 || value > max {
                return Err(SceneError::invalid(
                    field(name),
                    format!("must be in [1, {max}], got {value}"),
                ));
            }
        }
        if spec.interior_levels > 8 {
            return Err(SceneError::invalid(
                field("interior_levels"),
                format!("must be in [0, 8], got {}", spec.interior_levels),
            ));
        }
        check_positive(&field("penalty"), spec.penalty)?;
        check_range(&field("penalty"), spec.penalty, 0.0, 1e8)?;
        if spec.modes == 0 || spec.modes > MAX_MODES {
            return Err(SceneError::invalid(
                field("modes"),
                format!("must be in [1, {MAX_MODES}], got {}", spec.modes),
            ));
        }
        check_positive(&field("eigen_tolerance"), spec.eigen_tolerance)?;
        check_range(&field("eigen_tolerance"), spec.eigen_tolerance, 0.0, 1e-2)?;
        for (name, value) in [
            ("mass_damping", spec.mass_damping),
            ("stiffness_damping", spec.stiffness_damping),
            ("grab_eta", spec.grab_eta),
            ("grab_gamma", spec.grab_gamma),
        ] {
            check_range(&field(name), value, 0.0, 1e6)?;
        }
        if spec.surface_subdivisions > 7 {
            return Err(SceneError::invalid(
                field("surface_subdivisions"),
                format!("must be in [0, 7], got {}", spec.surface_subdivisions),
            ));
        }
        if spec.dynamics == Dynamics::Nonlinear {
            if spec.playback.is_some() {
                return Err(SceneError::invalid(
                    field("playback"),
                    "plays a mode back, but `dynamics = \"nonlinear\"` computes no modes; use \
                     `dynamics = \"modal\"` or drop the playback",
                ));
            }
            if let Some(k) = spec.grabs.iter().position(|g| g.rotation.is_some()) {
                return Err(SceneError::invalid(
                    field(&format!("grabs[{k}].rotation")),
                    "`dynamics = \"nonlinear\"` holds grabbed positions only (as stiff \
                     springs); hold two or three points instead, or use `dynamics = \"modal\"`",
                ));
            }
        }
        if let Some(playback) = &spec.playback {
            if playback.mode >= spec.modes {
                return Err(SceneError::invalid(
                    field("playback.mode"),
                    format!(
                        "is {}, but the solid keeps {} modes (0 to {})",
                        playback.mode,
                        spec.modes,
                        spec.modes - 1
                    ),
                ));
            }
            check_range(&field("playback.amplitude"), playback.amplitude, -1e6, 1e6)?;
        }
        let geometry = spec.geometry(at)?;
        let (min, max) = geometry.bounds;
        let extent = max - min;
        // Nodes sit at most one per octant of side `cell` over the
        // bounding box (interior octants are that or coarser).
        let nodes = (0..3)
            .map(|k| (extent[k] / spec.cell).ceil().max(1.0))
            .product::<Real>();
        let limit = MAX_NODES.min(options.max_particles);
        if nodes > limit as Real {
            return Err(SceneError::TooFine {
                field: field("cell"),
                points: nodes.min(u64::MAX as Real) as u64,
                limit,
            });
        }
        for a in 0..3 {
            if min[a] < context.domain.min[a] || max[a] > context.domain.max[a] {
                return Err(SceneError::invalid(
                    field("position"),
                    "the solid reaches outside the domain; move it or enlarge the domain",
                ));
            }
        }
        for (k, anchor) in spec.anchors.iter().enumerate() {
            check_box(&format!("{at}.anchors[{k}]"), anchor, 3)?;
        }
        let params = spec.params()?;
        let fixed = spec.fixed(at, &geometry, &params.efg)?;
        // The host reserves the estimate once the octree stands, before
        // the quadrature, shape functions and matrices are allocated.
        let mut solid = ModalSolid::build_admitted(
            geometry.implicit.as_ref(),
            &fixed,
            spec.material(),
            &params,
            Some(geometry.skin),
            &options.cancel,
            &|estimate| options.budget.reserve(estimate.bytes),
        )
        .map_err(|e| match e {
            _ if e.is_cancelled() => SceneError::Cancelled,
            EfgError::Refused { .. } => SceneError::OverBudget {
                field: at.to_owned(),
                message: e.to_string(),
            },
            _ => SceneError::invalid(at, e.to_string()),
        })?;
        let grabs: Vec<Grab> = spec.grabs.iter().map(GrabSpec::grab).collect();
        solid
            .set_grabs(&grabs)
            .map_err(|e| SceneError::invalid(field("grabs"), e.to_string()))?;
        Ok(solid)
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Scene, SystemSpec};
    use super::*;

    fn beam(cell: Real) -> Scene {
        let text = format!(
            r#"
            [domain]
            min = [-0.05, -0.3, -0.1]
            max = [0.3, 0.1, 0.1]
            [time]
            dt = 0.02
            [[systems]]
            kind = "modal_solid"
            shape = {{ type = "box", half_extents = [0.08, 0.02, 0.02] }}
            position = [0.08, 0.0, 0.0]
            young = 1.0e5
            cell = {cell}
            "#
        );
        Scene::from_toml_str(&text).expect("parses")
    }

    /// A modal solid over the node limit is told to raise a key it has:
    /// the key the message names in backticks is one of the spec's own
    /// (it said "raise the spacing", which modal solids do not have).
    #[test]
    fn the_node_limit_names_a_key_of_the_modal_solid() {
        let scene = beam(1e-4);
        let err = scene
            .validate(&BuildOptions::default())
            .expect_err("too fine");
        assert!(matches!(err, SceneError::TooFine { .. }), "{err:?}");
        let message = err.to_string();
        let key = message
            .split("raise `")
            .nth(1)
            .and_then(|rest| rest.split('`').next())
            .unwrap_or_else(|| panic!("names a key to raise: {message}"));
        let SystemSpec::ModalSolid(spec) = &scene.systems[0] else {
            panic!("a modal solid");
        };
        let keys = toml::Value::try_from(spec).expect("serialises");
        assert!(
            keys.get(key).is_some(),
            "`{key}` is a key of the modal solid spec: {message}"
        );
        assert_eq!(key, "cell", "{message}");
    }

    /// A budget that refuses the estimate refuses the scene as a resource
    /// limit naming the system, before the precompute allocates it.
    #[test]
    fn a_refused_budget_refuses_the_scene() {
        let options = BuildOptions {
            budget: super::super::Budget::new(|_| {
                Err("the host has 1 MB of its 1 MB budget left".into())
            }),
            ..BuildOptions::default()
        };
        let err = beam(0.02).validate(&options).expect_err("refused");
        assert!(matches!(err, SceneError::OverBudget { .. }), "{err:?}");
        let message = err.to_string();
        assert!(message.starts_with("systems[0]: "), "{message}");
        assert!(message.contains("1 MB of its 1 MB"), "{message}");
    }

    /// A steel cantilever, 1 x 0.1 x 0.1 m (L/H = 10) from x = 0, on 2.5
    /// cm cells, its display surface split `subdivisions` times, held by
    /// `anchors` (TOML).
    fn steel_cantilever(subdivisions: u32, anchors: &str) -> (Scene, ModalSolidSpec) {
        let text = format!(
            r#"
            [domain]
            min = [-0.1, -0.3, -0.3]
            max = [1.2, 0.3, 0.3]
            [time]
            dt = 0.01
            [[systems]]
            kind = "modal_solid"
            shape = {{ type = "box", half_extents = [0.5, 0.05, 0.05] }}
            position = [0.5, 0.0, 0.0]
            density = 7850.0
            young = 2.0e11
            poisson = 0.3
            cell = 0.025
            modes = 6
            surface_subdivisions = {subdivisions}
            anchors = {anchors}
            "#
        );
        let scene = Scene::from_toml_str(&text).expect("parses");
        let SystemSpec::ModalSolid(spec) = &scene.systems[0] else {
            panic!("a modal solid");
        };
        let spec = spec.clone();
        (scene, spec)
    }

    /// The face at x = 0 and nothing of the sides (an anchor reaching
    /// past the face also holds the strips of the side faces inside it).
    const CLAMP: &str = "[{ min = [-0.001, -0.06, -0.06], max = [0.0, 0.06, 0.06] }]";

    /// The angular frequency of the bending wave of wavenumber `k` in a
    /// Timoshenko beam: the lower root of
    /// `E I k^4 - rho A w^2 - rho I w^2 k^2 (1 + E / (kappa G)) + rho^2 I w^4 / (kappa G) = 0`
    /// (Timoshenko 1921), with Cowper's `kappa`.
    fn timoshenko_omega(
        k: Real,
        (e, rho, nu): (Real, Real, Real),
        area: Real,
        inertia: Real,
    ) -> Real {
        let kappa = 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu);
        let kg = kappa * e / (2.0 * (1.0 + nu));
        let a = rho * rho * inertia / kg;
        let b = -(rho * area + rho * inertia * k * k * (1.0 + e / kg));
        let c = e * inertia * k.powi(4);
        ((-b - (b * b - 4.0 * a * c).sqrt()) / (2.0 * a)).sqrt()
    }

    /// The clamp is part of the discretisation: a cantilever built at
    /// display resolutions 0, 1 and 2 sags and rings the same (to 1e-9),
    /// and close to beam theory. Before the penalty was integrated over
    /// the box's own faces it took the display triangles, and the tip sag
    /// moved by more than 10 % between them.
    #[test]
    fn the_clamp_does_not_depend_on_the_display_resolution() {
        let (l, h): (Real, Real) = (1.0, 0.1);
        let (e, rho, nu): (Real, Real, Real) = (2.0e11, 7850.0, 0.3);
        let g = 9.81;
        let (area, inertia) = (h * h, h.powi(4) / 12.0);
        let q = rho * g * area;
        let kappa = 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu);
        let shear = e / (2.0 * (1.0 + nu));
        let euler_bernoulli = q * l.powi(4) / (8.0 * e * inertia);
        let timoshenko = euler_bernoulli + q * l * l / (2.0 * kappa * shear * area);
        let beta_l: Real = 1.875_104_07;
        let omega_eb = (beta_l / l).powi(2) * (e * inertia / (rho * area)).sqrt();
        let omega_t = timoshenko_omega(beta_l / l, (e, rho, nu), area, inertia);
        let mut measured = Vec::new();
        for subdivisions in [0, 1, 2] {
            let (scene, spec) = steel_cantilever(subdivisions, CLAMP);
            let solid = spec
                .prepare("systems[0]", &scene.context(), &BuildOptions::default())
                .expect("builds");
            let efg = solid.efg();
            let u = efg
                .static_displacement(&efg.body_load(&Vector::new(0.0, -g, 0.0)))
                .expect("held by the clamp");
            let nodal: Vec<Vector> = u.chunks(3).map(|c| Vector::new(c[0], c[1], c[2])).collect();
            let mut at = Vec::new();
            efg.shape_table(&[Vector::new(l, 0.0, 0.0)])
                .expect("covered")
                .interpolate(&nodal, &mut at);
            let (tip, omega) = (-at[0].y, solid.frequencies()[0]);
            println!(
                "surface_subdivisions {subdivisions}: tip {tip:.6e} m (Timoshenko {timoshenko:.6e}, \
                 {:+.2} %), omega_1 {omega:.4} rad/s (Euler–Bernoulli {omega_eb:.4}, {:+.2} %; \
                 Timoshenko {omega_t:.4}, {:+.2} %)",
                100.0 * (tip / timoshenko - 1.0),
                100.0 * (omega / omega_eb - 1.0),
                100.0 * (omega / omega_t - 1.0)
            );
            measured.push((tip, omega));
        }
        let (tip, omega) = measured[0];
        for (other_tip, other_omega) in &measured[1..] {
            assert!((other_tip / tip - 1.0).abs() < 1e-9, "{measured:?}");
            assert!((other_omega / omega - 1.0).abs() < 1e-9, "{measured:?}");
        }
        assert!(
            (tip / timoshenko - 1.0).abs() < 0.05,
            "{tip} vs {timoshenko}"
        );
        assert!((omega / omega_t - 1.0).abs() < 0.05, "{omega} vs {omega_t}");
    }

    /// Each anchor must hold part of the surface: one beside the beam is
    /// refused by its own key, not dropped while the other holds the beam.
    #[test]
    fn an_anchor_that_holds_nothing_is_refused_naming_it() {
        let anchors = "[{ min = [-0.001, -0.06, -0.06], max = [0.001, 0.06, 0.06] }, \
                       { min = [0.4, 0.1, -0.06], max = [0.6, 0.2, 0.06] }]";
        let (scene, _) = steel_cantilever(0, anchors);
        let err = scene
            .validate(&BuildOptions::default())
            .expect_err("the second anchor holds nothing");
        let message = err.to_string();
        println!("{message}");
        assert!(
            message.starts_with("systems[0].anchors[1]: holds none of the solid's surface"),
            "{message}"
        );
    }

    /// A sphere is a sphere at every display resolution: its volume is
    /// the ball's and its anchored cap and first frequency do not move
    /// with `surface_subdivisions` (the solid was the display icosphere,
    /// an icosahedron at 0: 40 % short of the ball's volume).
    #[test]
    fn a_sphere_does_not_depend_on_the_display_resolution() {
        let radius: Real = 0.1;
        let mut measured = Vec::new();
        for subdivisions in [0, 2] {
            let text = format!(
                r#"
                [domain]
                min = [-0.2, -0.2, -0.2]
                max = [0.2, 0.2, 0.2]
                [time]
                dt = 0.01
                [[systems]]
                kind = "modal_solid"
                shape = {{ type = "sphere", radius = {radius} }}
                position = [0.0, 0.0, 0.0]
                young = 1.0e6
                cell = 0.04
                modes = 4
                surface_subdivisions = {subdivisions}
                anchors = [{{ min = [-0.2, -0.2, -0.2], max = [0.2, 0.2, -0.05] }}]
                "#
            );
            let scene = Scene::from_toml_str(&text).expect("parses");
            let SystemSpec::ModalSolid(spec) = &scene.systems[0] else {
                panic!("a modal solid");
            };
            let solid = spec
                .prepare("systems[0]", &scene.context(), &BuildOptions::default())
                .expect("builds");
            let volume = solid.efg().volume() / (4.0 / 3.0 * std::f64::consts::PI * radius.powi(3));
            println!(
                "surface_subdivisions {subdivisions}: volume / ball {volume:.5}, omega_1 {:.4} rad/s",
                solid.frequencies()[0]
            );
            measured.push((volume, solid.frequencies()[0]));
        }
        assert!((measured[0].0 - 1.0).abs() < 0.02, "{measured:?}");
        assert!(
            (measured[1].1 / measured[0].1 - 1.0).abs() < 1e-9,
            "{measured:?}"
        );
        assert!(
            (measured[1].0 / measured[0].0 - 1.0).abs() < 1e-12,
            "{measured:?}"
        );
    }
}
