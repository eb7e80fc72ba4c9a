//! The implicit surface of an oriented point cloud (points with outward
//! normals), for the Element-Free Galerkin octree that classifies its
//! octants by the field's sign and projects its exterior-boundary nodes
//! onto the zero set (Guo–Qin, Section 4.1).
//!
//! # The field
//!
//! The paper fits a multi-level partition of unity (MPU, Ohtake et al.
//! 2003): local quadrics in an adaptive octree, blended by weights. This
//! module fits the *implicit moving least squares* (IMLS) surface of Shen
//! et al. (2004) in the form Kolluri (2008) analysed, which is the same
//! kind of blend with the simplest local fit, each sample's own tangent
//! plane:
//!
//! ```text
//! f(x) = sum_i theta_i(x) n_i.(x - p_i) / sum_i theta_i(x)
//! ```
//!
//! with `theta_i` the Wendland C2 weight `(1-u)^4 (4u+1)`, `u = |x-p_i|/h_i`,
//! of compact support `h_i`. Why this rather than MPU:
//!
//! - what the octree needs is the sign, and Kolluri proves that for a
//!   uniformly well-sampled surface the IMLS zero set is close to it in
//!   position and topology, with the sign right away from it (for
//!   Gaussian weights of one width; the compactly supported weight here,
//!   the usual practical substitute, is what keeps a query local); the
//!   octree's terminal octants for the simulation are much larger than
//!   the sample spacing (the paper says so), so MPU's higher-order
//!   accuracy buys it nothing;
//! - the planes come with the data: no local least-squares solve, hence no
//!   fit that fails for too few or badly spread points (MPU subdivides
//!   cells until a quadric fits, and needs rules for when none does);
//! - a plane through each sample gives an unbiased field for flat parts
//!   and a bias of about `<alpha^2>/2`, the mean square angle the support
//!   subtends, on curved ones: for a radius of curvature `R`, some
//!   `0.07 (h/R)^2 R` (0.4% of `R` with the defaults at 16 samples per
//!   radian, 3,000 on a sphere), below any octant the simulation uses;
//! - averaging many normals makes the sign robust to noisy ones: a normal
//!   off by an angle adds a term of random sign that averages out, while
//!   the true distance enters every term.
//!
//! # Supports
//!
//! A sample's *local spacing* is the distance to its k-th nearest other
//! sample ([`PointSurfaceParams::neighbours`]), clamped to
//! [`SPACING_CLAMP`] times the median's range either way, and its support
//! radius is [`PointSurfaceParams::support`] times that: so the supports
//! follow the sampling density (a uniform radius would leave holes where
//! samples are sparse, or blur where they are dense), while duplicated
//! points cannot shrink a support to nothing nor an outlier grow one over
//! the whole cloud. The support must stay below the thickness of the
//! thinnest feature: where it reaches across a thin wall, the far side's
//! planes take part and can flip the sign just outside it.
//!
//! # Far from the samples
//!
//! Where the supports hold less than one sample's full weight (`W =
//! sum theta_i < 1`, at the rim of the supports and beyond), the fit is
//! underdetermined, and the field blends in the *nearest sample's* plane
//! distance `n_k.(x - p_k)` with weight `(1 - W)^2`, taking over wholly
//! where no support reaches. For a closed surface, the direction from a
//! point to its nearest surface point is the surface's normal there, so
//! this is the signed distance up to the sampling gap (less, by up to the
//! cosine of the half angle, off a sharp edge), and its sign is right at
//! any distance, even with normals off by tens of degrees. The blend
//! keeps the field continuous where the supports end.
//!
//! # Cost
//!
//! Samples are grouped by support radius in powers of two, one kd-tree per
//! group queried with the group's largest radius, so a query visits about
//! the samples its supports cover, whatever the density elsewhere. The
//! nearest sample comes from a bounding-volume hierarchy over the points.
//! About 120 bytes a point are kept, and under 200 while building: some
//! 0.5 and 0.8 GiB at [`MAX_POINTS`].

use super::ImplicitSurface;
use super::bvh::Bvh;
use crate::math::{Brief, Real, Vector};
use crate::neighbors::{CandidateSearch, KdTree};
use rayon::prelude::*;

/// Fewest points fitted: a closed surface sampled by fewer is too coarse
/// for any fit to say where its inside is.
pub const MIN_POINTS: usize = 16;

/// Most points fitted, so that memory stays bounded (under 1 GiB while
/// building, see the module doc); thin a larger cloud first.
pub const MAX_POINTS: usize = 1 << 22;

/// Most neighbours a local spacing may be measured over: past this the
/// spacing describes a patch rather than the sampling around a point, and
/// building costs grow with it.
pub const MAX_NEIGHBOURS: usize = 64;

/// Largest support factor: beyond it the fit smooths features away and
/// each query visits `support^2` times more samples.
pub const MAX_SUPPORT: Real = 8.0;

