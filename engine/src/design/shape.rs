//! Shape deformation (tutorial Section 8.1): the particle displacements
//! `u_i` that minimise `lambda_1 E_handle + lambda_2 E_rigidity + lambda_3
//! E_volume` (Eq. 78), handles at their targets (Eq. 74), the field as
//! rigid (Eq. 76) and volume-preserving (Eq. 77) as it can be.
//!
//! A solve starts from the caller's previous solution, so dragging a
//! handle re-solves from where the shape already is; without one, from the
//! rest shape carried by the rigid motion that best fits the handles.

use super::body::{DesignBody, Embedding};
use super::constraints::{ConstraintKind, ConstraintSet};
use super::energy::{deformation_gradient, push_shape_terms};
use super::lsq::{self, LeastSquares, Rows, RunState, Term};
use super::progress::{Observer, SolveInfo};
use super::{DesignError, DesignParams, Weights};
use crate::cancel::Cancel;
use crate::math::{Real, Vector};
use nalgebra::Matrix3;

/// The handle points of a problem and their targets.
#[derive(Debug, Clone)]
pub(crate) struct Handles {
    pub points: Embedding,
    pub targets: Vec<Vector>,
}

impl Handles {
    /// Resolves the handles whose time is `time` (none for a shape).
    pub(crate) fn resolve(
        body: &DesignBody,
        constraints: &ConstraintSet,
        time: impl Fn(Option<Real>) -> bool,
    ) -> Result<(Vec<Vector>, Vec<Vector>), DesignError> {
        let mut points = Vec::new();
        let mut targets = Vec::new();
        for c in constraints.iter() {
            let ConstraintKind::Handle(h) = &c.kind else {
                continue;
            };
            if !time(h.time) {
                continue;
            }
            let at = body
                .select(&h.points)
                .map_err(|message| DesignError::constraint(&c.name, message))?;
            let to = h.target.resolve(&at);
            if to.len() != at.len() {
                return Err(DesignError::constraint(
                    &c.name,
                    format!("{} targets for {} points", to.len(), at.len()),
                ));
            }
            points.extend(at);
            targets.extend(to);
        }
        Ok((points, targets))
    }
}

/// A solved shape: one displacement per design particle.
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeSolution {
    /// `u_i`, m, in the body's particle order.
    pub displacements: Vec<Vector>,
    /// How the solve ended.
    pub info: SolveInfo,
}

/// Solves the shape problem the untimed handles of `constraints` pose
/// on `body`, from `warm` (the previous displacements) or else the rest
/// shape moved rigidly onto the handles (see `Start::Rigid`).
///
/// # Errors
/// [`DesignError::Constraint`] for a handle that selects nothing usable;
/// [`DesignError::Problem`] with no untimed handle;
/// [`DesignError::Parameter`] for bad weights or solver settings or a
/// `warm` of the wrong length; [`DesignError::Cancelled`] and
/// [`DesignError::Diverged`] from the solver.
pub fn solve_shape(
    body: &DesignBody,
    constraints: &ConstraintSet,
    params: &DesignParams,
    warm: Option<&[Vector]>,
    observer: &mut Observer<'_>,
) -> Result<ShapeSolution, DesignError> {
    // A flag no one else holds is never raised.
    solve_shape_cancellable(body, constraints, params, warm, observer, &Cancel::new())
}

/// [`solve_shape`], stopped by another thread raising `cancel`: read at
/// every solver iteration and CG iteration, where the observer sees only
/// whole iterations, each of which can run long on a large body.
///
/// # Errors
/// As [`solve_shape`]; [`DesignError::Cancelled`] once `cancel` is
/// raised.
pub fn solve_shape_cancellable(
    body: &DesignBody,
    constraints: &ConstraintSet,
    params: &DesignParams,
    warm: Option<&[Vector]>,
    observer: &mut Observer<'_>,
    cancel: &Cancel,
) -> Result<ShapeSolution, DesignError> {
    super::on_pool(|| shape_on_pool(body, constraints, params, warm, observer, cancel))
}

