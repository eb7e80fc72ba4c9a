//! Motion design (tutorial Section 8.2): a smooth deformable motion
//! through keyframes, at given velocities, around obstacles.
//!
//! The unknowns are the design particles' displacements `u_(i,j)` at
//! frames `t_j`; the temporal MLS blends them into `u(x, t) = sum_j
//! Phi_j(t) sum_i phi_i(x) u_(i,j)` (Eq. 81) with analytic time
//! derivatives. The energy (Eq. 85) sums
//!
//! - keyframes: handles with a time, on `f(x_k, t_k)` (Eq. 74 per keyframe);
//! - rigidity and volume within each frame (Eq. 76-77 on `u_(., j)`, as
//!   the tutorial says), weighted by the frame's support `h_j`;
//! - velocity at keyframe times on `du/dt` (Eq. 82);
//! - acceleration at each frame time on `d2u_i/dt2`, the particles' own
//!   displacements, weighted by `h_j` (Eq. 83);
//! - obstacles: each particle a sphere of radius `r` kept out of every
//!   obstacle at each frame time, weighted by `h_j` (Eq. 84 with the
//!   tutorial's fattening).
//!
//! **Initial frames and guess.** The frames start at the keyframes, plus
//! one in the middle of each interval next to a velocity constraint (three
//! frames fix the quadratic blend, leaving a velocity no freedom). Each
//! keyframe is first solved as a shape problem (its handles alone, from
//! the previous keyframe's pose carried by the rigid motion that best fits
//! its handles), the extra frames start between them, and the joint solve
//! goes on from there.
//!
//! **Adaptive temporal sampling.** The penalties hold only at frames, so
//! the motion between them may pass through an obstacle or shear. After
//! each solve the error (the worst sphere penetration in spacings, and the
//! worst non-rigidity `|grad f^T grad f - I|_F`) is checked at
//! `samples` times between consecutive frames; a frame is inserted where
//! it is largest, initialised from the current motion (`u_(i,new) = sum_j
//! Phi_j(t) u_(i,j)`), and the motion solved again, until the error is
//! below the tolerance or `max_frames` is reached. One frame goes into
//! every interval over the tolerance at once, not only the worst in the
//! whole motion as in the tutorial: the intervals are independent, and
//! this needs fewer re-solves.

use super::body::{DesignBody, Embedding};
use super::constraints::{ConstraintKind, ConstraintSet, resolve_shape};
use super::energy::{deformation_gradient, push_shape_terms};
use super::lsq::{self, LeastSquares, Rows, RunState, Term};
use super::progress::{Observer, SolveInfo};
use super::shape::{Handles, Start, push_point, scale_into, solve_handles, unscale};
use super::temporal::{TemporalBasis, TemporalWeight};
use super::{DesignError, DesignParams, MotionParams, SolverParams, Weights};
use crate::cancel::Cancel;

/// Relative energy decrease that ends the solves between insertions.
const ROUGH_TOLERANCE: Real = 1e-2;
use crate::geometry::Shape;
use crate::math::{Real, Vector, vector};
use nalgebra::{Matrix3, Rotation3};

/// A solved motion: the design particles' displacements at each frame,
/// blended in time by the temporal MLS (Eq. 81).
#[derive(Debug, Clone)]
pub struct MotionSolution {
    basis: TemporalBasis,
    frames: Vec<Vec<Vector>>,
    /// How the last solve ended, with the frame count and sampling error.
    pub info: SolveInfo,
}

impl MotionSolution {
    /// Frame times, s (keyframes and inserted frames).
    pub fn times(&self) -> &[Real] {
        self.basis.times()
    }

    /// `u_(i, t_j)`: per frame, one displacement per design particle.
    pub fn frames(&self) -> &[Vec<Vector>] {
        &self.frames
    }

    /// First and last frame times.
    pub fn span(&self) -> (Real, Real) {
        let t = self.basis.times();
        (t[0], t[t.len() - 1])
    }