/// Local spacings are clamped to within this factor of their median, either
/// way: enough for the density variations of scans, and it bounds the
/// support classes to `SUPPORT_CLASSES`.
pub const SPACING_CLAMP: Real = 4.0;

/// Power-of-two classes that supports within `SPACING_CLAMP^2` of each
/// other fall into: `log2(16) = 4`.
const SUPPORT_CLASSES: usize = 4;

/// Newton steps [`PointSurface::project`] takes at most; from within a
/// support it converges in a handful, from far away the first step lands
/// on the nearest sample's tangent plane.
const NEWTON_STEPS: usize = 32;

/// Newton stops once `|f|` is below this fraction of the sample spacing,
/// far below the fit's own error.
const NEWTON_TOLERANCE: Real = 1e-6;

/// Smallest gradient norm a Newton step divides by: where normals cancel
/// (between two sheets, near the medial axis) the gradient is weak and a
/// full step would overshoot, so a step moves at most `|f| / MIN_GRADIENT`.
const MIN_GRADIENT: Real = 0.5;

/// Why an oriented point cloud cannot be fitted. Each message says what to
/// change.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PointCloudError {
    /// No points at all.
    #[error("the point cloud is empty; give the points (with normals) of a closed surface")]
    Empty,

    /// Points and normals differ in number.
    #[error("{points} points but {normals} normals; give exactly one normal per point")]
    LengthMismatch {
        /// Points given.
        points: usize,
        /// Normals given.
        normals: usize,
    },

    /// Fewer points than [`MIN_POINTS`], or than the neighbours a local
    /// spacing is measured over plus one.
    #[error(
        "{count} points are too few to fit a surface (at least {min} with these parameters); \
         sample the surface more densely"
    )]
    TooFewPoints {
        /// Points given.
        count: usize,
        /// The least accepted.
        min: usize,
    },

    /// More points than [`MAX_POINTS`].
    #[error(
        "{count} points are more than the {max} a surface is fitted to (bounded memory); \
         thin the cloud"
    )]
    TooManyPoints {
        /// Points given.
        count: usize,
        /// [`MAX_POINTS`].
        max: usize,
    },

    /// A point with a NaN or infinite coordinate.
    #[error("point {index} has a non-finite coordinate; every point needs finite x, y, z")]
    NonFinitePoint {
        /// Index of the first such point (0-based).
        index: usize,
    },

    /// A normal that is zero or not finite, so gives no direction.
    #[error(
        "the normal of point {index} is zero or not finite; every point needs a finite, \
         nonzero outward normal"
    )]
    BadNormal {
        /// Index of the first such point (0-based).
        index: usize,
    },

    /// Coordinates so large that squared distances between points overflow.
    #[error(
        "the points reach {extent:e} from the origin, too far apart for squared distances \
         between them; scale them down"
    )]
    TooLarge {
        /// The largest coordinate, in absolute value.
        extent: Real,
    },

    /// More than half the points sit on another point, so the median
    /// spacing, which every support scales with, is zero.
    #[error(
        "more than half the points coincide with another point, so the sample spacing is zero; \
         remove duplicated points"
    )]
    Coincident,

    /// [`PointSurfaceParams::neighbours`] out of range.
    #[error("neighbours = {value} must be between 1 and {MAX_NEIGHBOURS}")]
    Neighbours {
        /// The value given.
        value: usize,
    },

    /// [`PointSurfaceParams::support`] out of range.
    #[error(
        "support = {} must be between 1 (a support reaching the k-th neighbour) \
         and {MAX_SUPPORT}",
        Brief(*.value)
    )]
    Support {
        /// The value given.
        value: Real,
    },
}

/// How the field is fitted to a cloud.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointSurfaceParams {
    /// `k`: a sample's local spacing is the distance to its k-th nearest
    /// other sample, in `1..=MAX_NEIGHBOURS`. More is smoother across
    /// sampling irregularities, fewer follows density changes more
    /// closely. Default 10: about two spacings on a surface.
    pub neighbours: usize,
    /// A sample's support radius in units of its local spacing, in
    /// `[1, MAX_SUPPORT]`. Larger averages more normals (robust to noise,
    /// holes and uneven sampling) but smooths more and must stay below the
    /// thinnest feature. Default 2: about 4 sample spacings, so some 40
    /// samples lie in a support near the surface.
    pub support: Real,
}

impl Default for PointSurfaceParams {
    fn default() -> Self {
        Self {
            neighbours: 10,
            support: 2.0,
        }
    }
}

impl PointSurfaceParams {
    fn check(&self) -> Result<(), PointCloudError> {
        if !(1..=MAX_NEIGHBOURS).contains(&self.neighbours) {
            return Err(PointCloudError::Neighbours {
                value: self.neighbours,
            });
        }
        if !(1.0..=MAX_SUPPORT).contains(&self.support) {
            return Err(PointCloudError::Support {
                value: self.support,
            });
        }
        Ok(())
    }
}

