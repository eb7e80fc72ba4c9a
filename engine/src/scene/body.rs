//! Rigid bodies in a scene and the shapes of bodies and solids: the
//! spec, its validation, and the engine shape and pose a spec stands for
//! (spec -> shape), which the world's builder and the optimiser use.

use super::error::{check_positive, check_range, check_vector};
use super::mesh::{MeshData, MeshFiles};
use super::{FluidSpec, Scene, SceneError, defaults, solid_defaults};
use crate::geometry::{MeshError, MeshSolid, Shape, read};
use crate::math::{Brief, Real, Vector, vector};
use crate::rigid::Rotation;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The solid shape of a rigid body, in its body frame, centred on the
/// body's position (see [`crate::geometry::Shape`]). In 2D a shape stands
/// for its cross-section in the plane z = 0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeSpec {
    /// Half the side lengths, m (z ignored in 2D).
    Box {
        /// m.
        half_extents: [Real; 3],
    },
    /// A ball (a disc in 2D).
    Sphere {
        /// m.
        radius: Real,
    },
    /// A cylinder of length `2 half_length` along the body's y axis with
    /// hemispherical caps of `radius`.
    Capsule {
        /// Half the cylinder's length, m.
        half_length: Real,
        /// m.
        radius: Real,
    },
    /// The half-space `normal . x <= offset` in the body frame; `normal`
    /// points out of the solid (it need not be unit length).
    Plane {
        /// Out of the solid.
        normal: [Real; 3],
        /// m, along `normal`.
        #[serde(default)]
        offset: Real,
    },
    /// A closed triangle mesh from an OBJ or PLY file (3D only), its
    /// coordinates multiplied by `scale` (default 1). The body's
    /// `position` is where the mesh's centroid (its centre of mass) goes
    /// and `orientation` turns the mesh about it from the axes of the file.
    ///
    /// The file travels in `data`, or is named by `path` and loaded into
    /// `data` by [`Scene::check`] under the host's
    /// [`MeshFiles`](super::MeshFiles) policy (with both, `path` only names
    /// the mesh). A relative `path` is taken from the directory of the
    /// scene file when the scene is read with [`Scene::from_toml_file`]
    /// (which rewrites it so), otherwise as the policy says.
    Mesh {
        /// The OBJ or PLY file.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        path: Option<String>,
        /// The file's bytes.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        data: Option<MeshData>,
        /// Multiplies the file's coordinates (default 1).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        scale: Option<Real>,
    },
}

