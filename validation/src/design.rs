//! The optimiser's reference experiments, shared by the validation tests,
//! `meshless study` and the benchmarks.
//!
//! - [`Stretch`]: the tutorial's Figure 13. A 1 x 1 x 2 m box has its
//!   bottom fixed and its top pulled up by half its height. With rigidity
//!   alone the volume grows (the tutorial reports +53 %); with the volume
//!   energy it stays within 3 %.
//! - [`Passage`]: a 0.5 m cube travels 4 m through three keyframes; a
//!   ball stands beside the straight path between the first two, so the
//!   keyframes alone drive the cube through it and only the obstacle term
//!   between frames, found by adaptive temporal sampling, steers it clear.

use meshless_engine::design::{
    Constraint, ConstraintKind, ConstraintSet, Context, DesignBody, DesignError, DesignParams,
    Edit, Handle, MotionParams, MotionSolution, Obstacle, Progress, Quadrature, Selection,
    ShapeSolution, Target, Waypoint, solve_motion, solve_shape,
};
use meshless_engine::geometry::{Shape, TriMesh};
use meshless_engine::math::{Real, Vector};
use meshless_engine::scene::ShapeSpec;
use meshless_engine::solid::embedded::DeformedSurface;
use nalgebra::{Matrix3, Rotation3};
use std::ops::ControlFlow;
use std::time::{Duration, Instant};

fn quiet(_: &Progress) -> ControlFlow<()> {
    ControlFlow::Continue(())
}

/// A handle on every design particle in the box `[min, max]`, moved by
/// `translation` (and turned by `rotation` about `centre`).
pub fn region_handle(
    name: &str,
    min: [Real; 3],
    max: [Real; 3],
    translation: [Real; 3],
    rotation: [Real; 3],
    time: Option<Real>,
) -> Constraint {
    Constraint {
        name: name.into(),
        kind: ConstraintKind::Handle(Handle {
            points: Selection::Region { min, max },
            target: Target::Transform {
                translation,
                rotation,
                centre: [0.0; 3],
            },
            time,
        }),
    }
}

fn constraint_set(constraints: Vec<Constraint>) -> ConstraintSet {
    let mut set = ConstraintSet::new();
    let edits: Vec<Edit> = constraints.into_iter().map(Edit::Add).collect();
    set.apply(
        &edits,
        &Context {
            dim: 3,
            solids: Vec::new(),
        },
    )
    .expect("the experiment's constraints are valid");
    set
}

/// About `particles` design particles in a box of `half` extents centred
/// on the origin.
fn box_body(
    half: Vector,
    particles: u32,
    params: &DesignParams,
) -> Result<DesignBody, DesignError> {
    let shape = Shape::Box { half_extents: half };
    let params = DesignParams {
        particles,
        ..*params
    };
    DesignBody::new(
        &shape,
        Vector::zeros(),
        Rotation3::identity(),
        3,
        &params,
        None,
    )
}

/// The tutorial's Figure 13 stretch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stretch {
    /// About this many design particles.
    pub particles: u32,
    /// How far the top moves up, m (the box is 2 m tall).
    pub pull: Real,
}

impl Default for Stretch {
    fn default() -> Self {
        Self {
            particles: 128,
            pull: 1.0,
        }
    }
}

/// What a [`Stretch`] solve gave.
#[derive(Debug, Clone)]
pub struct StretchResult {
    /// Design particles of the box.
    pub particles: usize,
    /// Volume enclosed by the deformed surface over the rest volume, - 1.
    pub volume_change: Real,
    /// `sum_i V_i det F_i / V - 1` at the quadrature points.
    pub discrete_volume_change: Real,
    /// Largest distance of a handle point from its target, in spacings.
    pub handle_error: Real,
    /// The solve itself.
    pub solution: ShapeSolution,
    /// Wall time of the solve, without building the body or measuring.
    pub elapsed: Duration,
}

impl Stretch {
    const HALF: [Real; 3] = [0.5, 0.5, 1.0];