/// The samples whose support radii fall in one power-of-two class, in a
/// kd-tree queried with the largest of them.
#[derive(Debug, Clone)]
struct SupportClass {
    tree: KdTree,
    /// The cloud's index of each point of the tree.
    members: Vec<u32>,
}

/// The field and its gradient at a point.
#[derive(Debug, Clone, Copy)]
struct Field {
    value: Real,
    gradient: Vector,
}

/// The IMLS implicit surface of an oriented point cloud (see the module
/// doc): negative inside, zero on the fitted surface, about the distance
/// to it nearby, and the nearest sample's plane distance far away.
#[derive(Debug, Clone)]
pub struct PointSurface {
    points: Vec<Vector>,
    /// Unit outward normals.
    normals: Vec<Vector>,
    /// The support radius of each sample.
    supports: Vec<Real>,
    classes: Vec<SupportClass>,
    /// Over the points, for the nearest sample.
    bvh: Bvh,
    /// The median distance from a sample to its nearest other sample.
    spacing: Real,
    bounds: (Vector, Vector),
}

impl PointSurface {
    /// Fits the surface to `points` with their outward `normals` (any
    /// nonzero length; they are normalised).
    ///
    /// # Errors
    /// [`PointCloudError`]: parameters out of range, an empty cloud, as
    /// many normals as points not given, fewer than [`MIN_POINTS`] (or
    /// `neighbours + 1`) or more than [`MAX_POINTS`] points, a non-finite
    /// coordinate, a zero or non-finite normal, coordinates whose squared
    /// distances overflow, and a cloud more than half of whose points are
    /// duplicates.
    pub fn new(
        points: &[Vector],
        normals: &[Vector],
        params: PointSurfaceParams,
    ) -> Result<Self, PointCloudError> {
        params.check()?;
        let count = points.len();
        if count == 0 {
            return Err(PointCloudError::Empty);
        }
        if normals.len() != count {
            return Err(PointCloudError::LengthMismatch {
                points: count,
                normals: normals.len(),
            });
        }
        let min = MIN_POINTS.max(params.neighbours + 1);
        if count < min {
            return Err(PointCloudError::TooFewPoints { count, min });
        }
        if count > MAX_POINTS {
            return Err(PointCloudError::TooManyPoints {
                count,
                max: MAX_POINTS,
            });
        }
        if let Some(index) = points.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
            return Err(PointCloudError::NonFinitePoint { index });
        }
        let normals = normals
            .iter()
            .enumerate()
            .map(|(index, n)| unit(n).ok_or(PointCloudError::BadNormal { index }))
            .collect::<Result<Vec<_>, _>>()?;
        let (mut lo, mut hi) = (points[0], points[0]);
        for p in points {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        // The spacing search squares radii of up to eight diagonals: its
        // start, sqrt(MAX_NEIGHBOURS) spacings, or twice the diagonal.
        if !(64.0 * (hi - lo).norm_squared()).is_finite() {
            return Err(PointCloudError::TooLarge {
                extent: lo.abs().sup(&hi.abs()).max(),
            });
        }

        let boxes: Vec<(Vector, Vector)> = points.iter().map(|p| (*p, *p)).collect();
        let bvh = Bvh::new(&boxes);
        drop(boxes);
        let nearest: Vec<Real> = (0..count)
            .into_par_iter()
            .map(|i| {
                let p = &points[i];
                bvh.nearest(p, |j| {
                    let d2 = if j as usize == i {
                        Real::INFINITY
                    } else {
                        (points[j as usize] - p).norm_squared()
                    };
                    (d2, ())
                })
                .map_or(0.0, |(_, d2, ())| d2.sqrt())
            })
            .collect();
        let spacing = median(&nearest);
        if spacing <= 0.0 {
            return Err(PointCloudError::Coincident);
        }

        // On a surface the k-th neighbour lies about sqrt(k / pi) spacings
        // away, so most points find theirs in the first round.
        let mut radii = kth_neighbour_distances(
            points,
            params.neighbours,
            spacing * (params.neighbours as Real).sqrt(),
        );
        let reference = median(&radii);
        for r in &mut radii {
            *r = r.clamp(reference / SPACING_CLAMP, reference * SPACING_CLAMP);
        }
        let supports: Vec<Real> = radii.iter().map(|r| params.support * r).collect();
        let smallest = params.support * reference / SPACING_CLAMP;
        let mut members = vec![Vec::new(); SUPPORT_CLASSES];
        for (i, h) in supports.iter().enumerate() {
            let class = ((h / smallest).log2().floor().max(0.0) as usize).min(SUPPORT_CLASSES - 1);
            members[class].push(i as u32);
        }
        let classes = members
            .into_iter()
            .filter(|m| !m.is_empty())
            .map(|members| {
                let radius = members
                    .iter()
                    .map(|&i| supports[i as usize])
                    .fold(0.0, Real::max);
                let positions: Vec<Vector> = members.iter().map(|&i| points[i as usize]).collect();
                let mut tree = KdTree::new(radius);
                tree.rebuild(&positions);
                SupportClass { tree, members }
            })
            .collect();
        // The zero set of the fit lies within the supports; beyond them
        // the nearest sample's plane distance is about the distance to a
        // closed surface, which does not vanish there.
        let reach = Vector::repeat(supports.iter().copied().fold(0.0, Real::max));
        Ok(Self {
            points: points.to_vec(),
            normals,
            supports,
            classes,
            bvh,
            spacing,
            bounds: (lo - reach, hi + reach),
        })
    }