fn shape_on_pool(
    body: &DesignBody,
    constraints: &ConstraintSet,
    params: &DesignParams,
    warm: Option<&[Vector]>,
    observer: &mut Observer<'_>,
    cancel: &Cancel,
) -> Result<ShapeSolution, DesignError> {
    super::check_params(params)?;
    let (points, targets) = Handles::resolve(body, constraints, |t| t.is_none())?;
    if points.is_empty() {
        return Err(DesignError::Problem(
            "a shape problem needs at least one handle without a time; add one".into(),
        ));
    }
    if let Some(warm) = warm
        && warm.len() != body.len()
    {
        return Err(DesignError::Parameter {
            field: "warm",
            message: format!(
                "has {} displacements for {} design particles",
                warm.len(),
                body.len()
            ),
        });
    }
    let mut run = RunState {
        frames: 1,
        ..RunState::default()
    };
    let start = match warm {
        Some(warm) => Start::Warm(warm),
        None => Start::Rigid(None),
    };
    let (displacements, info) = solve_handles(
        body, &points, targets, params, start, &mut run, observer, cancel,
    )?;
    Ok(ShapeSolution {
        displacements,
        info,
    })
}

/// Where a solve starts.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Start<'a> {
    /// From these displacements as they are: a dragged handle has moved a
    /// little, and the rest of the shape is already where it should be.
    Warm(&'a [Vector]),
    /// From these displacements (the rest shape for `None`) carried by
    /// the rigid motion that best takes the handles to their targets: a
    /// keyframe or a first solve whose handles moved far. A rigid motion
    /// costs no rigidity or volume, so when the handles move rigidly
    /// this is the solution, and otherwise the solver starts from a shape
    /// instead of from stretching particles one neighbourhood at a time.
    Rigid(Option<&'a [Vector]>),
}

/// Minimises Eq. 78 for handle `points` at rest and their `targets`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn solve_handles(
    body: &DesignBody,
    points: &[Vector],
    targets: Vec<Vector>,
    params: &DesignParams,
    start: Start<'_>,
    run: &mut RunState,
    observer: &mut Observer<'_>,
    cancel: &Cancel,
) -> Result<(Vec<Vector>, SolveInfo), DesignError> {
    let handles = Handles {
        points: body.embed(points)?,
        targets,
    };
    let problem = ShapeProblem {
        body,
        handles: &handles,
        weights: params.weights,
    };
    let dim = body.dim();
    let s = body.spacing();
    let mut x = vec![0.0; body.len() * dim];
    match start {
        Start::Warm(warm) => scale_into(warm, dim, s, &mut x),
        Start::Rigid(base) => {
            let carried = carry_rigidly(body, &handles, base);
            scale_into(&carried, dim, s, &mut x);
        }
    }
    let info = lsq::minimise(&problem, &mut x, &params.solver, run, observer, cancel)?;
    Ok((unscale(&x, dim, s), info))
}

/// The displacements `base` (zero for `None`) followed by the rigid
/// motion that best takes the handle points, displaced by `base`, to
/// their targets in the least-squares sense (Kabsch's SVD fit). Handles
/// that fix no rotation (a point, or points on a line in 3D) get only the
/// translation.
fn carry_rigidly(body: &DesignBody, handles: &Handles, base: Option<&[Vector]>) -> Vec<Vector> {
    let displaced = |i: usize| base.map_or(Vector::zeros(), |u| u[i]);
    let mut from = handles.points.rest().to_vec();
    if let Some(u) = base {
        handles.points.deform(u, &mut from);
    }
    let count = from.len() as Real;
    let centre = from.iter().sum::<Vector>() / count;
    let target = handles.targets.iter().sum::<Vector>() / count;
    let mut cross = Matrix3::zeros();
    for (p, q) in from.iter().zip(&handles.targets) {
        cross += (p - centre) * (q - target).transpose();
    }
    let svd = cross.svd(true, true);
    let dim = body.dim();
    let rotation = match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) if svd.singular_values[dim - 2] > 1e-9 * svd.singular_values[0] => {
            let v = v_t.transpose();
            let mut flip = Matrix3::identity();
            // The last axis of the fit: z in 2D, where it must stay z.
            flip[(2, 2)] = (v * u.transpose()).determinant().signum();
            v * flip * u.transpose()
        }
        _ => Matrix3::identity(),
    };
    body.rest()
        .iter()
        .enumerate()
        .map(|(i, x)| rotation * (x + displaced(i) - centre) + target - x)
        .collect()
}

