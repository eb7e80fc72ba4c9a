//! The fixed part of a solid's own boundary: where the penalty of
//! `assemble.rs` holds the displacement at zero (Guo–Qin, Section 5.3.3:
//! essential conditions on `Gamma_u`, integrated over `Gamma_u`).
//!
//! The penalty is a surface integral, so the points it is evaluated at are
//! part of the discretisation, not of the picture: they come from the
//! shape's exact boundary and a rule sized by the solid's own `cell`, never
//! from the triangles a frame carries (whose density is an output
//! resolution). Each rule is Gauss–Legendre of the volume's
//! `quadrature_order` on panels of side `cell / subdivision`, the side of
//! the volume's integration cells, so that the penalty resolves the shape
//! functions as finely as the stiffness does.
//!
//! - a box: each face is clipped to the anchor box exactly (a convex
//!   polygon in the face's own coordinates), the polygon cut into
//!   trapezoids between its corners, and each trapezoid mapped from a grid
//!   of panels;
//! - a sphere: panels in (polar, azimuth) angle with the Gauss rule in each,
//!   the points inside the anchor box kept (the sphere's part in a box has
//!   no simple parametrisation; its edge is resolved to a panel).

use super::quadrature::gauss_legendre;
use super::solid::{EfgParams, FixedSurface};
use crate::math::{Real, Vector};
use nalgebra::{Rotation3, Vector2};

/// Most points one anchor's part of the boundary may hold. They are made
/// before the host's admission prices the build (the estimate counts their
/// shape-function rows), so they are capped here: a million points are
/// 32 MB, several times what the finest display surface of a box held.
pub const MAX_FIXED_POINTS: usize = 1 << 20;

/// An anchor whose part of the boundary needs more than
/// [`MAX_FIXED_POINTS`] points at the solid's resolution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error(
    "its part of the surface needs more than {MAX_FIXED_POINTS} quadrature points at this \
     resolution; use a smaller anchor, a larger `cell`, or a lower `subdivision` or \
     `quadrature_order`"
)]
pub struct TooManyPoints;

/// Where a shape sits: the centre of its own frame in the world, and the
/// rotation from its frame to the world's.
#[derive(Debug, Clone, Copy)]
pub struct Pose<'a> {
    /// The centre, world frame.
    pub centre: &'a Vector,
    /// Own frame to world.
    pub rotation: &'a Rotation3<Real>,
}

/// An axis-aligned box of the world frame, `[min, max]`.
#[derive(Debug, Clone, Copy)]
pub struct Anchor<'a> {
    /// Lower corner.
    pub min: &'a Vector,
    /// Upper corner.
    pub max: &'a Vector,
}

impl Anchor<'_> {
    fn contains(&self, p: &Vector) -> bool {
        (0..3).all(|k| p[k] >= self.min[k] && p[k] <= self.max[k])
    }
}

/// A discretisation's panel rule: its Gauss–Legendre abscissae and weights
/// on [-1, 1] and the panel side.
struct Rule {
    x: &'static [Real],
    w: &'static [Real],
    panel: Real,
}

impl Rule {
    fn of(params: &EfgParams) -> Self {
        let (x, w) = gauss_legendre(params.quadrature_order);
        Self {
            x,
            w,
            panel: params.cell / params.subdivision.max(1) as Real,
        }
    }

    /// Panels across `length`: at least one.
    fn panels(&self, length: Real) -> usize {
        ((length / self.panel).ceil() as usize).max(1)
    }

    /// The Gauss points and weights of `[a, b]` cut into `n` panels.
    fn points(&self, a: Real, b: Real, n: usize) -> impl Iterator<Item = (Real, Real)> + '_ {
        let h = (b - a) / n as Real;
        (0..n).flat_map(move |i| {
            self.x
                .iter()
                .zip(self.w)
                .map(move |(x, w)| (a + h * (i as Real + 0.5 * (1.0 + x)), 0.5 * h * w))
        })
    }
}

impl FixedSurface {
    /// The part of the faces of the box `[-half, half]` (own frame, placed
    /// by `pose`) inside `anchor`, integrated by the solid's panel rule
    /// (module notes): exact in area, and independent of any display mesh.
    ///
    /// # Errors
    /// [`TooManyPoints`] when the part needs more than
    /// [`MAX_FIXED_POINTS`] points; none is made past the cap.
    pub fn of_box_in_box(
        half: &Vector,
        pose: Pose<'_>,
        anchor: Anchor<'_>,
        params: &EfgParams,
    ) -> Result<Self, TooManyPoints> {
        let rule = Rule::of(params);
        let mut fixed = Self::default();
        for axis in 0..3 {
            let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
            let (e1, e2) = (Vector::ith(a, 1.0), Vector::ith(b, 1.0));
            let (r1, r2) = (pose.rotation * e1, pose.rotation * e2);
            for side in [-1.0, 1.0] {
                let origin = Vector::ith(axis, side * half[axis]);
                let at =
                    |s: Real, t: Real| pose.centre + pose.rotation * (origin + e1 * s + e2 * t);
                let o = at(0.0, 0.0);
                // The anchor as half-planes `n . (s, t) <= c` of the face.
                let mut polygon = vec![
                    Vector2::new(-half[a], -half[b]),
                    Vector2::new(half[a], -half[b]),
                    Vector2::new(half[a], half[b]),
                    Vector2::new(-half[a], half[b]),
                ];
                for k in 0..3 {
                    let n = Vector2::new(r1[k], r2[k]);
                    polygon = clip(&polygon, &n, anchor.max[k] - o[k]);
                    polygon = clip(&polygon, &-n, o[k] - anchor.min[k]);
                }
                let room = MAX_FIXED_POINTS - fixed.points.len();
                for (s, t, w) in polygon_points(&polygon, &rule, room)? {
                    fixed.points.push(at(s, t));
                    fixed.areas.push(w);
                }
            }
        }
        Ok(fixed)
    }

