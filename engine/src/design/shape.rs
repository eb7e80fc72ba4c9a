//! Shape deformation (tutorial Section 8.1): the particle displacements
//! `u_i` that minimise `lambda_1 E_handle + lambda_2 E_rigidity + lambda_3
//! E_volume` (Eq. 78), handles at their targets (Eq. 74), the field as
//! rigid (Eq. 76) and volume-preserving (Eq. 77) as it can be.
//!
//! A solve starts from the caller's previous solution, so dragging a
//! handle re-solves from where the shape already is.

use super::body::{DesignBody, Embedding};
use super::constraints::{ConstraintKind, ConstraintSet};
use super::energy::{deformation_gradient, push_shape_terms};
use super::lsq::{self, LeastSquares, Rows, RunState, Term};
use super::progress::{Observer, SolveInfo};
use super::{DesignError, DesignParams, Weights};
use crate::math::{Real, Vector};

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
    pub displacements: Vec<Vector>,
    pub info: SolveInfo,
}

/// Solves the shape problem the untimed handles of `constraints` pose
/// on `body`, from `warm` (the previous displacements) or the rest shape.
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
    let (displacements, info) =
        solve_handles(body, &points, targets, params, warm, &mut run, observer)?;
    Ok(ShapeSolution {
        displacements,
        info,
    })
}

/// Minimises Eq. 78 for handle `points` at rest and their `targets`.
pub(crate) fn solve_handles(
    body: &DesignBody,
    points: &[Vector],
    targets: Vec<Vector>,
    params: &DesignParams,
    warm: Option<&[Vector]>,
    run: &mut RunState,
    observer: &mut Observer<'_>,
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
    if let Some(warm) = warm {
        scale_into(warm, dim, s, &mut x);
    }
    let info = lsq::minimise(&problem, &mut x, &params.solver, run, observer)?;
    Ok((unscale(&x, dim, s), info))
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
/// `base(j)`, scaled by `weight` (already square-rooted).
pub(crate) fn push_point(
    rows: &mut Rows,
    term: Term,
    dim: usize,
    offset: Vector,
    entries: &[(usize, Real)],
    x: &[Real],
    weight: Real,
) {
    for a in 0..dim {
        let value = offset[a] + entries.iter().map(|&(b, c)| c * x[b + a]).sum::<Real>();
        rows.push(
            term,
            weight * value,
            entries.iter().map(|&(b, c)| ((b + a) as u32, weight * c)),
        );
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