    /// The box's design particles.
    ///
    /// # Errors
    /// From [`DesignBody::new`] for unusable `params`.
    pub fn body(&self, params: &DesignParams) -> Result<DesignBody, DesignError> {
        box_body(Vector::from(Self::HALF), self.particles, params)
    }

    /// Bottom fixed, top pulled up.
    pub fn constraints(&self) -> ConstraintSet {
        constraint_set(vec![
            region_handle(
                "bottom",
                [-1.0, -1.0, -2.0],
                [1.0, 1.0, -0.8],
                [0.0; 3],
                [0.0; 3],
                None,
            ),
            Self::top(self.pull),
        ])
    }

    /// The top handle, pulled up by `pull` m: replace it to drag the top.
    pub fn top(pull: Real) -> Constraint {
        region_handle(
            "top",
            [-1.0, -1.0, 0.8],
            [1.0, 1.0, 2.0],
            [0.0, 0.0, pull],
            [0.0; 3],
            None,
        )
    }

    /// The box's surface, 768 triangles.
    pub fn mesh() -> TriMesh {
        Self::surface_mesh(3)
    }

    /// The box's surface with each of its 12 triangles split `times`
    /// times into four: 7 gives 196,608 triangles and 98,306 vertices, a
    /// render mesh for timing.
    pub fn surface_mesh(times: u32) -> TriMesh {
        let h = Vector::from(Self::HALF);
        TriMesh::cuboid(-h, h).subdivided(times)
    }

    /// Solves and measures.
    ///
    /// # Errors
    /// From the solve.
    pub fn solve(&self, params: &DesignParams) -> Result<StretchResult, DesignError> {
        let body = self.body(params)?;
        let constraints = self.constraints();
        let start = Instant::now();
        let solution = solve_shape(&body, &constraints, params, None, &mut quiet)?;
        let elapsed = start.elapsed();
        let mesh = Self::mesh();
        let surface = body.surface(&mesh)?;
        let positions: Vec<Vector> = body
            .rest()
            .iter()
            .zip(&solution.displacements)
            .map(|(x, u)| x + u)
            .collect();
        let mut deformed = DeformedSurface::new();
        surface
            .update(&positions, &[], &mut deformed)
            .map_err(|e| DesignError::Surface(e.to_string()))?;
        let volume_change =
            deformed.to_mesh(surface.triangles()).signed_volume() / mesh.signed_volume() - 1.0;
        let (quadrature, volumes) = body.quadrature();
        let total: Real = volumes.iter().sum();
        let discrete_volume_change = (0..quadrature.len())
            .map(|q| {
                volumes[q]
                    * (Matrix3::identity()
                        + quadrature.displacement_gradient(q, &solution.displacements))
                    .determinant()
            })
            .sum::<Real>()
            / total
            - 1.0;
        let mut handle_error: Real = 0.0;
        for c in constraints.iter() {
            let ConstraintKind::Handle(h) = &c.kind else {
                continue;
            };
            let points = body.select(&h.points).map_err(DesignError::Problem)?;
            let targets = h.target.resolve(&points);
            let embedding = body.embed(&points)?;
            for (k, target) in targets.iter().enumerate() {
                let at = points[k] + embedding.displacement(k, &solution.displacements);
                handle_error = handle_error.max((at - target).norm() / body.spacing());
            }
        }
        Ok(StretchResult {
            particles: body.len(),
            volume_change,
            discrete_volume_change,
            handle_error,
            solution,
            elapsed,
        })
    }
}

/// The cube passing a ball between keyframes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Passage {
    /// About this many design particles.
    pub particles: u32,
    /// Whether the ball is there.
    pub obstacle: bool,
}

impl Default for Passage {
    fn default() -> Self {
        Self {
            particles: 200,
            obstacle: true,
        }
    }
}

/// The ball: centred 0.45 m beside the path at x = 1 m, radius 0.3 m.
pub const PASSAGE_BALL: ([Real; 3], Real) = ([1.0, 0.45, 0.0], 0.3);

