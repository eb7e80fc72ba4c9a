//! Elastic solids in a scene: the TOML/protocol description and its
//! validation (the world's builder makes the engine solid of it).

use super::body::checked_shape;
use super::error::{check_box, check_positive, check_range, check_vector};
use super::{Aabb, SceneContext, SceneError, ShapeSpec, shape_pose};
use crate::approx::mls::Order;
use crate::geometry::{MeshSdf, Shape, TriMesh};
use crate::math::{Real, Vector, vector};
use crate::solid::embedded::{EmbeddedSurface, EmbeddingMethod};
use crate::solid::fracture::{
    CrackCriterion, Discontinuity, Notch, Resampling, Threshold, check_room,
};
use crate::solid::{
    FractureParams, Hyperelastic, ImplicitParams, ImplicitScheme, Integrator, Material, Plasticity,
    SolidParams,
};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Defaults of the optional solid parameters, shared with the protocol
/// conversion.
pub mod defaults {
    use crate::approx::mls::Order;
    use crate::math::Real;

    /// kg/m^3, water-like.
    pub const DENSITY: Real = 1000.0;
    /// Poisson's ratio of a rubber-like solid.
    pub const POISSON: Real = 0.3;
    /// Linear: Müller et al. 2004's choice, exact for affine motion, and a
    /// third of the quadratic's cost (the cantilever table in the README
    /// shows what each buys).
    pub const ORDER: Order = Order::Linear;
    /// MLS support in spacings: the smallest that keeps a full linear fit
    /// at the corners of a lattice.
    pub const SUPPORT: Real = 2.0;
    /// Hourglass weight relative to Young's modulus: removes the lattice's
    /// zero-energy modes while adding under 1 % to a cantilever's stiffness
    /// at 10 particles across (README).
    pub const HOURGLASS: Real = 0.1;
    /// Coulomb coefficient against walls and obstacles.
    pub const FRICTION: Real = 0.5;
    /// Explicit steps at half the wave limit.
    pub const CFL: Real = 0.5;
    /// 3072 triangles on a box, 5120 on a sphere.
    pub const SURFACE_SUBDIVISIONS: u32 = 4;
}

/// How a solid advances in time (see [`crate::solid::Integrator`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum IntegratorKind {
    /// Symplectic Euler, sub-stepped within the wave limit.
    #[default]
    Explicit,
    /// Backward Euler with Newton steps, any step length.
    Implicit,
}

/// A box of anchored particles: every particle of the solid inside it is
/// fixed in place.
pub type AnchorSpec = Aabb;

/// An elastic (optionally plastic) solid: a shape filled with particles
/// on a lattice of `spacing` (tutorial Section 7; Müller et al. 2004).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolidSpec {
    /// Any bounded shape (not a plane); meshes in 3D only.
    pub shape: ShapeSpec,
    /// Where the shape's centre goes, m.
    pub position: [Real; 3],
    /// Rotation vector (axis times angle) of the shape, rad.
    #[serde(default)]
    pub orientation: [Real; 3],
    /// Particle spacing, m: each particle stands for `spacing^dim`.
    pub spacing: Real,
    /// kg/m^3.
    #[serde(default = "default_density")]
    pub density: Real,
    /// Young's modulus, Pa.
    pub young: Real,
    /// Poisson's ratio, in [0, 0.5).
    #[serde(default = "default_poisson")]
    pub poisson: Real,
    /// `k_v` of the volume-conservation force (Eq. 65), Pa; 0 is off.
    #[serde(default)]
    pub volume_stiffness: Real,
    /// MLS basis order of the displacement gradient.
    #[serde(default = "default_order")]
    pub order: Order,
    /// MLS support radius in spacings.
    #[serde(default = "default_support")]
    pub support: Real,
    /// Hourglass-control weight relative to Young's modulus.
    #[serde(default = "default_hourglass")]
    pub hourglass: Real,
    /// Pairwise velocity damping rate, 1/s.
    #[serde(default)]
    pub damping: Real,
    /// Coulomb friction against walls and static rigid bodies.
    #[serde(default = "default_friction")]
    pub friction: Real,
    /// How it advances in time.
    #[serde(default)]
    pub integrator: IntegratorKind,
    /// Explicit only: the sub-step as a fraction of the wave limit.
    #[serde(default = "default_cfl")]
    pub cfl: Real,
    /// Implicit only: Newton and linear-solver settings.
    #[serde(default)]
    pub implicit: ImplicitParams,
    /// Initial velocity, m/s.
    #[serde(default)]
    pub velocity: [Real; 3],
    /// Initial angular velocity about `position`, rad/s.
    #[serde(default)]
    pub angular_velocity: [Real; 3],
    /// Boxes (world frame) whose particles are fixed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub anchors: Vec<AnchorSpec>,
    /// Plastic flow; none keeps the solid purely elastic and stores no
    /// plastic strain.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plasticity: Option<Plasticity>,
    /// Cracks (tutorial Section 7.3): when they start, how they cut the
    /// particles' pairs, how fast they run; none never cracks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fracture: Option<FractureSpec>,
    /// A high-resolution surface that follows the particles, carried by
    /// every frame (3D); none computes no surface.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface: Option<SolidSurfaceSpec>,
    /// The hyperelastic energy (`material = "stable_neo_hookean"` for a
    /// soft solid that must not collapse; see `solid::material`).
    #[serde(default, skip_serializing_if = "Hyperelastic::is_default")]
    pub material: Hyperelastic,
}