    /// The part of the sphere of `radius` (own frame centred at the
    /// origin, placed by `pose`) inside `anchor`: bands of polar angle,
    /// each cut into azimuth panels of about the panel side, the
    /// Gauss–Legendre rule in both angles with the area element
    /// `r^2 sin(theta)`, and the points inside the anchor kept.
    ///
    /// # Errors
    /// [`TooManyPoints`] when more than [`MAX_FIXED_POINTS`] points fall
    /// inside the anchor; none is kept past the cap.
    pub fn of_sphere_in_box(
        radius: Real,
        pose: Pose<'_>,
        anchor: Anchor<'_>,
        params: &EfgParams,
    ) -> Result<Self, TooManyPoints> {
        use std::f64::consts::{FRAC_PI_2, PI};
        let rule = Rule::of(params);
        let mut fixed = Self::default();
        let bands = rule.panels(PI * radius);
        for band in 0..bands {
            let (t0, t1) = (
                PI * band as Real / bands as Real,
                PI * (band + 1) as Real / bands as Real,
            );
            // The band's widest circle sets its azimuth panels.
            let widest = if t0 <= FRAC_PI_2 && FRAC_PI_2 <= t1 {
                1.0
            } else {
                t0.sin().max(t1.sin())
            };
            let around = rule.panels(2.0 * PI * radius * widest);
            for (theta, wt) in rule.points(t0, t1, 1) {
                for (phi, wp) in rule.points(0.0, 2.0 * PI, around) {
                    let own = Vector::new(
                        theta.sin() * phi.cos(),
                        theta.sin() * phi.sin(),
                        theta.cos(),
                    ) * radius;
                    let p = pose.centre + pose.rotation * own;
                    if !anchor.contains(&p) {
                        continue;
                    }
                    if fixed.points.len() == MAX_FIXED_POINTS {
                        return Err(TooManyPoints);
                    }
                    fixed.points.push(p);
                    fixed.areas.push(radius * radius * theta.sin() * wt * wp);
                }
            }
        }
        Ok(fixed)
    }
}

/// The part of the convex polygon `polygon` where
/// `n . p <= c` (Sutherland–Hodgman, one edge).
fn clip(polygon: &[Vector2<Real>], n: &Vector2<Real>, c: Real) -> Vec<Vector2<Real>> {
    let mut out = Vec::with_capacity(polygon.len() + 1);
    for (i, p) in polygon.iter().enumerate() {
        let q = polygon[(i + 1) % polygon.len()];
        let (dp, dq) = (n.dot(p) - c, n.dot(&q) - c);
        if dp <= 0.0 {
            out.push(*p);
        }
        if (dp < 0.0 && dq > 0.0) || (dp > 0.0 && dq < 0.0) {
            out.push(p + (q - p) * (dp / (dp - dq)));
        }
    }
    out
}

/// The extent `(low, high)` in `t` of the convex polygon's section at `s`
/// (empty, `low > high`, where the line misses it).
fn section(polygon: &[Vector2<Real>], s: Real) -> (Real, Real) {
    let mut range = (Real::INFINITY, Real::NEG_INFINITY);
    let mut take = |t: Real| range = (range.0.min(t), range.1.max(t));
    for (i, p) in polygon.iter().enumerate() {
        let q = polygon[(i + 1) % polygon.len()];
        if (p.x - s) * (q.x - s) > 0.0 {
            continue;
        }
        if p.x == q.x {
            take(p.y);
            take(q.y);
        } else {
            take(p.y + (s - p.x) / (q.x - p.x) * (q.y - p.y));
        }
    }
    range
}