    /// The design particles' displacements at time `t` (Eq. 80).
    ///
    /// # Errors
    /// [`DesignError::Parameter`] for a time outside [`Self::span`].
    pub fn displacements_at(&self, t: Real) -> Result<Vec<Vector>, DesignError> {
        blend(&self.basis, &self.frames, t, Derivative::Value)
    }

    /// Their first time derivative at `t`.
    ///
    /// # Errors
    /// As [`Self::displacements_at`].
    pub fn velocities_at(&self, t: Real) -> Result<Vec<Vector>, DesignError> {
        blend(&self.basis, &self.frames, t, Derivative::First)
    }
}

/// Which of the blend's time derivatives [`blend`] returns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Derivative {
    /// The blended displacements, m.
    Value,
    /// Their first time derivative, m/s.
    First,
}

/// `sum_j Phi_j(t) u_(., j)` (Eq. 80), or its time derivative, of
/// per-frame displacements `frames` on `basis`: what a motion's playback
/// and a client holding only a result's frames both evaluate.
///
/// # Errors
/// [`DesignError::Parameter`] for a time outside the frames' span.
pub fn blend(
    basis: &TemporalBasis,
    frames: &[Vec<Vector>],
    t: Real,
    which: Derivative,
) -> Result<Vec<Vector>, DesignError> {
    let mut weights = Vec::new();
    basis
        .shape_functions(t, &mut weights)
        .map_err(|e| DesignError::Parameter {
            field: "time",
            message: e.to_string(),
        })?;
    let mut u = vec![Vector::zeros(); frames[0].len()];
    for w in &weights {
        let c = match which {
            Derivative::Value => w.value,
            Derivative::First => w.d1,
        };
        for (u, f) in u.iter_mut().zip(&frames[w.frame]) {
            *u += f * c;
        }
    }
    Ok(u)
}

/// An obstacle placed in the world, moving along its path.
#[derive(Debug, Clone)]
struct Placed {
    shape: Shape,
    rotation: Rotation3<Real>,
    path: Vec<(Real, Vector)>,
    dim: usize,
}

impl Placed {
    fn centre(&self, t: Real) -> Vector {
        let p = &self.path;
        match p.iter().position(|(time, _)| *time > t) {
            Some(0) => p[0].1,
            None => p[p.len() - 1].1,
            Some(k) => {
                let ((t0, x0), (t1, x1)) = (p[k - 1], p[k]);
                x0 + (x1 - x0) * ((t - t0) / (t1 - t0))
            }
        }
    }

    /// Signed distance (negative inside) and outward normal at `x`, time `t`.
    fn distance(&self, x: &Vector, t: Real) -> (Real, Vector) {
        let local = self.rotation.inverse() * (x - self.centre(t));
        (
            self.shape.signed_distance(&local, self.dim),
            self.rotation * self.shape.normal(&local, self.dim),
        )
    }
}

/// A set of points with targets at one time.
#[derive(Debug)]
struct Keyframe {
    time: Real,
    handles: Handles,
}

/// A velocity target at one time over a set of points.
#[derive(Debug)]
struct VelocityTarget {
    time: Real,
    velocity: Vector,
    points: Embedding,
    volumes: Vec<Real>,
}

/// Everything a motion problem is posed from, fixed while frames change.
struct Setup<'a> {
    body: &'a DesignBody,
    weights: Weights,
    keyframes: Vec<Keyframe>,
    velocities: Vec<VelocityTarget>,
    obstacles: Vec<Placed>,
    /// Sphere radius, m.
    radius: Real,
    /// Duration of the motion, s.
    duration: Real,
}

/// Solves the motion the timed handles (keyframes), velocities and
/// obstacles of `constraints` pose on `body`.
///
/// # Errors
/// As [`super::solve_shape`]; [`DesignError::Problem`] with fewer than
/// two keyframe times; [`DesignError::Constraint`] for a velocity outside
/// the keyframes' span; [`DesignError::Parameter`] for bad motion
/// settings.
pub fn solve_motion(
    body: &DesignBody,
    constraints: &ConstraintSet,
    params: &DesignParams,
    motion: &MotionParams,
    observer: &mut Observer<'_>,
) -> Result<MotionSolution, DesignError> {
    // A flag no one else holds is never raised.
    solve_motion_cancellable(body, constraints, params, motion, observer, &Cancel::new())
}