/// Cracks in a solid (tutorial Section 7.3), as a scene writes them: one
/// threshold, the criterion and its opacity, the front's pace and the
/// most cracks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FractureSpec {
    /// Brittle: the largest principal stress a particle bears, Pa.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stress: Option<Real>,
    /// With `stress`: the mode I fracture toughness `K_Ic`, Pa m^(1/2),
    /// with which a front runs when the stress a critical distance ahead
    /// of it passes `stress` (`Threshold::Toughness`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub toughness: Option<Real>,
    /// Ductile: the plastic strain norm a particle tears at.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plastic_strain: Option<Real>,
    /// How a crack cuts the pairs it passes between.
    #[serde(default)]
    pub criterion: CrackCriterion,
    /// Transparency's opacity scale, in particle spacings.
    #[serde(default = "default_kappa")]
    pub kappa: Real,
    /// The farthest a front advances per step, in particle spacings.
    #[serde(default = "default_advance")]
    pub advance: Real,
    /// Most cracks the solid may hold.
    #[serde(default = "default_max_cracks")]
    pub max_cracks: u32,
    /// A running front whose stress passes this many times the
    /// threshold splits in two; none never branches.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub branching: Option<Real>,
    /// Cracks the solid is built with (flaws, machined notches), which
    /// count against `max_cracks`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notches: Vec<NotchSpec>,
    /// Adaptive resampling where cracks hide neighbours (tutorial Eq.
    /// 71); none keeps the particles the solid is built with.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resample: Option<Resampling>,
    /// A 3D solid in pieces: the grid cell each piece's closed surface is
    /// cut on, in particle spacings.
    #[serde(default = "default_surface_cell")]
    pub surface_cell: Real,
}

/// A crack a solid is built with, world frame at the build: in 2D a
/// segment of half-length `radius` through `center` normal to `normal`,
/// in 3D a disc (a penny-shaped crack). Parts outside the body are inert.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NotchSpec {
    /// Its centre, m.
    pub center: [Real; 3],
    /// The normal of its plane (not zero; z = 0 in 2D).
    pub normal: [Real; 3],
    /// Half-length (2D) or radius (3D), m.
    pub radius: Real,
}

impl NotchSpec {
    /// The engine's notch.
    pub fn notch(&self) -> Notch {
        Notch {
            center: vector(self.center),
            normal: vector(self.normal),
            radius: self.radius,
        }
    }
}

fn default_kappa() -> Real {
    FractureParams::DEFAULT_KAPPA
}
fn default_advance() -> Real {
    FractureParams::DEFAULT_ADVANCE
}
fn default_max_cracks() -> u32 {
    FractureParams::DEFAULT_MAX_CRACKS
}
fn default_surface_cell() -> Real {
    FractureParams::DEFAULT_SURFACE_CELL
}

impl FractureSpec {
    /// The engine's parameters (a stress threshold of 0 where none is
    /// set, which validation refuses first).
    pub fn params(&self) -> FractureParams {
        let threshold = match (self.stress, self.toughness, self.plastic_strain) {
            (None, _, Some(plastic_strain)) => Threshold::PlasticStrain { plastic_strain },
            (stress, Some(toughness), _) => Threshold::Toughness {
                stress: stress.unwrap_or(0.0),
                toughness,
            },
            (stress, None, _) => Threshold::Stress {
                stress: stress.unwrap_or(0.0),
            },
        };
        FractureParams {
            threshold,
            discontinuity: match self.criterion {
                CrackCriterion::Transparency => Discontinuity::Transparency { kappa: self.kappa },
                CrackCriterion::Visibility => Discontinuity::Visibility,
            },
            advance: self.advance,
            max_cracks: self.max_cracks,
            branching: self.branching,
            resample: self.resample,
            surface_cell: self.surface_cell,
        }
    }
}