/// Gauss points `(s, t, weight)` over a convex polygon: between two
/// consecutive corners' `s` its section's ends move linearly, so each
/// such slab is a trapezoid, mapped from a grid of panels (exact in
/// area). Each slab's count is checked against `room` before its points
/// are made.
///
/// # Errors
/// [`TooManyPoints`] past `room` points.
fn polygon_points(
    polygon: &[Vector2<Real>],
    rule: &Rule,
    room: usize,
) -> Result<Vec<(Real, Real, Real)>, TooManyPoints> {
    let mut out = Vec::new();
    if polygon.len() < 3 {
        return Ok(out);
    }
    let mut corners: Vec<Real> = polygon.iter().map(|p| p.x).collect();
    corners.sort_by(Real::total_cmp);
    corners.dedup();
    for slab in corners.windows(2) {
        let (s0, s1) = (slab[0], slab[1]);
        let ((lo0, hi0), (lo1, hi1)) = (section(polygon, s0), section(polygon, s1));
        let width = (hi0 - lo0).max(hi1 - lo1);
        if !(s1 > s0 && width > 0.0) {
            continue;
        }
        let (along, across) = (rule.panels(s1 - s0), rule.panels(width));
        let order = rule.x.len();
        if along.saturating_mul(across).saturating_mul(order * order) > room - out.len() {
            return Err(TooManyPoints);
        }
        for (s, ws) in rule.points(s0, s1, along) {
            let f = (s - s0) / (s1 - s0);
            let (lo, hi) = (lo0 + f * (lo1 - lo0), hi0 + f * (hi1 - hi0));
            if hi <= lo {
                continue;
            }
            for (t, wt) in rule.points(lo, hi, across) {
                out.push((s, t, ws * wt));
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn params(cell: Real) -> EfgParams {
        EfgParams::new(cell)
    }

    /// A box turned about an oblique axis: an anchor holding all of it
    /// integrates its whole surface, and one holding the half-space below
    /// its centre exactly half (the box is centrally symmetric), both to
    /// round-off, whatever the turn.
    #[test]
    fn a_turned_box_is_clipped_exactly() {
        let half = Vector::new(0.5, 0.1, 0.05);
        let whole_area = 8.0 * (half.x * half.y + half.y * half.z + half.z * half.x);
        let centre = Vector::new(1.0, -2.0, 0.5);
        let rotation = Rotation3::new(Vector::new(0.3, -0.7, 0.4));
        let pose = Pose {
            centre: &centre,
            rotation: &rotation,
        };
        let (lo, hi) = (Vector::repeat(-10.0), Vector::repeat(10.0));
        let all =
            FixedSurface::of_box_in_box(&half, pose, Anchor { min: &lo, max: &hi }, &params(0.03))
                .expect("few points");
        assert!(
            (all.area() / whole_area - 1.0).abs() < 1e-12,
            "{}",
            all.area()
        );
        let below = Vector::new(centre.x, 10.0, 10.0);
        let part = FixedSurface::of_box_in_box(
            &half,
            pose,
            Anchor {
                min: &lo,
                max: &below,
            },
            &params(0.03),
        )
        .expect("few points");
        assert!(
            (part.area() / whole_area - 0.5).abs() < 1e-12,
            "{}",
            part.area()
        );
        assert!(part.points.iter().all(|p| p.x <= centre.x));
    }

    /// The sphere's rule integrates its area to the Gauss rule's accuracy,
    /// and a polar cap `z >= r / 2` (area `pi r^2`) to a panel's width.
    #[test]
    fn the_sphere_rule_measures_its_area_and_a_cap() {
        let (radius, centre) = (0.4, Vector::new(0.1, 0.2, 0.3));
        let rotation = Rotation3::identity();
        let pose = Pose {
            centre: &centre,
            rotation: &rotation,
        };
        let (lo, hi) = (Vector::repeat(-10.0), Vector::repeat(10.0));
        let all = FixedSurface::of_sphere_in_box(
            radius,
            pose,
            Anchor { min: &lo, max: &hi },
            &params(0.05),
        )
        .expect("few points");
        let sphere = 4.0 * PI * radius * radius;
        assert!(
            (all.area() / sphere - 1.0).abs() < 1e-4,
            "{}",
            all.area() / sphere
        );
        let cap_min = Vector::new(-10.0, -10.0, centre.z + radius / 2.0);
        let cap = FixedSurface::of_sphere_in_box(
            radius,
            pose,
            Anchor {
                min: &cap_min,
                max: &hi,
            },
            &params(0.05),
        )
        .expect("few points");
        let error = cap.area() / (PI * radius * radius) - 1.0;
        assert!(error.abs() < 0.05, "{error}");
    }

    /// Past the cap, an anchor is refused before its points are made.
    #[test]
    fn a_boundary_rule_past_its_cap_is_refused() {
        let half = Vector::new(1.0, 1.0, 1.0);
        let (centre, rotation) = (Vector::zeros(), Rotation3::identity());
        let (lo, hi) = (Vector::repeat(-2.0), Vector::repeat(2.0));
        let fine = FixedSurface::of_box_in_box(
            &half,
            Pose {
                centre: &centre,
                rotation: &rotation,
            },
            Anchor { min: &lo, max: &hi },
            &params(1e-3),
        );
        assert_eq!(fine, Err(TooManyPoints));
    }
}
