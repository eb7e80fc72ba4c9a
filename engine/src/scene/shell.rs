//! Thin shells in a scene (Guo–Qin 4.2 and 5.2): the TOML/protocol
//! description, its validation, and the build of the engine shell, which
//! the check does (the chart, the quadtree, the shape functions and the
//! first factorisation are its admission: a surface the chart or the
//! supports refuse is refused before a world exists).
//!
//! The surface is a flat rectangular plate (a box with one half extent
//! zero: the plate's plane), a sphere (an icosphere, closed), a triangle
//! mesh from a file, open or closed, of any genus, or an oriented point
//! cloud (a PLY of points with normals and no faces, the paper's input),
//! whose surface is meshed first (`surface/reconstruct.rs`) and which
//! then carries its own points: one least-squares conformal chart where
//! the surface is a disk, else an atlas of charts meeting at seams
//! (`geometry/atlas.rs`).

use super::error::{check_box, check_positive, check_range, check_vector};
use super::{Aabb, BuildOptions, SceneContext, SceneError, ShapeSpec};
use crate::approx::gauss::MAX_ORDER;
use crate::approx::mls::Order;
use crate::cancel::Cancel;
use crate::geometry::atlas::{Atlas, AtlasParams};
use crate::geometry::quadtree::Point2;
use crate::geometry::read::{self, MeshFormat};
use crate::geometry::{OrientedPoints, TriMesh, project};
use crate::math::{Real, Vector, bounds, vector};
use crate::shell::{
    DynamicParams, Embedded, Integrator, Load, Material, Mechanics, ShellDynamics, ShellError,
    ShellModel, ShellParams, Support, SupportKind,
};
use crate::surface::reconstruct::{ReconstructError, reconstruct};
use nalgebra::Rotation3;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Defaults of the optional shell parameters, shared with the protocol
/// conversion.
pub mod defaults {
    use crate::math::Real;

    /// kg/m^3.
    pub const DENSITY: Real = 1000.0;
    /// A typical metal's or polymer's.
    pub const POISSON: Real = 0.3;
    /// Support side in leaf sides: a quadratic fit needs three nodes
    /// along each axis over every point, the domain's corners included.
    pub const ETA: Real = 4.0;
    /// Gauss points per axis of an integration cell.
    pub const QUADRATURE_ORDER: u32 = 4;
    /// Integration cells per leaf side (one per leaf integrates bending
    /// poorly: `engine/tests/plate.rs`).
    pub const SUBDIVISION: u32 = 2;
    /// The supports' penalty scale (`engine/src/shell/assembly.rs`).
    pub const PENALTY: Real = 10.0;
    /// Newton's relative residual per step.
    pub const TOLERANCE: Real = 1e-7;
    /// Newton iterations per step.
    pub const MAX_ITERATIONS: u32 = 20;
    /// Cells of a plate's carried mesh along its longer side.
    pub const SURFACE_CELLS: u32 = 32;
}

/// Most nodes a shell may place, by the estimate made before building
/// it: each step assembles and factorises the tangent over all of them,
/// and a session waits for the first factorisation at admission.
pub const MAX_NODES: u64 = 20_000;

/// Most cells along a plate's carried mesh.
const MAX_SURFACE_CELLS: u32 = 1024;

/// Bytes a shell holds per quadrature point: the energy's gradient and
/// Hessian in the 15 local unknowns (1,920 B), the stencil of about 25
/// nodes with six values each (1,300 B) and the reference geometry,
/// rounded up; the sparse tangent and its factor come on top, per node.
const BYTES_PER_POINT: Real = 3_600.0;

/// Bytes per node: its block column of the tangent (about 80 coupled
/// nodes of 9 values), the Cholesky factor's fill-in and, under linear
/// mechanics, its block columns of the constant stiffness and mass (6 kB),
/// by count and rounded up.
const BYTES_PER_NODE: Real = 30_000.0;