/// A fracture table's notches, for a solid of `particles` particles:
/// each in range, and room for them all (`check_room`, as `Body::notch`
/// checks again).
fn check_notches(
    at: &str,
    fracture: &FractureSpec,
    spacing: Real,
    dim: usize,
    particles: usize,
) -> Result<(), SceneError> {
    let field = format!("{at}.fracture.notches");
    let notches: Vec<Notch> = fracture.notches.iter().map(NotchSpec::notch).collect();
    for (k, notch) in notches.iter().enumerate() {
        notch
            .validate(dim)
            .map_err(|e| SceneError::invalid(format!("{field}[{k}]"), e.to_string()))?;
    }
    check_room(
        &notches,
        (0, 0),
        fracture.max_cracks,
        (dim, spacing, particles),
    )
    .map_err(|e| SceneError::invalid(field, e.to_string()))
}

/// The surface embedded in a solid (tutorial Section 7.2): the shape's own
/// surface, a mesh shape's file or a box or sphere tessellated finely,
/// deformed with the particles.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolidSurfaceSpec {
    /// `shape_functions` (Alternative 1: per-vertex MLS shape functions,
    /// precomputed) or `gradients` (Alternative 2, Eq. 68: the particles'
    /// displacement gradients, less memory).
    #[serde(default = "default_embedding")]
    pub method: EmbeddingMethod,
    /// Midpoint subdivisions of a box's faces (12 * 4^n triangles) or of a
    /// sphere's icosahedron (20 * 4^n); a mesh shape uses its own mesh.
    #[serde(default = "default_subdivisions")]
    pub subdivisions: u32,
}

fn default_embedding() -> EmbeddingMethod {
    EmbeddingMethod::ShapeFunctions
}
fn default_subdivisions() -> u32 {
    defaults::SURFACE_SUBDIVISIONS
}

fn default_density() -> Real {
    defaults::DENSITY
}
fn default_poisson() -> Real {
    defaults::POISSON
}
fn default_order() -> Order {
    defaults::ORDER
}
fn default_support() -> Real {
    defaults::SUPPORT
}
fn default_hourglass() -> Real {
    defaults::HOURGLASS
}
fn default_friction() -> Real {
    defaults::FRICTION
}
fn default_cfl() -> Real {
    defaults::CFL
}

impl SolidSpec {
    /// The engine parameters in `dim` dimensions.
    pub fn params(&self, dim: usize) -> SolidParams {
        SolidParams {
            dim,
            spacing: self.spacing,
            density: self.density,
            young: self.young,
            material: Material::from_young_poisson(self.young, self.poisson, self.volume_stiffness)
                .with_model(self.material),
            order: self.order,
            support: self.support * self.spacing,
            hourglass: self.hourglass,
            damping: self.damping,
            friction: self.friction,
            integrator: match self.integrator {
                IntegratorKind::Explicit => Integrator::Explicit { cfl: self.cfl },
                IntegratorKind::Implicit => Integrator::Implicit(self.implicit),
            },
            plasticity: self.plasticity,
            fracture: self.fracture.as_ref().map(FractureSpec::params),
        }
    }

    /// The surface mesh in the world frame at the rest shape: the same
    /// placement as the particles.
    pub(crate) fn surface_mesh(
        &self,
        shape: &Shape,
        dim: usize,
        subdivisions: u32,
    ) -> Option<TriMesh> {
        let local = match shape {
            Shape::Box { half_extents } => {
                TriMesh::cuboid(-half_extents, *half_extents).subdivided(subdivisions)
            }
            Shape::Sphere { radius } => TriMesh::icosphere(Vector::zeros(), *radius, subdivisions),
            Shape::Mesh(solid) => solid.mesh().clone(),
            Shape::Capsule { .. } | Shape::Plane { .. } => return None,
        };
        let (centre, rotation) = shape_pose(self.position, self.orientation, shape, dim);
        Some(TriMesh {
            vertices: local
                .vertices
                .iter()
                .map(|v| centre + rotation * v)
                .collect(),
            triangles: local.triangles,
        })
    }