/// [`solve_motion`], stopped by another thread raising `cancel`: read at
/// every solver iteration and CG iteration of every solve the motion
/// takes, where the observer sees only whole iterations.
///
/// # Errors
/// As [`solve_motion`]; [`DesignError::Cancelled`] once `cancel` is
/// raised.
pub fn solve_motion_cancellable(
    body: &DesignBody,
    constraints: &ConstraintSet,
    params: &DesignParams,
    motion: &MotionParams,
    observer: &mut Observer<'_>,
    cancel: &Cancel,
) -> Result<MotionSolution, DesignError> {
    super::on_pool(|| motion_on_pool(body, constraints, params, motion, observer, cancel))
}

fn motion_on_pool(
    body: &DesignBody,
    constraints: &ConstraintSet,
    params: &DesignParams,
    motion: &MotionParams,
    observer: &mut Observer<'_>,
    cancel: &Cancel,
) -> Result<MotionSolution, DesignError> {
    super::check_params(params)?;
    check_motion(motion)?;
    let setup = Setup::new(body, constraints, params, motion)?;
    let keyframe_times: Vec<Real> = setup.keyframes.iter().map(|k| k.time).collect();
    let times = setup.initial_frames();
    let mut basis = TemporalBasis::new(&times).map_err(|e| DesignError::Problem(e.to_string()))?;
    let mut run = RunState {
        frames: times.len(),
        ..RunState::default()
    };

    // Keyframe poses as shape problems, each from the last carried
    // rigidly onto its handles.
    let mut frames: Vec<Vec<Vector>> = Vec::with_capacity(keyframe_times.len());
    for k in &setup.keyframes {
        let (u, _) = solve_handles(
            body,
            k.handles.points.rest(),
            k.handles.targets.clone(),
            params,
            Start::Rigid(frames.last().map(Vec::as_slice)),
            &mut run,
            observer,
            cancel,
        )?;
        frames.push(u);
    }
    // Frames beside the keyframes start on the line between them.
    let mut frames: Vec<Vec<Vector>> = times
        .iter()
        .map(|&t| {
            let k = keyframe_times.partition_point(|&kt| kt < t);
            if keyframe_times.get(k) == Some(&t) {
                return frames[k].clone();
            }
            let (t0, t1) = (keyframe_times[k - 1], keyframe_times[k]);
            let a = (t - t0) / (t1 - t0);
            frames[k - 1]
                .iter()
                .zip(&frames[k])
                .map(|(u0, u1)| u0 * (1.0 - a) + u1 * a)
                .collect()
        })
        .collect();

    let dim = body.dim();
    let s = body.spacing();
    let n = body.len();
    let mut polishing = false;
    loop {
        let problem = MotionProblem::new(&setup, &basis)?;
        let mut x = vec![0.0; frames.len() * n * dim];
        for (j, u) in frames.iter().enumerate() {
            scale_into(u, dim, s, &mut x[j * n * dim..(j + 1) * n * dim]);
        }
        // While frames are still being inserted a rough solve is enough
        // to tell where; the final one is polished to the tolerance.
        let rough = SolverParams {
            tolerance: params.solver.tolerance.max(ROUGH_TOLERANCE),
            ..params.solver
        };
        let polish = !motion.adaptive || polishing;
        let solver = if polish { &params.solver } else { &rough };
        let mut info = lsq::minimise(&problem, &mut x, solver, &mut run, observer, cancel)?;
        frames = x
            .chunks(n * dim)
            .map(|frame| unscale(frame, dim, s))
            .collect();
        let (error, worst) = setup.sampling_error(&basis, &frames, motion.samples)?;
        run.sampling_error = Some(error);
        info.sampling_error = Some(error);
        let room = (motion.max_frames as usize).saturating_sub(frames.len());
        let insert: Vec<Real> = worst
            .into_iter()
            .filter(|(e, _)| *e > motion.tolerance)
            .map(|(_, t)| t)
            .take(room)
            .collect();
        if insert.is_empty() && !polish {
            polishing = true;
            continue;
        }
        if polish || insert.is_empty() {
            info.frames = frames.len();
            info.inserted = run.inserted;
            return Ok(MotionSolution {
                basis,
                frames,
                info,
            });
        }
        for t in insert {
            let initial = blend(&basis, &frames, t, Derivative::Value)?;
            let (next, index) = basis
                .with_frame(t)
                .map_err(|e| DesignError::Problem(e.to_string()))?;
            basis = next;
            frames.insert(index, initial);
            run.inserted += 1;
        }
        run.frames = frames.len();
    }
}