impl ShapeSpec {
    /// Loads the file a mesh shape names into its `data` under `files`
    /// (see [`MeshFiles`]); other shapes, and meshes that carry their
    /// data, are left as they are. `at` names the shape's field in errors.
    ///
    /// # Errors
    /// [`SceneError::Invalid`] naming `{at}.path` or `{at}.data`.
    pub fn load_mesh(
        &mut self,
        files: &MeshFiles,
        max_bytes: u64,
        at: &str,
    ) -> Result<(), SceneError> {
        match self {
            Self::Mesh { path, data, .. } => {
                super::mesh::load(path.as_deref(), data, files, max_bytes, at)
            }
            Self::Box { .. } | Self::Sphere { .. } | Self::Capsule { .. } | Self::Plane { .. } => {
                Ok(())
            }
        }
    }
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
    /// Its shape, in its own frame.
    pub shape: ShapeSpec,
    /// Centre (of mass), m; z is ignored in 2D.
    pub position: [Real; 3],
    /// Rotation vector (axis times angle in radians) from the shape's
    /// frame to the world; in 2D only about z.
    #[serde(default)]
    pub orientation: [Real; 3],
    /// How it moves.
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
    /// How the fluid meets its surface.
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

impl Scene {
    /// A body in a periodic domain must be static and keep a support
    /// radius clear of every periodic face: its boundary samples do not
    /// wrap around, so a fluid particle near a face would miss the images
    /// across it. Flow past a cylinder in a periodic channel is allowed;
    /// a body crossing a periodic face is not.
    pub(super) fn check_periodic_body(
        &self,
        s: usize,
        body: &RigidBodySpec,
        shape: &Shape,
        fluid: Option<&FluidSpec>,
    ) -> Result<(), SceneError> {
        let periodic = self.periodic_axes();
        if !periodic.contains(&true) {
            return Ok(());
        }
        if body.motion != MotionKind::Static {
            return Err(SceneError::invalid(
                format!("systems[{s}].motion"),
                "only static bodies may sit in a periodic domain (moving ones would cross its \
                 periodic faces, which their boundary samples do not wrap around); make it \
                 static or the domain non-periodic",
            ));
        }
        let clearance = fluid.map_or(0.0, FluidSpec::support_radius);
        let reach = shape.bounding_radius(self.dimension) + clearance;
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            let (lo, hi) = (self.domain.min[a], self.domain.max[a]);
            let at = body.position[a];
            if periodic[a] && (at - reach < lo || at + reach > hi) {
                return Err(SceneError::invalid(
                    format!("systems[{s}].position"),
                    format!(
                        "the body comes within a support radius of the periodic faces along \
                         {axis} (it reaches {} m from {}, the domain spans [{}, {}]); move it \
                         inward, shrink it, or make {axis} non-periodic",
                        Brief(reach),
                        Brief(at),
                        Brief(lo),
                        Brief(hi)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Checks a shape's parameters and makes its engine shape (parsing
    /// its mesh).
    pub(super) fn checked_shape(
        &self,
        shape_at: &str,
        spec: &ShapeSpec,
    ) -> Result<Shape, SceneError> {
        checked_shape(shape_at, spec, self.dimension)
    }

    /// Checks a rigid body and makes its engine shape (parsing its mesh).
    /// Without a fluid the body is a static obstacle for solids.
    pub(super) fn validate_body(
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
            let pose = body_pose(body, &shape, dim);
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
}

/// Checks a shape's parameters and makes its engine shape (parsing
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
    body_shape(spec, dim, shape_at)
}

/// Parses the loaded mesh of a `shape = { type = "mesh" }` at field `at`,
/// scales it and puts it in its principal frame. Every failure names
/// `{at}.data` or `{at}.path` and the mesh (its path, when it has one).
fn mesh_shape(
    path: Option<&str>,
    data: Option<&MeshData>,
    scale: Option<Real>,
    at: &str,
) -> Result<Shape, SceneError> {
    let (field, label) = match path {
        Some(path) if !path.is_empty() => (format!("{at}.path"), path.to_owned()),
        _ => (format!("{at}.data"), format!("the mesh data of {at}")),
    };
    let Some(data) = data else {
        return Err(SceneError::invalid(
            field,
            "the mesh was not loaded; load it first (`Scene::check` and \
             `ShapeSpec::load_mesh` do)",
        ));
    };
    let mut mesh = read::parse(Path::new(&label), data.format, &data.content)
        .map_err(|e| SceneError::invalid(&field, format!("cannot load the mesh: {e}")))?
        .mesh;
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
                "{label}: the mesh must be closed to bound a solid, but {} edges are open \
                 ({boundary} boundary, {non_manifold} non-manifold, {misoriented} misoriented); \
                 close the holes, weld duplicated vertices and orient the faces outward",
                boundary + non_manifold + misoriented
            ),
            other => format!("{label}: {other}"),
        };
        SceneError::invalid(&field, what)
    })?;
    Ok(Shape::Mesh(solid))
}

/// The engine shape of a scene's shape (the shape at field `at`); in 2D a
/// box's z extent is unused. Parses loaded meshes; reads no file.
///
/// # Errors
/// A mesh that cannot be read or does not bound a solid (see
/// [`mesh_shape`]).
pub(crate) fn body_shape(spec: &ShapeSpec, dim: usize, at: &str) -> Result<Shape, SceneError> {
    Ok(match spec {
        ShapeSpec::Box { half_extents } => Shape::Box {
            half_extents: vector(*half_extents),
        },
        ShapeSpec::Sphere { radius } => Shape::Sphere { radius: *radius },
        ShapeSpec::Capsule {
            half_length,
            radius,
        } => Shape::Capsule {
            half_length: *half_length,
            radius: *radius,
        },
        ShapeSpec::Plane { normal, offset } => {
            let mut n = vector(*normal);
            if dim == 2 {
                n.z = 0.0;
            }
            // Scaling the normal to unit length scales the offset with it.
            let length = n.norm();
            Shape::Plane {
                normal: n / length,
                offset: offset / length,
            }
        }
        ShapeSpec::Mesh { path, data, scale } => {
            mesh_shape(path.as_deref(), data.as_ref(), *scale, at)?
        }
    })
}

/// The rotation from a body's frame to the frame its shape was given in:
/// a mesh's principal axes in its file, the identity for the primitives.
pub(crate) fn shape_axes(shape: &Shape) -> Rotation {
    match shape {
        Shape::Mesh(solid) => solid.axes(),
        _ => Rotation::identity(),
    }
}

/// A body's initial position and orientation; in 2D in the plane z = 0.
/// The scene's orientation turns the shape as given (a mesh as in its
/// file); the body frame is turned further onto the shape's principal axes.
pub(crate) fn body_pose(spec: &RigidBodySpec, shape: &Shape, dim: usize) -> (Vector, Rotation) {
    shape_pose(spec.position, spec.orientation, shape, dim)
}

/// [`body_pose`] from a scene position and rotation vector.
pub(crate) fn shape_pose(
    position: [Real; 3],
    orientation: [Real; 3],
    shape: &Shape,
    dim: usize,
) -> (Vector, Rotation) {
    let mut position = vector(position);
    if dim == 2 {
        position.z = 0.0;
    }
    (
        position,
        Rotation::from_scaled_axis(vector(orientation)) * shape_axes(shape),
    )
}

fn default_motion() -> MotionKind {
    defaults::MOTION
}
fn default_slip() -> SlipKind {
    defaults::SLIP
}