    /// The median distance from a sample to its nearest other sample: the
    /// scale below which the field says nothing reliable, and the distance
    /// from the surface beyond which its sign is right even with noisy
    /// normals (tested with normals off by up to 20 degrees).
    pub fn spacing(&self) -> Real {
        self.spacing
    }

    /// The distance from `x` to the nearest sample: `None` for a
    /// non-finite `x`. What tells the fitted field's zero set apart from
    /// its extension past an open cloud's rim, where no sample is near.
    pub fn distance_to_samples(&self, x: &Vector) -> Option<Real> {
        self.nearest_sample(x).map(|k| (self.points[k] - x).norm())
    }

    /// The sample nearest `x`: `None` for a non-finite `x` (which the
    /// search would otherwise walk whole, every comparison failing), or
    /// one whose squared distances overflow.
    fn nearest_sample(&self, x: &Vector) -> Option<usize> {
        if !x.iter().all(|c| c.is_finite()) {
            return None;
        }
        self.bvh
            .nearest(x, |i| ((self.points[i as usize] - x).norm_squared(), ()))
            .map(|(i, _, ())| i as usize)
    }

    /// The field and its analytic gradient at `x`: NaN for a non-finite
    /// `x`, which no tree search should see, and for one so far from the
    /// cloud that squared distances overflow.
    fn field(&self, x: &Vector) -> Field {
        if !x.iter().all(|c| c.is_finite()) {
            return Field {
                value: Real::NAN,
                gradient: Vector::repeat(Real::NAN),
            };
        }
        // Sums of theta, theta a (a = n.(x - p)) and their gradients.
        let (mut w, mut wa) = (0.0, 0.0);
        let (mut grad_w, mut grad_wa) = (Vector::zeros(), Vector::zeros());
        for class in &self.classes {
            class.tree.for_each_candidate(x, |j| {
                let i = class.members[j as usize] as usize;
                let d = x - self.points[i];
                let h = self.supports[i];
                let d2 = d.norm_squared();
                if d2 >= h * h {
                    return;
                }
                let u = d2.sqrt() / h;
                let t = 1.0 - u;
                let t3 = t * t * t;
                let theta = t3 * t * (4.0 * u + 1.0);
                // d theta / du = -20 u (1-u)^3, and grad u = d / (h |d|).
                let grad_theta = d * (-20.0 * t3 / (h * h));
                let n = &self.normals[i];
                let a = n.dot(&d);
                w += theta;
                wa += theta * a;
                grad_w += grad_theta;
                grad_wa += grad_theta * a + n * theta;
            });
        }
        let (mut numerator, mut denominator) = (wa, w);
        let (mut grad_numerator, mut grad_denominator) = (grad_wa, grad_w);
        if w < 1.0 {
            let Some(k) = self.nearest_sample(x) else {
                return Field {
                    value: Real::NAN,
                    gradient: Vector::repeat(Real::NAN),
                };
            };
            let n = &self.normals[k];
            let a = n.dot(&(x - self.points[k]));
            let beta = (1.0 - w) * (1.0 - w);
            let grad_beta = grad_w * (-2.0 * (1.0 - w));
            numerator += beta * a;
            denominator += beta;
            grad_numerator += grad_beta * a + n * beta;
            grad_denominator += grad_beta;
        }
        // The denominator is W + (1 - W)^2 >= 3/4 below W = 1, W above.
        let value = numerator / denominator;
        Field {
            value,
            gradient: (grad_numerator - grad_denominator * value) / denominator,
        }
    }
}

impl ImplicitSurface for PointSurface {
    fn signed_distance(&self, p: &Vector) -> Real {
        self.field(p).value
    }

    /// The normalised gradient; where it vanishes (normals cancelling
    /// exactly), the nearest sample's normal.
    fn normal(&self, p: &Vector) -> Vector {
        let gradient = self.field(p).gradient;
        unit(&gradient)
            .or_else(|| self.nearest_sample(p).map(|k| self.normals[k]))
            .unwrap_or(gradient)
    }