/// A thin shell: a Kirchhoff–Love surface discretised on its conformal
/// chart or atlas (Guo–Qin 4.2, 5.2). The knobs that trade speed for accuracy:
/// `resolution`, `eta`, `basis`, `quadrature_order`, `subdivision`,
/// `integrator`, and the scene's `time.dt`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShellSpec {
    /// The middle surface: a plate (`type = "box"` with one half extent
    /// 0, the plate lying across the other two axes), a sphere, a mesh
    /// (OBJ or PLY, an orientable manifold, open or closed), or an
    /// oriented point cloud (a PLY with normals and no faces).
    pub shape: ShapeSpec,
    /// Where the surface's centre (its bounding box's) goes, m.
    pub position: [Real; 3],
    /// Rotation vector of the surface, rad.
    #[serde(default)]
    pub orientation: [Real; 3],
    /// Shell thickness, m.
    pub thickness: Real,
    /// kg/m^3.
    #[serde(default = "default_density")]
    pub density: Real,
    /// Young's modulus, Pa.
    pub young: Real,
    /// Poisson's ratio, in [0, 0.5).
    #[serde(default = "default_poisson")]
    pub poisson: Real,
    /// Largest quadtree cell on the surface, m (`lambda l`): the
    /// resolution.
    pub resolution: Real,
    /// Support side in quadtree leaf sides.
    #[serde(default = "default_eta")]
    pub eta: Real,
    /// MLS basis: quadratic (bending needs curvature reproduced) or
    /// linear (cheaper, membranes).
    #[serde(default = "default_basis")]
    pub basis: Order,
    /// Gauss points per axis of an integration cell.
    #[serde(default = "default_quadrature_order")]
    pub quadrature_order: u32,
    /// Integration cells per leaf side.
    #[serde(default = "default_subdivision")]
    pub subdivision: u32,
    /// `"backward_euler"` (robust, damps) or `"newmark"` (second order,
    /// keeps energy).
    #[serde(default)]
    pub integrator: Integrator,
    /// `"nonlinear"` (large deflections and rotations) or `"linear"` (the
    /// paper's constant `M` and `K`: small displacements, one solve per
    /// step with a factor kept between steps).
    #[serde(default)]
    pub mechanics: Mechanics,
    /// Rayleigh damping `a` of `C = a M + b K`, 1/s.
    #[serde(default)]
    pub mass_damping: Real,
    /// Rayleigh damping `b` of `C = a M + b K`, s.
    #[serde(default)]
    pub stiffness_damping: Real,
    /// The supports' penalty scale.
    #[serde(default = "default_penalty")]
    pub penalty: Real,
    /// Newton's relative residual per step.
    #[serde(default = "default_tolerance")]
    pub tolerance: Real,
    /// Newton iterations per step.
    #[serde(default = "default_max_iterations")]
    pub max_iterations: u32,
    /// Pressure on the side the surface's normal points to, Pa.
    #[serde(default)]
    pub pressure: Real,
    /// Boxes (world frame): the surface's boundary inside them is
    /// clamped (held in place and in slope).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clamped: Vec<Aabb>,
    /// Boxes (world frame): the surface's boundary inside them is pinned
    /// (held in place, free to turn: simply supported).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pinned: Vec<Aabb>,
    /// Cells of a plate's carried mesh along its longer side (a mesh
    /// carries its own vertices).
    #[serde(default = "default_surface_cells")]
    pub surface_cells: u32,
}

fn default_density() -> Real {
    defaults::DENSITY
}
fn default_poisson() -> Real {
    defaults::POISSON
}
fn default_eta() -> Real {
    defaults::ETA
}
fn default_basis() -> Order {
    Order::Quadratic
}
fn default_quadrature_order() -> u32 {
    defaults::QUADRATURE_ORDER
}
fn default_subdivision() -> u32 {
    defaults::SUBDIVISION
}
fn default_penalty() -> Real {
    defaults::PENALTY
}
fn default_tolerance() -> Real {
    defaults::TOLERANCE
}
fn default_max_iterations() -> u32 {
    defaults::MAX_ITERATIONS
}
fn default_surface_cells() -> u32 {
    defaults::SURFACE_CELLS
}

/// A shell as its check built it: the dynamics at rest, and the surface
/// it carries in frames.
#[derive(Debug, Clone)]
pub(crate) struct PreparedShell {
    /// The shell, held and loaded.
    pub dynamics: ShellDynamics,
    /// The carried mesh's vertices (or the cloud's points), embedded in
    /// the shell.
    pub surface: Embedded,
    /// The carried mesh's triangles (none for a cloud).
    pub triangles: Vec<[u32; 3]>,
    /// The surface's atlas, where a grab's material point is found.
    pub atlas: Atlas,
    /// How far from the surface a grab's point may lie, m (the
    /// resolution): it is moved onto the surface.
    pub grab_reach: Real,
    /// A grab's spring, N/m: `penalty E t`.
    pub grab_stiffness: Real,
}