/// Checks the motion settings, as [`solve_motion`] does before it starts;
/// public for the same reason as [`super::check_params`].
///
/// # Errors
/// [`DesignError::Parameter`] naming the first setting out of range.
pub fn check_motion(m: &MotionParams) -> Result<(), DesignError> {
    let invalid = |field, message: String| Err(DesignError::Parameter { field, message });
    if !(m.tolerance.is_finite() && m.tolerance > 0.0) {
        return invalid(
            "motion.tolerance",
            format!("is {}; give a positive number", m.tolerance),
        );
    }
    if m.samples == 0 || m.samples > 1000 {
        return invalid(
            "motion.samples",
            format!("is {}; give 1 to 1000", m.samples),
        );
    }
    if m.max_frames < 2 {
        return invalid(
            "motion.max_frames",
            format!("is {}; allow at least 2", m.max_frames),
        );
    }
    if !(m.radius.is_finite() && m.radius >= 0.0) {
        return invalid(
            "motion.radius",
            format!("is {}; give 0 or more spacings", m.radius),
        );
    }
    Ok(())
}

impl<'a> Setup<'a> {
    fn new(
        body: &'a DesignBody,
        constraints: &ConstraintSet,
        params: &DesignParams,
        motion: &MotionParams,
    ) -> Result<Self, DesignError> {
        let mut times: Vec<Real> = constraints
            .iter()
            .filter_map(|c| match &c.kind {
                ConstraintKind::Handle(h) => h.time,
                _ => None,
            })
            .collect();
        times.sort_by(Real::total_cmp);
        times.dedup();
        if times.len() < 2 {
            return Err(DesignError::Problem(format!(
                "a motion needs handles at two keyframe times or more; found {}",
                times.len()
            )));
        }
        let mut keyframes = Vec::with_capacity(times.len());
        for &time in &times {
            let (points, targets) = Handles::resolve(body, constraints, |t| t == Some(time))?;
            keyframes.push(Keyframe {
                time,
                handles: Handles {
                    points: body.embed(&points)?,
                    targets,
                },
            });
        }
        let (start, end) = (times[0], times[times.len() - 1]);
        let mut velocities = Vec::new();
        let mut obstacles = Vec::new();
        let dim = body.dim();
        for c in constraints.iter() {
            match &c.kind {
                ConstraintKind::Handle(_) => {}
                ConstraintKind::Velocity(v) => {
                    if !(start..=end).contains(&v.time) {
                        return Err(DesignError::constraint(
                            &c.name,
                            format!(
                                "time {} lies outside the keyframes' span [{start}, {end}]",
                                v.time
                            ),
                        ));
                    }
                    let (points, volumes) = match &v.points {
                        Some(selection) => {
                            let at = body
                                .select(selection)
                                .map_err(|m| DesignError::constraint(&c.name, m))?;
                            let ones = vec![1.0; at.len()];
                            (body.embed(&at)?, ones)
                        }
                        None => (body.field().clone(), body.volumes().to_vec()),
                    };
                    velocities.push(VelocityTarget {
                        time: v.time,
                        velocity: vector(v.velocity),
                        points,
                        volumes,
                    });
                }
                ConstraintKind::Obstacle(o) => {
                    let shape = resolve_shape(&o.shape, dim)
                        .map_err(|m| DesignError::constraint(&c.name, m))?;
                    let (_, rotation) =
                        crate::scene::shape_pose([0.0; 3], o.orientation, &shape, dim);
                    obstacles.push(Placed {
                        shape,
                        rotation: rotation.to_rotation_matrix(),
                        path: o
                            .path
                            .iter()
                            .map(|w| {
                                let mut p = vector(w.position);
                                if dim == 2 {
                                    p.z = 0.0;
                                }
                                (w.time, p)
                            })
                            .collect(),
                        dim,
                    });
                }
            }
        }
        Ok(Self {
            body,
            weights: params.weights,
            keyframes,
            velocities,
            obstacles,
            radius: motion.radius * body.spacing(),
            duration: end - start,
        })
    }