    /// Newton steps `x <- x - f grad f / |grad f|^2`, each at most
    /// `|f| / MIN_GRADIENT` long, until `|f|` is below a millionth of the
    /// spacing or `NEWTON_STEPS` are taken; if that has not converged,
    /// the best of its iterates and the sample nearest `p` (which lies on
    /// the surface up to the fit's error).
    fn project(&self, p: &Vector) -> Vector {
        let tolerance = NEWTON_TOLERANCE * self.spacing;
        let mut x = *p;
        let mut best = (Real::INFINITY, *p);
        for _ in 0..NEWTON_STEPS {
            let Field { value, gradient } = self.field(&x);
            if value.is_nan() || value.abs() >= best.0 {
                // Not a number, or no better: Newton has lost its way.
                break;
            }
            best = (value.abs(), x);
            if value.abs() <= tolerance {
                return x;
            }
            let g2 = gradient.norm_squared();
            if !(g2 > 0.0 && g2.is_finite()) {
                break;
            }
            x -= gradient * (value / g2.max(MIN_GRADIENT * MIN_GRADIENT));
        }
        match self.nearest_sample(p) {
            Some(k) if self.field(&self.points[k]).value.abs() < best.0 => self.points[k],
            _ => best.1,
        }
    }

    fn bounds(&self) -> (Vector, Vector) {
        self.bounds
    }
}

/// `v` scaled to unit length, if it has a direction. Scaling by the
/// largest component first keeps tiny and huge (finite) vectors from
/// underflowing or overflowing the norm.
fn unit(v: &Vector) -> Option<Vector> {
    let scale = v.amax();
    if !(scale > 0.0 && v.iter().all(|c| c.is_finite())) {
        return None;
    }
    let v = v / scale;
    Some(v / v.norm())
}

/// The median of `values` (not empty).
fn median(values: &[Real]) -> Real {
    let mut values = values.to_vec();
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, Real::total_cmp).1
}