impl PreparedShell {
    /// Bytes it holds, by count.
    pub(crate) fn bytes(&self) -> Real {
        let model = self.dynamics.model();
        model.points().len() as Real * BYTES_PER_POINT
            + model.node_count() as Real * BYTES_PER_NODE
            + self.surface.len() as Real * 1_500.0
    }
}

impl ShellSpec {
    /// Checks the shell against `context` and builds it: the chart, the
    /// quadtree, the shape functions, the supports and the state at rest.
    pub(super) fn prepare(
        &self,
        at: &str,
        context: &SceneContext,
        options: &BuildOptions,
    ) -> Result<PreparedShell, SceneError> {
        if context.dimension != 3 {
            return Err(SceneError::invalid(
                at,
                "shells are 3D surfaces; set dimension = 3",
            ));
        }
        self.check_values(at)?;
        let field = |name: &str| format!("{at}.{name}");
        let (mesh, cloud) = self.surface_mesh(at, &options.cancel)?;
        for v in mesh
            .vertices
            .iter()
            .chain(cloud.iter().flat_map(|c| &c.points))
        {
            for a in 0..3 {
                if v[a] < context.domain.min[a] || v[a] > context.domain.max[a] {
                    return Err(SceneError::invalid(
                        field("position"),
                        "the shell reaches outside the domain; move it or enlarge the domain",
                    ));
                }
            }
        }
        // A leaf's side on the surface lies between half the resolution
        // and the resolution: twice the area over its square bounds the
        // leaves from above within a factor two, plus the exterior ring.
        let area = mesh.area();
        let nodes = 2.0 * area / (self.resolution * self.resolution);
        let limit = MAX_NODES.min(options.max_particles);
        if nodes > limit as Real {
            return Err(SceneError::TooFine {
                field: field("resolution"),
                points: nodes.min(u64::MAX as Real) as u64,
                limit,
            });
        }
        let atlas = Atlas::new(&mesh, &AtlasParams::new(self.eta * self.resolution))
            .map_err(|e| SceneError::invalid(field("shape"), e.to_string()))?;
        let shell_error = |e: ShellError| match e {
            ShellError::Cancelled => SceneError::Cancelled,
            other => SceneError::invalid(at, other.to_string()),
        };
        let (lo, hi) = atlas.bounds();
        let mut params = self.params();
        if atlas.is_closed() {
            // A closed surface has no rim to put exterior leaves beyond:
            // across its seams the neighbouring charts' nodes are the
            // supports.
            params.quadtree.exterior = 0;
        }
        let model = ShellModel::new(&atlas, lo, hi, self.material(), &params, &options.cancel)
            .map_err(shell_error)?;
        let bytes = model.points().len() as Real * BYTES_PER_POINT
            + model.node_count() as Real * BYTES_PER_NODE;
        options
            .budget
            .reserve(bytes as u64)
            .map_err(|message| SceneError::OverBudget {
                field: at.to_owned(),
                message,
            })?;
        let supports = self.supports(at, &mesh, &atlas, &model)?;
        let load = Load {
            per_area: self.density * self.thickness * context.gravity,
            pressure: self.pressure,
            points: Vec::new(),
            closed: atlas.is_closed(),
        };
        let params = DynamicParams {
            integrator: self.integrator,
            mechanics: self.mechanics,
            mass_damping: self.mass_damping,
            stiffness_damping: self.stiffness_damping,
            penalty: self.penalty,
            tolerance: self.tolerance,
            max_iterations: self.max_iterations as usize,
            ..DynamicParams::new(context.dt)
        };
        let (surface, triangles) = match cloud {
            None => (
                model
                    .embed(atlas.vertex_parameters(), &mesh.vertices)
                    .map_err(shell_error)?,
                mesh.triangles,
            ),
            Some(cloud) => {
                let at = cloud_parameters(&field("shape"), &mesh, &atlas, &cloud.points)?;
                (
                    model.embed(&at, &cloud.points).map_err(shell_error)?,
                    Vec::new(),
                )
            }
        };
        let dynamics = ShellDynamics::new(model, &supports, &load, params).map_err(shell_error)?;
        Ok(PreparedShell {
            dynamics,
            surface,
            triangles,
            atlas,
            grab_reach: self.resolution,
            grab_stiffness: self.penalty * self.young * self.thickness,
        })
    }