    /// The embedded surface of a solid whose particles rest at `rest`, and
    /// for a fracturing solid its reference surface as a distance field
    /// (each piece's surface is cut from it once the solid breaks,
    /// `solid/fracture/fragment_surface.rs`).
    pub(crate) fn embedded_surface(
        &self,
        shape: &Shape,
        dim: usize,
        rest: &[Vector],
    ) -> Option<Result<SolidSurfaces, String>> {
        let spec = self.surface.as_ref()?;
        let Some(mesh) = self.surface_mesh(shape, dim, spec.subdivisions) else {
            return Some(Err(
                "a capsule has no surface mesh here; use a box, a sphere or a mesh shape".into(),
            ));
        };
        let embedded = EmbeddedSurface::new(
            &mesh,
            rest,
            dim,
            self.support * self.spacing,
            self.order,
            spec.method,
        );
        let outline = self
            .fracture
            .as_ref()
            .map(|_| MeshSdf::new(&mesh).map(Arc::new))
            .transpose();
        Some(match (embedded, outline) {
            (Ok(embedded), Ok(outline)) => Ok((embedded, outline)),
            (Err(e), _) => Err(e.to_string()),
            (_, Err(e)) => Err(e.to_string()),
        })
    }

    /// Whether a particle at `x` lies in one of the anchor boxes, and so
    /// is fixed.
    pub(crate) fn anchored(&self, x: &Vector, dim: usize) -> bool {
        self.anchors.iter().any(|b| inside(b, x, dim))
    }

    /// Particle positions (world frame) and initial velocities.
    pub(crate) fn particles(&self, shape: &Shape, dim: usize) -> Vec<(Vector, Vector)> {
        let (centre, rotation) = shape_pose(self.position, self.orientation, shape, dim);
        let (v, w) = (vector(self.velocity), vector(self.angular_velocity));
        shape
            .sample_volume(self.spacing, dim)
            .unwrap_or_default()
            .into_iter()
            .map(|local| {
                let x = centre + rotation * local;
                let mut velocity = v + w.cross(&(x - centre));
                if dim == 2 {
                    velocity.z = 0.0;
                }
                (x, velocity)
            })
            .collect()
    }
}