/// The distance from each point to its `k`-th nearest other point
/// (`k < points.len()`), through kd-trees of doubling radius from `start`
/// (> 0): a round settles the points with `k` others within its radius,
/// and the next searches the rest twice as far. Ends once the radius
/// passes the points' extent, where every point has all others within.
fn kth_neighbour_distances(points: &[Vector], k: usize, start: Real) -> Vec<Real> {
    let mut distances = vec![0.0; points.len()];
    let mut pending: Vec<u32> = (0..points.len() as u32).collect();
    let mut radius = start;
    while !pending.is_empty() {
        let mut tree = KdTree::new(radius);
        tree.rebuild(points);
        let r2 = radius * radius;
        let found: Vec<Option<Real>> = pending
            .par_iter()
            .map_init(Vec::new, |near: &mut Vec<Real>, &i| {
                let p = &points[i as usize];
                near.clear();
                tree.for_each_candidate(p, |j| {
                    let d2 = (points[j as usize] - p).norm_squared();
                    if j != i && d2 < r2 {
                        near.push(d2);
                    }
                });
                (near.len() >= k)
                    .then(|| near.select_nth_unstable_by(k - 1, Real::total_cmp).1.sqrt())
            })
            .collect();
        let mut unsettled = Vec::new();
        for (&i, d) in pending.iter().zip(found) {
            match d {
                Some(d) => distances[i as usize] = d,
                None => unsettled.push(i),
            }
        }
        pending = unsettled;
        radius *= 2.0;
    }
    distances
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{fibonacci_sphere, perturb_normals, random_unit, uniform};
    use std::f64::consts::PI;

    /// `n` points spread evenly over the unit sphere (a Fibonacci
    /// lattice); each is its own outward normal.
    fn sphere(n: usize) -> PointSurface {
        let points = fibonacci_sphere(n);
        PointSurface::new(&points, &points, PointSurfaceParams::default()).expect("a sphere")
    }

    /// Random points with radius uniform in `[0.5, 1.5]`.
    fn shell_points(count: usize, seed: &mut u64) -> Vec<Vector> {
        (0..count)
            .map(|_| random_unit(seed) * (0.5 + uniform(seed)))
            .collect()
    }

    /// A grid of `m^3` points over `[lo, hi]`.
    fn grid(lo: Vector, hi: Vector, m: usize) -> impl Iterator<Item = Vector> {
        (0..m * m * m).map(move |c| {
            let ijk = Vector::new((c % m) as Real, (c / m % m) as Real, (c / (m * m)) as Real);
            lo + (hi - lo).component_mul(&ijk) / (m - 1) as Real
        })
    }

    /// Largest error of the field against the exact distance `|x| - 1`,
    /// over the whole shell 0.5 < |x| < 1.5 and within 0.1 of the surface.
    #[test]
    fn sphere_distance_is_close_to_exact() {
        let surface = sphere(3000);
        let mut seed = 11;
        let (mut worst, mut worst_near) = (0.0, 0.0);
        for x in shell_points(3000, &mut seed) {
            let exact = x.norm() - 1.0;
            let error = (surface.signed_distance(&x) - exact).abs();
            worst = Real::max(worst, error);
            if exact.abs() < 0.1 {
                worst_near = Real::max(worst_near, error);
            }
        }
        assert!(worst < 1e-2, "shell error {worst}");
        assert!(worst_near < 6e-3, "near-surface error {worst_near}");
        // A distance near the surface: the gradient is about unit there.
        for x in shell_points(1000, &mut seed) {
            let slope = surface.field(&x).gradient.norm();
            assert!((0.85..1.15).contains(&slope), "at {x}: |grad f| = {slope}");
        }
        // The exact sphere lies in the bounds, which hold a support more.
        let (lo, hi) = surface.bounds();
        assert!(lo.max() < -1.0 && hi.min() > 1.0, "{lo} {hi}");
        assert!(hi.max() < 1.5, "{hi}");
    }

    #[test]
    fn sphere_sign_is_right_across_the_box() {
        let surface = sphere(3000);
        let mut checked = 0;
        for x in grid(Vector::repeat(-2.0), Vector::repeat(2.0), 24) {
            let exact = x.norm() - 1.0;
            if exact.abs() < 1e-2 {
                continue;
            }
            checked += 1;
            assert_eq!(surface.contains(&x), exact < 0.0, "at {x}: exact {exact}");
        }
        assert!(checked > 13_000, "{checked}");
    }

    /// Projections land on the sphere at the radial point; normals are
    /// within a fraction of a degree of radial where the fit holds, and
    /// within the angle half a spacing subtends (some 2 degrees) beyond,
    /// where the nearest sample's normal takes over.
    #[test]
    fn sphere_projection_and_normals_are_accurate() {
        let surface = sphere(3000);
        let mut seed = 12;
        let (mut worst_radius, mut worst_offset) = (0.0, 0.0);
        let (mut worst_angle, mut worst_angle_near) = (0.0, 0.0);
        for x in shell_points(1000, &mut seed) {
            let radial = x.normalize();
            let y = surface.project(&x);
            worst_radius = Real::max(worst_radius, (y.norm() - 1.0).abs());
            worst_offset = Real::max(worst_offset, (y - radial).norm());
            let n = surface.normal(&x);
            assert!((n.norm() - 1.0).abs() < 1e-12, "{n}");
            let angle = n.dot(&radial).clamp(-1.0, 1.0).acos().to_degrees();
            worst_angle = Real::max(worst_angle, angle);
            if (x.norm() - 1.0).abs() < 0.1 {
                worst_angle_near = Real::max(worst_angle_near, angle);
            }
        }
        assert!(
            worst_radius < 1e-2,
            "projection off the sphere by {worst_radius}"
        );
        assert!(
            worst_offset < 2e-2,
            "projection off the radial point by {worst_offset}"
        );
        assert!(
            worst_angle_near < 0.5,
            "normal off by {worst_angle_near} degrees"
        );
        assert!(worst_angle < 3.0, "normal off by {worst_angle} degrees");
    }

    /// The analytic gradient matches central differences of the field,
    /// including where the nearest-sample plane is blended in.
    #[test]
    fn gradient_matches_finite_differences() {
        let surface = sphere(2000);
        let mut seed = 13;
        let e = 1e-6;
        for x in shell_points(300, &mut seed) {
            let g = surface.field(&x).gradient;
            let fd = Vector::from_fn(|a, _| {
                let step = Vector::ith(a, e);
                (surface.signed_distance(&(x + step)) - surface.signed_distance(&(x - step)))
                    / (2.0 * e)
            });
            // A nearest-sample switch between the two evaluations makes a
            // (small) jump; skip those rare points rather than loosen.
            if (fd - g).norm() > 1e-4 * (1.0 + g.norm()) {
                let k = surface.nearest_sample(&x).expect("finite");
                let moved = (0..3).any(|a| {
                    let step = Vector::ith(a, e);
                    surface.nearest_sample(&(x + step)) != Some(k)
                        || surface.nearest_sample(&(x - step)) != Some(k)
                });
                assert!(moved, "at {x}: analytic {g}, differences {fd}");
            }
        }
    }

    /// A torus (R = 1, r = 0.4) sampled on its (u, v) lattice, denser on
    /// the inner side: a non-convex surface of genus one.
    fn torus(perturbation: Option<(Real, u64)>) -> (PointSurface, impl Fn(&Vector) -> Real) {
        let (big, small) = (1.0, 0.4);
        let (nu, nv) = (120, 48);
        let mut points = Vec::new();
        let mut normals = Vec::new();
        for i in 0..nu {
            for j in 0..nv {
                let u = 2.0 * PI * i as Real / nu as Real;
                let v = 2.0 * PI * (j as Real + 0.5 * (i % 2) as Real) / nv as Real;
                let n = Vector::new(v.cos() * u.cos(), v.cos() * u.sin(), v.sin());
                points.push(Vector::new(big * u.cos(), big * u.sin(), 0.0) + n * small);
                normals.push(n);
            }
        }
        if let Some((degrees, mut seed)) = perturbation {
            normals = perturb_normals(&normals, degrees, &mut seed);
        }
        let surface =
            PointSurface::new(&points, &normals, PointSurfaceParams::default()).expect("a torus");
        let exact = move |x: &Vector| {
            let ring = (x.x * x.x + x.y * x.y).sqrt() - big;
            (ring * ring + x.z * x.z).sqrt() - small
        };
        (surface, exact)
    }

    /// Points of a grid over the torus's box, with their exact distance,
    /// at least `margin` from the surface.
    fn torus_grid(exact: &impl Fn(&Vector) -> Real, margin: Real) -> Vec<(Vector, Real)> {
        grid(
            Vector::new(-1.7, -1.7, -0.7),
            Vector::new(1.7, 1.7, 0.7),
            30,
        )
        .map(|x| (x, exact(&x)))
        .filter(|(_, d)| d.abs() >= margin)
        .collect()
    }

    #[test]
    fn torus_inside_and_outside_are_right_off_the_surface() {
        let (surface, exact) = torus(None);
        let points = torus_grid(&exact, surface.spacing());
        assert!(points.len() > 20_000, "{}", points.len());
        let inside = points.iter().filter(|(_, d)| *d < 0.0).count();
        assert!(inside > 2_000, "{inside} inside");
        for (x, d) in &points {
            assert_eq!(surface.contains(x), *d < 0.0, "at {x}: exact {d}");
        }
        // The hole is outside, the tube's core inside.
        assert!(surface.signed_distance(&Vector::zeros()) > 0.5);
        assert!(surface.signed_distance(&Vector::new(0.0, 1.0, 0.0)) < -0.3);
    }

    /// The union of two crossing bars, each face sampled on a square
    /// lattice and the samples inside the other bar dropped: sharp convex
    /// and concave edges.
    #[test]
    fn crossing_bars_inside_and_outside_are_right_off_the_surface() {
        let half = [Vector::new(1.0, 0.3, 0.3), Vector::new(0.3, 1.0, 0.3)];
        let spacing = 0.05;
        let inside = |h: &Vector, x: &Vector| (0..3).all(|a| x[a].abs() < h[a]);
        let (mut points, mut normals) = (Vec::new(), Vec::new());
        for (h, other) in [(half[0], half[1]), (half[1], half[0])] {
            for axis in 0..3 {
                for side in [-1.0, 1.0] {
                    let (s, t) = ((axis + 1) % 3, (axis + 2) % 3);
                    let (ms, mt) = (
                        (2.0 * h[s] / spacing).round() as usize,
                        (2.0 * h[t] / spacing).round() as usize,
                    );
                    for i in 0..ms {
                        for j in 0..mt {
                            let mut p = Vector::zeros();
                            p[axis] = side * h[axis];
                            p[s] = -h[s] + (i as Real + 0.5) * 2.0 * h[s] / ms as Real;
                            p[t] = -h[t] + (j as Real + 0.5) * 2.0 * h[t] / mt as Real;
                            if !inside(&other, &p) {
                                points.push(p);
                                normals.push(Vector::ith(axis, side));
                            }
                        }
                    }
                }
            }
        }
        let surface = PointSurface::new(&points, &normals, PointSurfaceParams::default())
            .expect("crossing bars");
        // Distance to a box, exact outside and a lower bound on the depth
        // inside; the union's is the smaller of the two.
        let box_distance = |h: &Vector, x: &Vector| {
            let q = x.abs() - h;
            q.sup(&Vector::zeros()).norm() + q.max().min(0.0)
        };
        let margin = surface.spacing();
        let mut checked = 0;
        for x in grid(
            Vector::new(-1.2, -1.2, -0.5),
            Vector::new(1.2, 1.2, 0.5),
            30,
        ) {
            let d = box_distance(&half[0], &x).min(box_distance(&half[1], &x));
            if d.abs() < margin {
                continue;
            }
            checked += 1;
            assert_eq!(surface.contains(&x), d < 0.0, "at {x}: exact {d}");
        }
        assert!(checked > 15_000, "{checked}");
    }

    /// Normals turned by up to 20 degrees: the sign is still right one
    /// sample spacing off the surface, for the sphere and the torus.
    #[test]
    fn noisy_normals_keep_the_sign_a_spacing_away() {
        let mut seed = 21;
        let points = fibonacci_sphere(3000);
        let normals = perturb_normals(&points, 20.0, &mut seed);
        let surface = PointSurface::new(&points, &normals, PointSurfaceParams::default())
            .expect("a noisy sphere");
        let spacing = surface.spacing();
        let mut checked = 0;
        for x in shell_points(4000, &mut seed).into_iter().chain(grid(
            Vector::repeat(-2.0),
            Vector::repeat(2.0),
            16,
        )) {
            let exact = x.norm() - 1.0;
            if exact.abs() >= spacing {
                checked += 1;
                assert_eq!(surface.contains(&x), exact < 0.0, "at {x}: exact {exact}");
            }
        }
        assert!(checked > 6_000, "{checked}");

        let (surface, exact) = torus(Some((20.0, 22)));
        for (x, d) in torus_grid(&exact, surface.spacing()) {
            assert_eq!(surface.contains(&x), d < 0.0, "at {x}: exact {d}");
        }
    }

    #[test]
    fn non_finite_queries_give_nan_without_panicking() {
        let surface = sphere(500);
        let nan = Vector::new(Real::NAN, 0.0, 0.0);
        assert!(surface.signed_distance(&nan).is_nan());
        assert!(!surface.contains(&Vector::new(0.0, Real::INFINITY, 0.0)));
        assert!(surface.normal(&nan).x.is_nan());
        assert!(surface.project(&nan).x.is_nan());
    }

    #[test]
    fn spacing_follows_the_sampling_and_duplicates_are_tolerated() {
        let n = 2000;
        let surface = sphere(n);
        // Hexagonal-ish lattice: the spacing of n points on area 4 pi.
        let expected = (4.0 * PI / n as Real).sqrt();
        let ratio = surface.spacing() / expected;
        assert!((0.8..1.3).contains(&ratio), "{ratio}");
        // A third of the points doubled: still the same sphere.
        let mut points = fibonacci_sphere(n);
        points.extend_from_within(..n / 3);
        let surface = PointSurface::new(&points, &points, PointSurfaceParams::default())
            .expect("some duplicates");
        for x in [Vector::new(0.0, 0.0, 0.9), Vector::new(1.1, 0.0, 0.0)] {
            let error = (surface.signed_distance(&x) - (x.norm() - 1.0)).abs();
            assert!(error < 1e-2, "at {x}: {error}");
        }
    }

    #[test]
    fn each_invalid_input_is_refused_with_its_reason() {
        let points = fibonacci_sphere(100);
        let params = PointSurfaceParams::default();
        let fit = |p: &[Vector], n: &[Vector], params| PointSurface::new(p, n, params).err();
        let with = |i: usize, v: Vector, from: &[Vector]| {
            let mut v2 = from.to_vec();
            v2[i] = v;
            v2
        };
        let nan = Vector::new(0.0, Real::NAN, 0.0);
        let cases: Vec<(Option<PointCloudError>, &str)> = vec![
            (fit(&[], &[], params), "empty"),
            (fit(&points, &points[1..], params), "99 normals"),
            (fit(&points[..10], &points[..10], params), "at least 16"),
            (
                fit(
                    &points[..20],
                    &points[..20],
                    PointSurfaceParams {
                        neighbours: 30,
                        ..params
                    },
                ),
                "at least 31",
            ),
            (fit(&with(7, nan, &points), &points, params), "point 7"),
            (
                fit(&points, &with(8, Vector::zeros(), &points), params),
                "point 8",
            ),
            (fit(&points, &with(9, nan, &points), params), "point 9"),
            (
                fit(&with(3, Vector::repeat(1e300), &points), &points, params),
                "scale them down",
            ),
            (
                fit(&vec![Vector::repeat(1.0); 50], &points[..50], params),
                "duplicated",
            ),
            (
                fit(
                    &points,
                    &points,
                    PointSurfaceParams {
                        neighbours: 0,
                        ..params
                    },
                ),
                "neighbours = 0",
            ),
            (
                fit(
                    &points,
                    &points,
                    PointSurfaceParams {
                        neighbours: 65,
                        ..params
                    },
                ),
                "between 1 and 64",
            ),
            (
                fit(
                    &points,
                    &points,
                    PointSurfaceParams {
                        support: 0.5,
                        ..params
                    },
                ),
                "support = 0.5",
            ),
            (
                fit(
                    &points,
                    &points,
                    PointSurfaceParams {
                        support: Real::NAN,
                        ..params
                    },
                ),
                "support = NaN",
            ),
        ];
        for (err, what) in cases {
            let err = err.unwrap_or_else(|| panic!("{what}: accepted"));
            assert!(err.to_string().contains(what), "{what}: {err}");
        }
        // Over the cap, refused before anything is allocated for it.
        let many = vec![Vector::zeros(); MAX_POINTS + 1];
        let err = fit(&many, &many, params).expect("too many");
        assert!(
            matches!(err, PointCloudError::TooManyPoints { .. }),
            "{err}"
        );
        assert!(err.to_string().contains("thin the cloud"), "{err}");
        // Normals of any nonzero length are taken as directions.
        let long: Vec<Vector> = points.iter().map(|n| n * 1e-200).collect();
        assert!(fit(&points, &long, params).is_none());
    }
}