    /// Range checks of every number, before anything is built.
    fn check_values(&self, at: &str) -> Result<(), SceneError> {
        let field = |name: &str| format!("{at}.{name}");
        check_vector(&field("position"), self.position)?;
        check_vector(&field("orientation"), self.orientation)?;
        check_positive(&field("thickness"), self.thickness)?;
        check_positive(&field("density"), self.density)?;
        check_range(&field("density"), self.density, 1e-3, 1e6)?;
        check_positive(&field("young"), self.young)?;
        check_range(&field("young"), self.young, 0.0, 1e13)?;
        check_range(&field("poisson"), self.poisson, 0.0, 0.4999).map_err(|e| {
            e.with_hint("0.5 is incompressible, which plane stress in the surface cannot hold")
        })?;
        check_positive(&field("resolution"), self.resolution)?;
        if self.thickness > self.resolution * 10.0 {
            return Err(SceneError::invalid(
                field("thickness"),
                format!(
                    "is {} m, ten times the resolution or more: a Kirchhoff-Love shell is thin \
                     against its cells; lower the thickness or coarsen the resolution, or model \
                     the part as a modal_solid",
                    self.thickness
                ),
            ));
        }
        check_range(&field("eta"), self.eta, 2.0, 8.0).map_err(|e| {
            e.with_hint("below 2 a point may be covered by fewer supports than the basis needs")
        })?;
        if self.basis == Order::Constant {
            return Err(SceneError::invalid(
                field("basis"),
                "a constant basis has no curvature; use \"quadratic\" (or \"linear\")",
            ));
        }
        for (name, value, max) in [
            ("quadrature_order", self.quadrature_order, MAX_ORDER as u32),
            ("subdivision", self.subdivision, 8),
            ("max_iterations", self.max_iterations, 1000),
            ("surface_cells", self.surface_cells, MAX_SURFACE_CELLS),
        ] {
            if value == 0 || value > max {
                return Err(SceneError::invalid(
                    field(name),
                    format!("must be in [1, {max}], got {value}"),
                ));
            }
        }
        for (name, value) in [
            ("mass_damping", self.mass_damping),
            ("stiffness_damping", self.stiffness_damping),
        ] {
            check_range(&field(name), value, 0.0, 1e6)?;
        }
        check_positive(&field("penalty"), self.penalty)?;
        check_range(&field("penalty"), self.penalty, 0.0, 1e8)?;
        check_positive(&field("tolerance"), self.tolerance)?;
        check_range(&field("tolerance"), self.tolerance, 0.0, 0.1)?;
        check_range(&field("pressure"), self.pressure, -1e12, 1e12)?;
        for (name, boxes) in [("clamped", &self.clamped), ("pinned", &self.pinned)] {
            for (k, b) in boxes.iter().enumerate() {
                check_box(&format!("{at}.{name}[{k}]"), b, 3)?;
            }
        }
        Ok(())
    }

    fn material(&self) -> Material {
        Material {
            thickness: self.thickness,
            density: self.density,
            young: self.young,
            poisson: self.poisson,
        }
    }

    fn params(&self) -> ShellParams {
        let mut params = ShellParams::new(self.resolution);
        params.order = self.basis;
        params.quadtree.eta = self.eta;
        params.quadtree.gauss_order = self.quadrature_order as usize;
        params.quadtree.subdivision = self.subdivision as usize;
        params
    }