/// Keyframe times and the cube's translation at each.
pub const PASSAGE_KEYFRAMES: [(Real, [Real; 3]); 3] = [
    (0.0, [0.0, 0.0, 0.0]),
    (1.0, [2.0, 0.0, 0.0]),
    (2.0, [4.0, 0.0, 0.0]),
];

/// What a [`Passage`] solve gave.
#[derive(Debug, Clone)]
pub struct PassageResult {
    /// Design particles of the cube.
    pub particles: usize,
    /// Deepest penetration of a particle sphere into the ball over 201
    /// evenly spaced times, in spacings (0 when clear).
    pub penetration: Real,
    /// Largest distance of a particle from its keyframe target, in
    /// spacings.
    pub keyframe_error: Real,
    /// The solve itself.
    pub solution: MotionSolution,
    /// Wall time of the solve, without building the body or measuring.
    pub elapsed: Duration,
}

impl Passage {
    /// The cube's design particles.
    ///
    /// # Errors
    /// From [`DesignBody::new`].
    pub fn body(&self, params: &DesignParams) -> Result<DesignBody, DesignError> {
        box_body(Vector::repeat(0.25), self.particles, params)
    }

    /// Keyframes on every particle and the ball.
    pub fn constraints(&self) -> ConstraintSet {
        let mut constraints: Vec<Constraint> = PASSAGE_KEYFRAMES
            .iter()
            .enumerate()
            .map(|(k, &(t, shift))| {
                region_handle(
                    &format!("key{k}"),
                    [-1.0; 3],
                    [1.0; 3],
                    shift,
                    [0.0; 3],
                    Some(t),
                )
            })
            .collect();
        if self.obstacle {
            let (at, radius) = PASSAGE_BALL;
            constraints.push(Constraint {
                name: "ball".into(),
                kind: ConstraintKind::Obstacle(Obstacle {
                    shape: ShapeSpec::Sphere { radius },
                    orientation: [0.0; 3],
                    path: vec![Waypoint {
                        time: 0.0,
                        position: at,
                    }],
                }),
            });
        }
        constraint_set(constraints)
    }

    /// Solves and measures.
    ///
    /// # Errors
    /// From the solve.
    pub fn solve(
        &self,
        params: &DesignParams,
        motion: &MotionParams,
    ) -> Result<PassageResult, DesignError> {
        let body = self.body(params)?;
        let start = Instant::now();
        let solution = solve_motion(&body, &self.constraints(), params, motion, &mut quiet)?;
        let elapsed = start.elapsed();
        let s = body.spacing();
        let field = body.field();
        let (centre, radius) = (Vector::from(PASSAGE_BALL.0), PASSAGE_BALL.1);
        let mut penetration: Real = 0.0;
        for k in 0..=200 {
            let t = 2.0 * k as Real / 200.0;
            let u = solution.displacements_at(t)?;
            for (i, x) in body.rest().iter().enumerate() {
                let p = x + field.displacement(i, &u);
                let clearance = (p - centre).norm() - radius;
                penetration = penetration.max((motion.radius * s - clearance) / s);
            }
        }
        let mut keyframe_error: Real = 0.0;
        for &(t, shift) in &PASSAGE_KEYFRAMES {
            let u = solution.displacements_at(t)?;
            for (i, x) in body.rest().iter().enumerate() {
                let at = x + field.displacement(i, &u);
                keyframe_error = keyframe_error.max((at - x - Vector::from(shift)).norm() / s);
            }
        }
        Ok(PassageResult {
            particles: body.len(),
            penetration,
            keyframe_error,
            solution,
            elapsed,
        })
    }
}

/// Figure 13's settings: volume measured over cells, volume weight 300.
pub fn stretch_params(volume: bool) -> DesignParams {
    let mut params = DesignParams {
        quadrature: Quadrature::Cells,
        ..DesignParams::default()
    };
    params.weights.volume = if volume { 300.0 } else { 0.0 };
    params
}