    /// The keyframe times, and the middle of every interval next to a
    /// velocity constraint: through three frames the quadratic blend is
    /// fixed, so a velocity needs a frame of its own to bend the path.
    fn initial_frames(&self) -> Vec<Real> {
        let keys: Vec<Real> = self.keyframes.iter().map(|k| k.time).collect();
        let mut times = keys.clone();
        for w in keys.windows(2) {
            if self
                .velocities
                .iter()
                .any(|v| (w[0]..=w[1]).contains(&v.time))
            {
                times.push(0.5 * (w[0] + w[1]));
            }
        }
        times.sort_by(Real::total_cmp);
        times
    }

    /// The largest error between frames and, per interval, its largest
    /// error and where.
    fn sampling_error(
        &self,
        basis: &TemporalBasis,
        frames: &[Vec<Vector>],
        samples: u32,
    ) -> Result<(Real, Vec<(Real, Real)>), DesignError> {
        let times = basis.times();
        // The distortion the frames themselves hold is the optimum's, not
        // an error of the sampling: only what the blend adds counts.
        let own: Vec<Real> = frames.iter().map(|u| self.distortion(u)).collect();
        let mut worst = Vec::with_capacity(times.len() - 1);
        let mut overall: Real = 0.0;
        for (k, w) in times.windows(2).enumerate() {
            let base = own[k].max(own[k + 1]);
            let mut best = (0.0, 0.5 * (w[0] + w[1]));
            for m in 1..=samples {
                let t = w[0] + (w[1] - w[0]) * m as Real / (samples + 1) as Real;
                let u = blend(basis, frames, t, Derivative::Value)?;
                let e = self
                    .penetration(&u, t)
                    .max(self.distortion(&u) - base)
                    .max(0.0);
                if e > best.0 {
                    best = (e, t);
                }
            }
            overall = overall.max(best.0);
            worst.push(best);
        }
        Ok((overall, worst))
    }

    /// The deepest penetration of a particle sphere into an obstacle under
    /// the field `u` at time `t`, in spacings.
    fn penetration(&self, u: &[Vector], t: Real) -> Real {
        let field = self.body.field();
        let s = self.body.spacing();
        let mut worst: Real = 0.0;
        for (i, x) in self.body.rest().iter().enumerate() {
            let p = x + field.displacement(i, u);
            for o in &self.obstacles {
                let (d, _) = o.distance(&p, t);
                worst = worst.max((self.radius - d) / s);
            }
        }
        worst
    }

    /// The worst non-rigidity `|grad f^T grad f - I|_F` of the field `u`
    /// at the particles.
    fn distortion(&self, u: &[Vector]) -> Real {
        let field = self.body.field();
        (0..self.body.len())
            .map(|i| {
                let f = Matrix3::identity() + field.displacement_gradient(i, u);
                (f.transpose() * f - Matrix3::identity()).norm()
            })
            .fold(0.0, Real::max)
    }
}