    /// The middle surface in the world frame: a plate's grid of split
    /// squares, or the mesh file centred on its bounding box's centre; for
    /// a point cloud, the mesh of its surface and the cloud, placed alike.
    fn surface_mesh(
        &self,
        at: &str,
        cancel: &Cancel,
    ) -> Result<(TriMesh, Option<Cloud>), SceneError> {
        let shape_at = format!("{at}.shape");
        let (centre, rotation) = (
            vector(self.position),
            Rotation3::new(vector(self.orientation)),
        );
        let mut mesh = match &self.shape {
            ShapeSpec::Box { half_extents } => self.plate(&shape_at, *half_extents)?,
            ShapeSpec::Mesh { path, data, scale } => {
                let label = path.clone().unwrap_or_else(|| format!("{shape_at}.data"));
                let Some(data) = data else {
                    return Err(SceneError::invalid(
                        format!("{shape_at}.path"),
                        "the mesh was not loaded; load it first (`Scene::check` does)",
                    ));
                };
                let scale = scale.unwrap_or(1.0);
                check_positive(&format!("{shape_at}.scale"), scale)?;
                let loaded = match read::parse(Path::new(&label), data.format, &data.content) {
                    Ok(loaded) if !loaded.mesh.triangles.is_empty() => loaded,
                    parsed if data.format == MeshFormat::Ply => {
                        let points = read::parse_oriented_points(Path::new(&label), &data.content)
                            .map_err(|e| {
                                let mesh = parsed.err().map_or_else(
                                    || "it has no faces".to_owned(),
                                    |m| m.to_string(),
                                );
                                SceneError::invalid(
                                    &shape_at,
                                    format!(
                                        "is neither a mesh ({mesh}) nor an oriented point cloud \
                                         ({e})"
                                    ),
                                )
                            })?;
                        let cloud = self.cloud(&shape_at, &points, scale, cancel)?;
                        return Ok(cloud);
                    }
                    parsed => {
                        let why = parsed
                            .err()
                            .map_or_else(|| "it has no faces".to_owned(), |e| e.to_string());
                        return Err(SceneError::invalid(
                            shape_at,
                            format!(
                                "{why}; a shell's surface is a triangle mesh or an oriented \
                                 point cloud (a PLY with normals)"
                            ),
                        ));
                    }
                };
                let mut mesh = loaded.mesh;
                let (lo, hi) = bounds(&mesh.vertices);
                let middle = 0.5 * (lo + hi);
                for v in &mut mesh.vertices {
                    *v = (*v - middle) * scale;
                }
                mesh
            }
            ShapeSpec::Sphere { radius } => {
                check_positive(&format!("{shape_at}.radius"), *radius)?;
                // Edges of about `2 pi r / surface_cells`: an icosphere's
                // edge is about 1.1 r / 2^subdivisions.
                let cells = self.surface_cells as Real * 1.1 / (2.0 * std::f64::consts::PI);
                let subdivisions = cells.log2().round().clamp(1.0, 7.0) as u32;
                TriMesh::icosphere(Vector::zeros(), *radius, subdivisions)
            }
            ShapeSpec::Capsule { .. } | ShapeSpec::Plane { .. } => {
                return Err(SceneError::invalid(
                    shape_at,
                    "a shell is a plate (type = \"box\" with one half extent 0), a sphere, \
                     a mesh file or an oriented point cloud (a PLY with normals)",
                ));
            }
        };
        for v in &mut mesh.vertices {
            *v = centre + rotation * *v;
        }
        Ok((mesh, None))
    }

    /// An oriented point cloud placed as a mesh file is (centred on its
    /// box, scaled, turned and moved), and the mesh of its surface.
    fn cloud(
        &self,
        at: &str,
        points: &OrientedPoints,
        scale: Real,
        cancel: &Cancel,
    ) -> Result<(TriMesh, Option<Cloud>), SceneError> {
        let (centre, rotation) = (
            vector(self.position),
            Rotation3::new(vector(self.orientation)),
        );
        let (lo, hi) = bounds(&points.points);
        let middle = 0.5 * (lo + hi);
        let cloud = Cloud {
            points: points
                .points
                .iter()
                .map(|p| centre + rotation * ((p - middle) * scale))
                .collect(),
            normals: points.normals.iter().map(|n| rotation * n).collect(),
        };
        // The mesh resolves the leaves' scale, no finer: it carries the
        // charts, the cloud carries the detail.
        let built = reconstruct(&cloud.points, &cloud.normals, 0.5 * self.resolution, cancel)
            .map_err(|e| match e {
                ReconstructError::Cancelled => SceneError::Cancelled,
                other => SceneError::invalid(at, other.to_string()),
            })?;
        Ok((built.mesh, Some(cloud)))
    }