impl SolidSpec {
    /// Checks the solid against `context` and samples its particles and
    /// surface for the build.
    pub(super) fn prepare(
        &self,
        at: &str,
        context: &SceneContext,
        max_particles: u64,
    ) -> Result<SampledSolid, SceneError> {
        let solid = self;
        let dim = context.dimension;
        let shape_at = format!("{at}.shape");
        if matches!(solid.shape, ShapeSpec::Plane { .. }) {
            return Err(SceneError::invalid(
                shape_at,
                "a solid must be bounded; use a box, sphere, capsule or closed mesh",
            ));
        }
        let shape = checked_shape(&shape_at, &solid.shape, dim)?;
        check_vector(&format!("{at}.position"), solid.position)?;
        check_vector(&format!("{at}.orientation"), solid.orientation)?;
        check_vector(&format!("{at}.velocity"), solid.velocity)?;
        check_vector(&format!("{at}.angular_velocity"), solid.angular_velocity)?;
        check_positive(&format!("{at}.spacing"), solid.spacing)?;
        check_positive(&format!("{at}.density"), solid.density)?;
        check_range(&format!("{at}.density"), solid.density, 1e-3, 1e6)?;
        check_positive(&format!("{at}.young"), solid.young)?;
        check_range(&format!("{at}.young"), solid.young, 0.0, 1e13)?;
        check_range(&format!("{at}.poisson"), solid.poisson, 0.0, 0.4999)
            .map_err(|e| e.with_hint("0.5 is incompressible, which Hooke's law cannot hold"))?;
        check_range(
            &format!("{at}.volume_stiffness"),
            solid.volume_stiffness,
            0.0,
            1e13,
        )?;
        check_range(&format!("{at}.support"), solid.support, 1.5, 6.0).map_err(|e| {
            e.with_hint(
                "the support is in spacings; below 1.5 a particle sees no diagonal neighbours",
            )
        })?;
        check_range(&format!("{at}.hourglass"), solid.hourglass, 0.0, 10.0)?;
        check_range(&format!("{at}.damping"), solid.damping, 0.0, 1e6)?;
        check_range(&format!("{at}.friction"), solid.friction, 0.0, 10.0)?;
        check_positive(&format!("{at}.cfl"), solid.cfl)?;
        check_range(&format!("{at}.cfl"), solid.cfl, 0.0, 1.0)?;
        let implicit = &solid.implicit;
        check_positive(
            &format!("{at}.implicit.newton_tolerance"),
            implicit.newton_tolerance,
        )?;
        check_range(
            &format!("{at}.implicit.newton_tolerance"),
            implicit.newton_tolerance,
            0.0,
            1.0,
        )?;
        check_positive(
            &format!("{at}.implicit.cg_tolerance"),
            implicit.cg_tolerance,
        )?;
        check_range(
            &format!("{at}.implicit.cg_tolerance"),
            implicit.cg_tolerance,
            0.0,
            1.0,
        )?;
        for (field, value) in [
            ("max_newton_iterations", implicit.max_newton_iterations),
            ("max_cg_iterations", implicit.max_cg_iterations),
        ] {
            if value == 0 || value > 100_000 {
                return Err(SceneError::invalid(
                    format!("{at}.implicit.{field}"),
                    format!("must be in [1, 100000], got {value}"),
                ));
            }
        }
        if implicit.scheme == ImplicitScheme::Static {
            if solid.integrator != IntegratorKind::Implicit {
                return Err(SceneError::invalid(
                    format!("{at}.implicit.scheme"),
                    "\"static\" is an implicit scheme; set integrator = \"implicit\"",
                ));
            }
            if solid.anchors.is_empty() {
                return Err(SceneError::invalid(
                    format!("{at}.implicit.scheme"),
                    "\"static\" needs anchors: a free body has no equilibrium under gravity; \
                     add anchors or choose backward_euler",
                ));
            }
        }
        if let Some(p) = &solid.plasticity {
            if solid.material != Hyperelastic::StVenantKirchhoff {
                return Err(SceneError::invalid(
                    format!("{at}.plasticity"),
                    "plastic flow is written on St Venant-Kirchhoff's Green strain; remove \
                     plasticity or set material = \"st_venant_kirchhoff\"",
                ));
            }
            check_range(&format!("{at}.plasticity.yield"), p.yield_strain, 0.0, 10.0)?;
            check_positive(&format!("{at}.plasticity.creep"), p.creep)?;
            check_range(&format!("{at}.plasticity.creep"), p.creep, 0.0, 1.0)?;
            check_range(&format!("{at}.plasticity.max"), p.max, 0.0, 100.0)?;
            if let Some(r) = p.rebase {
                check_positive(&format!("{at}.plasticity.rebase"), r)?;
            }
        }
        if let Some(f) = &solid.fracture {
            if f.stress.is_some() == f.plastic_strain.is_some() {
                return Err(SceneError::invalid(
                    format!("{at}.fracture"),
                    "set one threshold: stress (brittle, Pa) or plastic_strain (ductile)",
                ));
            }
            if f.toughness.is_some() && f.stress.is_none() {
                return Err(SceneError::invalid(
                    format!("{at}.fracture.toughness"),
                    "a toughness needs the strength that starts cracks: set stress (Pa) too",
                ));
            }
            let rebases = solid.plasticity.is_some_and(|p| p.rebase.is_some());
            f.params()
                .validate(solid.spacing, solid.plasticity.is_some(), rebases)
                .map_err(|e| SceneError::invalid(format!("{at}.fracture"), e.to_string()))?;
        }
        if dim == 2 {
            for (field, v) in [
                ("orientation", solid.orientation),
                ("angular_velocity", solid.angular_velocity),
            ] {
                if v[0] != 0.0 || v[1] != 0.0 {
                    return Err(SceneError::invalid(
                        format!("{at}.{field}"),
                        "in 2D a solid only turns about z; set x and y to 0",
                    ));
                }
            }
        }
        let reach = shape.bounding_radius(dim);
        let cells = (2.0 * reach / solid.spacing).ceil().powi(dim as i32);
        if cells > crate::geometry::MAX_SAMPLES as Real {
            return Err(SceneError::TooFine {
                field: format!("{at}.spacing"),
                points: cells.min(u64::MAX as Real) as u64,
                limit: crate::geometry::MAX_SAMPLES as u64,
            });
        }
        // Sampling allocates for every particle and an embedded surface
        // costs MLS work per vertex, so a solid beyond the host's limit is
        // refused before either: first by its lattice's expected count
        // (volume / spacing^dim, refused at twice the limit so that the
        // estimate's boundary error never refuses a scene that fits),
        // then by the count sampled.
        let too_many = |count: u64| SceneError::TooManyParticles {
            count,
            limit: max_particles,
        };
        let expected = shape.volume(dim).unwrap_or(0.0) / solid.spacing.powi(dim as i32);
        if expected > 2.0 * max_particles as Real {
            return Err(too_many(expected.round().min(u64::MAX as Real) as u64));
        }
        let particles = solid.particles(&shape, dim);
        if particles.len() as u64 > max_particles {
            return Err(too_many(particles.len() as u64));
        }
        if particles.is_empty() {
            return Err(SceneError::invalid(
                format!("{at}.spacing"),
                format!(
                    "is too coarse: no lattice point at spacing {} m falls inside the shape; \
                     lower it",
                    solid.spacing
                ),
            ));
        }
        let radius = 0.5 * solid.spacing;
        if let Some((x, _)) = particles.iter().find(|(x, _)| {
            (0..dim).any(|a| {
                x[a] < context.domain.min[a] + radius || x[a] > context.domain.max[a] - radius
            })
        }) {
            return Err(SceneError::invalid(
                format!("{at}.position"),
                format!(
                    "the solid reaches outside the domain (a particle at {:?}); move it or \
                     enlarge the domain",
                    [x.x, x.y, x.z]
                ),
            ));
        }
        for (k, anchor) in solid.anchors.iter().enumerate() {
            let field = format!("{at}.anchors[{k}]");
            check_box(&field, anchor, dim)?;
            if !particles.iter().any(|(x, _)| inside(anchor, x, dim)) {
                return Err(SceneError::invalid(
                    field,
                    "holds no particle of the solid; enlarge it or move it onto the solid",
                ));
            }
        }
        if let Some(f) = &solid.fracture {
            check_notches(at, f, solid.spacing, dim, particles.len())?;
            if let Some(limit) = f.resample.and_then(|r| r.max_particles)
                && (limit as usize) < particles.len()
            {
                return Err(SceneError::invalid(
                    format!("{at}.fracture.resample.max_particles"),
                    format!(
                        "is {limit}, under the {} particles the solid is built with; raise it \
                         or leave it out (twice the built count)",
                        particles.len()
                    ),
                ));
            }
        }
        if let Some(surface) = &solid.surface {
            let field = format!("{at}.surface");
            if dim != 3 {
                return Err(SceneError::invalid(
                    field,
                    "embedded surfaces are 3D only; set dimension = 3 or remove it",
                ));
            }
            if surface.subdivisions > 7 {
                return Err(SceneError::invalid(
                    format!("{field}.subdivisions"),
                    format!(
                        "must be in [0, 7] (4^7 times the base triangles), got {}",
                        surface.subdivisions
                    ),
                ));
            }
        }
        // Built here rather than at the build: checking a surface means
        // building it, its MLS work per vertex is the dearest part of a
        // solid's admission, and the build takes it from here.
        let rest: Vec<Vector> = particles.iter().map(|(x, _)| *x).collect();
        let (surface, outline) = solid
            .embedded_surface(&shape, dim, &rest)
            .transpose()
            .map_err(|e| SceneError::invalid(format!("{at}.surface"), e))?
            .map_or((None, None), |(surface, outline)| (Some(surface), outline));
        Ok(SampledSolid {
            particles,
            surface,
            outline,
        })
    }

    /// The most particles the solid may hold once built with `built`:
    /// more only where it resamples. What the scene is admitted with.
    pub(crate) fn capacity(&self, built: usize) -> usize {
        self.fracture
            .as_ref()
            .and_then(|f| f.resample)
            .map_or(built, |r| r.capacity(built).max(built))
    }
}

/// A solid's embedded surface and, for a fracturing solid, its reference
/// surface as a distance field.
type SolidSurfaces = (EmbeddedSurface, Option<Arc<MeshSdf>>);

/// What admitting a solid made, kept for its build: its particles' rest
/// positions and initial velocities, and its embedded surface.
#[derive(Debug, Clone)]
pub(crate) struct SampledSolid {
    pub(crate) particles: Vec<(Vector, Vector)>,
    pub(crate) surface: Option<EmbeddedSurface>,
    /// The reference surface as a distance field, for a fracturing solid
    /// with a surface.
    pub(crate) outline: Option<Arc<MeshSdf>>,
}

fn inside(b: &Aabb, x: &Vector, dim: usize) -> bool {
    (0..dim).all(|a| x[a] >= b.min[a] && x[a] <= b.max[a])
}