/// The motion's least squares over a fixed set of frames.
struct MotionProblem<'s, 'a> {
    setup: &'s Setup<'a>,
    frames: usize,
    times: Vec<Real>,
    supports: Vec<Real>,
    /// Temporal weights at each frame, keyframe and velocity time.
    at_frames: Vec<Vec<TemporalWeight>>,
    at_keyframes: Vec<Vec<TemporalWeight>>,
    at_velocities: Vec<Vec<TemporalWeight>>,
    /// Group offsets: shape terms, per-particle frame terms, keyframes,
    /// velocities, end.
    offsets: [usize; 5],
    /// First group of each keyframe and velocity target.
    keyframe_starts: Vec<usize>,
    velocity_starts: Vec<usize>,
}

impl<'s, 'a> MotionProblem<'s, 'a> {
    fn new(setup: &'s Setup<'a>, basis: &TemporalBasis) -> Result<Self, DesignError> {
        let weights_at = |t: Real| -> Result<Vec<TemporalWeight>, DesignError> {
            let mut w = Vec::new();
            basis
                .shape_functions(t, &mut w)
                .map_err(|e| DesignError::Problem(e.to_string()))?;
            Ok(w)
        };
        let at_frames = basis
            .times()
            .iter()
            .map(|&t| weights_at(t))
            .collect::<Result<Vec<_>, _>>()?;
        let at_keyframes = setup
            .keyframes
            .iter()
            .map(|k| weights_at(k.time))
            .collect::<Result<Vec<_>, _>>()?;
        let at_velocities = setup
            .velocities
            .iter()
            .map(|v| weights_at(v.time))
            .collect::<Result<Vec<_>, _>>()?;
        let frames = basis.len();
        let body = setup.body;
        let quadrature = body.quadrature().1.len();
        let mut keyframe_starts = Vec::new();
        let mut next = frames * quadrature + frames * body.len();
        let shape_end = frames * quadrature;
        let particle_end = next;
        for k in &setup.keyframes {
            keyframe_starts.push(next);
            next += k.handles.targets.len();
        }
        let keyframe_end = next;
        let mut velocity_starts = Vec::new();
        for v in &setup.velocities {
            velocity_starts.push(next);
            next += v.points.len();
        }
        Ok(Self {
            setup,
            frames,
            times: basis.times().to_vec(),
            supports: basis.supports().to_vec(),
            at_frames,
            at_keyframes,
            at_velocities,
            offsets: [0, shape_end, particle_end, keyframe_end, next],
            keyframe_starts,
            velocity_starts,
        })
    }

    /// `(column base, coefficient)` of the field at a point with spatial
    /// row `(js, phi)` and temporal weights `tw`, the coefficient picked by
    /// `pick` (value, first or second derivative).
    fn entries(
        &self,
        js: &[u32],
        phi: &[Real],
        tw: &[TemporalWeight],
        pick: impl Fn(&TemporalWeight) -> Real,
    ) -> Vec<(usize, Real)> {
        let n = self.setup.body.len();
        let dim = self.setup.body.dim();
        tw.iter()
            .flat_map(|w| {
                let c = pick(w);
                js.iter()
                    .zip(phi)
                    .map(move |(&l, &p)| ((w.frame * n + l as usize) * dim, c * p))
            })
            .filter(|(_, c)| *c != 0.0)
            .collect()
    }

    /// The frame's weight in the time integrals, `h_j / T`.
    fn frame_weight(&self, j: usize) -> Real {
        self.supports[j] / self.setup.duration
    }
}

impl LeastSquares for MotionProblem<'_, '_> {
    fn unknowns(&self) -> usize {
        self.frames * self.setup.body.len() * self.setup.body.dim()
    }

    /// A line is one particle component across the frames.
    fn lines(&self) -> usize {
        self.setup.body.len() * self.setup.body.dim()
    }

    fn groups(&self) -> usize {
        self.offsets[4]
    }