/// Writes displacements in metres as unknowns in spacings.
pub(crate) fn scale_into(u: &[Vector], dim: usize, s: Real, x: &mut [Real]) {
    for (i, u) in u.iter().enumerate() {
        for a in 0..dim {
            x[i * dim + a] = u[a] / s;
        }
    }
}

/// Displacements in metres from unknowns in spacings.
pub(crate) fn unscale(x: &[Real], dim: usize, s: Real) -> Vec<Vector> {
    x.chunks(dim)
        .map(|c| Vector::from_fn(|a, _| if a < dim { c[a] * s } else { 0.0 }))
        .collect()
}

/// The handle residuals of point `k` of `handles`, the field at it
/// `sum_j phi_j x_(j, .)` with the unknowns of particle `j` from
/// `base(j)`, as one block, scaled by `weight` (already square-rooted).
pub(crate) fn push_point(
    rows: &mut Rows,
    term: Term,
    dim: usize,
    offset: Vector,
    entries: &[(usize, Real)],
    x: &[Real],
    weight: Real,
) {
    rows.value_block(dim, entries);
    let mut d = [0.0; 3];
    for a in 0..dim {
        let value = offset[a] + entries.iter().map(|&(b, c)| c * x[b + a]).sum::<Real>();
        d.fill(0.0);
        d[a] = weight;
        rows.push(term, weight * value, &d[..dim]);
    }
}

struct ShapeProblem<'a> {
    body: &'a DesignBody,
    handles: &'a Handles,
    weights: Weights,
}

impl LeastSquares for ShapeProblem<'_> {
    fn unknowns(&self) -> usize {
        self.body.len() * self.body.dim()
    }

    /// One group per particle (rigidity, volume), then one per handle.
    fn groups(&self) -> usize {
        self.body.quadrature().1.len() + self.handles.targets.len()
    }

    fn group(&self, g: usize, x: &[Real], rows: &mut Rows) {
        let dim = self.body.dim();
        let s = self.body.spacing();
        let (quadrature, volumes) = self.body.quadrature();
        if g < quadrature.len() {
            let (js, _, grads) = quadrature.row(g);
            let terms: Vec<(usize, Vector)> = js
                .iter()
                .zip(grads)
                .map(|(&j, grad)| (j as usize * dim, grad * s))
                .collect();
            let f = deformation_gradient(dim, terms.iter().copied(), x);
            let v = volumes[g];
            push_shape_terms(
                rows,
                dim,
                &f,
                &terms,
                (self.weights.rigidity * v).sqrt(),
                (self.weights.volume * v).sqrt(),
            );
        } else {
            let k = g - quadrature.len();
            let (js, phi, _) = self.handles.points.row(k);
            let entries: Vec<(usize, Real)> = js
                .iter()
                .zip(phi)
                .map(|(&j, &p)| (j as usize * dim, p))
                .collect();
            let offset = (self.handles.points.rest()[k] - self.handles.targets[k]) / s;
            push_point(
                rows,
                Term::Handle,
                dim,
                offset,
                &entries,
                x,
                self.weights.handle.sqrt(),
            );
        }
    }
}