    /// A plate across the two axes of `half_extents` that are not zero.
    fn plate(&self, at: &str, half_extents: [Real; 3]) -> Result<TriMesh, SceneError> {
        check_vector(&format!("{at}.half_extents"), half_extents)?;
        let flat: Vec<usize> = (0..3).filter(|&a| half_extents[a] == 0.0).collect();
        let [normal] = flat[..] else {
            return Err(SceneError::invalid(
                format!("{at}.half_extents"),
                "a shell's plate is a box with exactly one half extent 0 (the plate's normal \
                 axis); its thickness is the shell's `thickness`",
            ));
        };
        let (u, v) = ((normal + 1) % 3, (normal + 2) % 3);
        let (hu, hv) = (half_extents[u], half_extents[v]);
        if hu <= 0.0 || hv <= 0.0 {
            return Err(SceneError::invalid(
                format!("{at}.half_extents"),
                "the plate's two other half extents must be > 0",
            ));
        }
        let longer = hu.max(hv);
        let cells = |h: Real| ((h / longer * self.surface_cells as Real).round() as usize).max(1);
        let (nu, nv) = (cells(hu), cells(hv));
        Ok(TriMesh::grid(nu, nv, |i, j| {
            let mut p = Vector::zeros();
            p[u] = hu * (2.0 * i as Real / nu as Real - 1.0);
            p[v] = hv * (2.0 * j as Real / nv as Real - 1.0);
            p
        }))
    }

    /// The penalty supports of the boundary edges inside the clamped and
    /// pinned boxes: each such edge held at four Gauss points.
    fn supports(
        &self,
        at: &str,
        mesh: &TriMesh,
        atlas: &Atlas,
        model: &ShellModel,
    ) -> Result<Vec<Support>, SceneError> {
        let held = [
            SupportKind::Displacement(Vector::x()),
            SupportKind::Displacement(Vector::y()),
            SupportKind::Displacement(Vector::z()),
        ];
        let mut supports = Vec::new();
        for (name, boxes, clamp) in [
            ("clamped", &self.clamped, true),
            ("pinned", &self.pinned, false),
        ] {
            for (k, b) in boxes.iter().enumerate() {
                let inside = |p: &Vector| (0..3).all(|a| p[a] >= b.min[a] && p[a] <= b.max[a]);
                let mut edges = 0;
                for &([i, j], [from, to]) in atlas.boundary() {
                    let (i, j) = (i as usize, j as usize);
                    if !(inside(&mesh.vertices[i]) && inside(&mesh.vertices[j])) {
                        continue;
                    }
                    edges += 1;
                    let d = [to[0] - from[0], to[1] - from[1]];
                    let length = d[0].hypot(d[1]);
                    let mut kinds = held.to_vec();
                    if clamp && length > 0.0 {
                        kinds.push(SupportKind::Slope([d[1] / length, -d[0] / length]));
                    }
                    supports.extend(model.edge_supports(from, to, 1, &kinds).map_err(|e| {
                        SceneError::invalid(format!("{at}.{name}[{k}]"), e.to_string())
                    })?);
                }
                if edges == 0 {
                    return Err(SceneError::invalid(
                        format!("{at}.{name}[{k}]"),
                        "holds no edge of the surface's boundary; move the box over an edge \
                         (a support holds boundary edges whose two ends lie in it)",
                    ));
                }
            }
        }
        Ok(supports)
    }
}

/// An oriented point cloud in the world frame.
#[derive(Debug, Clone)]
struct Cloud {
    points: Vec<Vector>,
    normals: Vec<Vector>,
}

/// Each cloud point's place in the plane: the point of the mesh nearest
/// it, in the chart owning the triangle there.
fn cloud_parameters(
    at: &str,
    mesh: &TriMesh,
    atlas: &Atlas,
    points: &[Vector],
) -> Result<Vec<Point2>, SceneError> {
    project(mesh, points)
        .into_iter()
        .enumerate()
        .map(|(i, found)| {
            found
                .and_then(|p| atlas.parameter_in(p.triangle, p.weights))
                .ok_or_else(|| {
                    SceneError::invalid(
                        at,
                        format!("point {i} of the cloud has no place on its surface"),
                    )
                })
        })
        .collect()
}