    fn group(&self, g: usize, x: &[Real], rows: &mut Rows) {
        let setup = self.setup;
        let body = setup.body;
        let dim = body.dim();
        let n = body.len();
        let s = body.spacing();
        let w = &setup.weights;
        let duration = setup.duration;
        if g < self.offsets[1] {
            // Rigidity and volume within frame j (Eq. 76-77).
            let (quadrature, volumes) = body.quadrature();
            let (j, q) = (g / quadrature.len(), g % quadrature.len());
            let (js, _, grads) = quadrature.row(q);
            let terms: Vec<(usize, Vector)> = js
                .iter()
                .zip(grads)
                .map(|(&l, grad)| ((j * n + l as usize) * dim, grad * s))
                .collect();
            let f = deformation_gradient(dim, terms.iter().copied(), x);
            let v = volumes[q] * self.frame_weight(j);
            push_shape_terms(
                rows,
                dim,
                &f,
                &terms,
                (w.rigidity * v).sqrt(),
                (w.volume * v).sqrt(),
            );
        } else if g < self.offsets[2] {
            // Acceleration and obstacles of particle i at frame j.
            let k = g - self.offsets[1];
            let (j, i) = (k / n, k % n);
            let (js, phi, _) = body.field().row(i);
            let tw = &self.at_frames[j];
            let v = body.volumes()[i] * self.frame_weight(j);
            if w.acceleration > 0.0 {
                // d2u_i/dt2 of the particle's own displacement, in
                // spacings per T^2: the field's acceleration at x_i is
                // its MLS blend, the same smoothness measure at a
                // fortieth of the cost, and it couples each particle
                // only to itself in time, which the preconditioner of
                // `lsq` inverts exactly.
                let entries: Vec<(usize, Real)> = tw
                    .iter()
                    .map(|t| ((t.frame * n + i) * dim, t.d2 * duration * duration))
                    .collect();
                push_point(
                    rows,
                    Term::Acceleration,
                    dim,
                    Vector::zeros(),
                    &entries,
                    x,
                    (w.acceleration * v).sqrt(),
                );
            }
            if w.obstacle > 0.0 && !setup.obstacles.is_empty() {
                let entries = self.entries(js, phi, tw, |t| t.value);
                let mut p = body.rest()[i];
                for &(b, c) in &entries {
                    for a in 0..dim {
                        p[a] += c * x[b + a] * s;
                    }
                }
                let time = self.times[j];
                let weight = (w.obstacle * v).sqrt();
                let mut block = false;
                for o in &setup.obstacles {
                    let (d, normal) = o.distance(&p, time);
                    let depth = (setup.radius - d) / s;
                    if depth > 0.0 {
                        // One block of the field at the particle, for
                        // every obstacle it touches.
                        if !block {
                            rows.value_block(dim, &entries);
                            block = true;
                        }
                        let derivative = -weight * normal;
                        rows.push(
                            Term::Obstacle,
                            weight * depth,
                            &derivative.as_slice()[..dim],
                        );
                    }
                }
            }
        } else if g < self.offsets[3] {
            // Keyframe handles (Eq. 74 at t_k).
            let k = self.keyframe_starts.partition_point(|&start| start <= g) - 1;
            let p = g - self.keyframe_starts[k];
            let handles = &setup.keyframes[k].handles;
            let (js, phi, _) = handles.points.row(p);
            let entries = self.entries(js, phi, &self.at_keyframes[k], |t| t.value);
            let offset = (handles.points.rest()[p] - handles.targets[p]) / s;
            push_point(
                rows,
                Term::Handle,
                dim,
                offset,
                &entries,
                x,
                w.handle.sqrt(),
            );
        } else {
            // Velocities (Eq. 82), in spacings per T.
            let k = self.velocity_starts.partition_point(|&start| start <= g) - 1;
            let p = g - self.velocity_starts[k];
            let target = &setup.velocities[k];
            let (js, phi, _) = target.points.row(p);
            let entries = self.entries(js, phi, &self.at_velocities[k], |t| t.d1 * duration);
            let offset = -target.velocity * duration / s;
            push_point(
                rows,
                Term::Velocity,
                dim,
                offset,
                &entries,
                x,
                (w.velocity * target.volumes[p]).sqrt(),
            );
        }
    }
}
