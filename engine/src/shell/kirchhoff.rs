//! The Kirchhoff–Love energy at one point of the middle surface (Guo–Qin
//! Section 5.2, Eq. 21-23, after Cirak, Ortiz & Schröder 2000), with its
//! exact gradient and Hessian, so that Newton's method converges
//! quadratically however large the rotations.
//!
//! At a point of the parametric domain the deformed middle surface is
//! known by five vectors, its *local unknowns* `q`: the tangents
//! `a_1 = x_,1`, `a_2 = x_,2` and the second derivatives `a_11`, `a_22`,
//! `a_12`. With `n = a_1 x a_2 / |a_1 x a_2|`, the first and second
//! fundamental forms are `a_ab = a_a . a_b` and `b_ab = a_,ab . n`, and
//! against the reference surface's `A_ab`, `B_ab` the membrane and
//! bending strains are
//!
//! ```text
//! eps_ab = (a_ab - A_ab) / 2          kap_ab = b_ab - B_ab
//! ```
//!
//! Both are exact for any rigid motion (they vanish) and need no small
//! rotation. The energy per unit reference area is
//!
//! ```text
//! W = t/2 eps : H : eps + t^3/24 kap : H : kap
//! H^abcd = E / (1 - nu^2) [ nu A^ab A^cd + (1 - nu)/2 (A^ac A^bd + A^ad A^bc) ]
//! ```
//!
//! with `A^ab` the inverse of the reference metric: the plane-stress law in
//! the surface's curvilinear coordinates. In Voigt form, with engineering
//! shear `e = (eps_11, eps_22, 2 eps_12)` and `k` likewise,
//! `W = t/2 e^T D e + t^3/24 k^T D k`, `D` the 3 x 3 matrix of `H` built
//! by [`Reference::new`].
//!
//! The derivatives: `e` is quadratic in `a_1`, `a_2`; `b_ab = a_,ab . n`
//! is linear in `a_,ab` and reaches `a_1`, `a_2` through `n`. With
//! `t = a_1 x a_2`, `j = |t|` and `g(t) = v . t / j` for a fixed `v`,
//!
//! ```text
//! grad g   = (v - (v . n) n) / j
//! hess g   = [ -(v n^T + n v^T) - (v . n) I + 3 (v . n) n n^T ] / j^2
//! dt/da_1  = -[a_2]x      dt/da_2 = [a_1]x      d2 t_k / da_1,r da_2,s = eps_krs
//! ```
//!
//! and the chain rule through the bilinear `t` gives the blocks of the
//! Hessian. The tests check the gradient against central differences of
//! the energy and the Hessian against central differences of the
//! gradient.

use crate::math::{Real, Vector};
use nalgebra::Matrix3;

/// Local unknowns at a point: `a_1`, `a_2`, `a_11`, `a_22`, `a_12`.
pub const SLOTS: usize = 5;

/// Scalar unknowns at a point: three per slot.
pub const LOCAL: usize = 3 * SLOTS;

/// The five vectors that know the surface at a point (see the module's
/// documentation), in the order of [`SLOTS`].
pub type Local = [Vector; SLOTS];

/// The energy's gradient in the local unknowns, `3 * slot + component`.
pub type LocalGradient = [Real; LOCAL];

/// The energy's Hessian in the local unknowns.
pub type LocalHessian = [[Real; LOCAL]; LOCAL];

/// The weights of `(11, 22, 12)` in engineering (Voigt) strain.
const VOIGT: [Real; 3] = [1.0, 1.0, 2.0];

/// The reference surface at a point: its fundamental forms, area element
/// and constitutive matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reference {
    /// `(A_11, A_22, A_12)`.
    pub metric: [Real; 3],
    /// `(B_11, B_22, B_12)`.
    pub curvature: [Real; 3],
    /// `|A_1 x A_2|`: reference area per unit parametric area.
    pub area: Real,
    /// Unit normal `A_1 x A_2 / |A_1 x A_2|`.
    pub normal: Vector,
    /// `D`, the plane-stress matrix of `H^abcd` in Voigt form (per unit
    /// thickness).
    pub d: Matrix3<Real>,
}

impl Reference {
    /// The reference surface known by `q` (as [`Local`]) of a material
    /// with Young's modulus `young` and Poisson's ratio `poisson`, or
    /// `None` where the tangents are parallel (no surface there).
    pub fn new(q: &Local, young: Real, poisson: Real) -> Option<Self> {
        let t = q[0].cross(&q[1]);
        let area = t.norm();
        let metric = [q[0].dot(&q[0]), q[1].dot(&q[1]), q[0].dot(&q[1])];
        let det = metric[0] * metric[1] - metric[2] * metric[2];
        if !(area > 0.0 && det > 0.0 && area.is_finite()) {
            return None;
        }
        let normal = t / area;
        let curvature = [q[2].dot(&normal), q[3].dot(&normal), q[4].dot(&normal)];
        // Contravariant metric A^ab, the inverse of A_ab.
        let (i11, i22, i12) = (metric[1] / det, metric[0] / det, -metric[2] / det);
        let c = young / (1.0 - poisson * poisson);
        let d01 = c * (poisson * i11 * i22 + (1.0 - poisson) * i12 * i12);
        let d22 = c * (0.5 * (1.0 - poisson) * i11 * i22 + 0.5 * (1.0 + poisson) * i12 * i12);
        let d = Matrix3::new(
            c * i11 * i11,
            d01,
            c * i11 * i12,
            d01,
            c * i22 * i22,
            c * i22 * i12,
            c * i11 * i12,
            c * i22 * i12,
            d22,
        );
        Some(Self {
            metric,
            curvature,
            area,
            normal,
            d,
        })
    }
}

/// Membrane and bending strains at a point, engineering shear:
/// `(eps_11, eps_22, 2 eps_12)` and `(kap_11, kap_22, 2 kap_12)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Strains {
    /// Membrane (Green–Lagrange) strain of the middle surface.
    pub membrane: Vector,
    /// Change of curvature.
    pub bending: Vector,
}

/// The strains at a point whose deformed surface is known by `q`, or
/// `None` where it has folded flat (parallel tangents).
pub fn strains(reference: &Reference, q: &Local) -> Option<Strains> {
    let t = q[0].cross(&q[1]);
    let j = t.norm();
    if !(j > 0.0 && j.is_finite()) {
        return None;
    }
    let n = t / j;
    let a = &reference.metric;
    let b = &reference.curvature;
    let membrane = Vector::new(
        0.5 * (q[0].dot(&q[0]) - a[0]),
        0.5 * (q[1].dot(&q[1]) - a[1]),
        q[0].dot(&q[1]) - a[2],
    );
    let bending = Vector::new(
        q[2].dot(&n) - b[0],
        q[3].dot(&n) - b[1],
        VOIGT[2] * (q[4].dot(&n) - b[2]),
    );
    Some(Strains { membrane, bending })
}

/// The energy per unit reference area of a shell of thickness
/// `thickness`, or `None` where the surface has folded flat.
pub fn energy(reference: &Reference, thickness: Real, q: &Local) -> Option<Real> {
    let s = strains(reference, q)?;
    let d = &reference.d;
    Some(
        0.5 * thickness * s.membrane.dot(&(d * s.membrane))
            + thickness.powi(3) / 24.0 * s.bending.dot(&(d * s.bending)),
    )
}

/// The cross-product matrix `[v]x`: `[v]x w = v x w`.
fn cross_matrix(v: &Vector) -> Matrix3<Real> {
    Matrix3::new(0.0, -v[2], v[1], v[2], 0.0, -v[0], -v[1], v[0], 0.0)
}

/// Adds `m` into the `(row, col)` slot block of `h`.
fn add_block(h: &mut LocalHessian, row: usize, col: usize, m: &Matrix3<Real>) {
    for r in 0..3 {
        for c in 0..3 {
            h[3 * row + r][3 * col + c] += m[(r, c)];
        }
    }
}

/// The energy's gradient and Hessian in the local unknowns at a point
/// whose deformed surface is known by `q`; returns the energy, or `None`
/// (and leaves `grad` and `hess` untouched) where the surface has folded
/// flat.
pub fn gradient_hessian(
    reference: &Reference,
    thickness: Real,
    q: &Local,
    grad: &mut LocalGradient,
    hess: &mut LocalHessian,
) -> Option<Real> {
    let s = strains(reference, q)?;
    let t = q[0].cross(&q[1]);
    let j = t.norm();
    let n = t / j;
    let d = &reference.d;
    let membrane_stiffness = thickness;
    let bending_stiffness = thickness.powi(3) / 12.0;
    // Stress resultants: `N = t D e`, `M = t^3/12 D k`.
    let force = membrane_stiffness * (d * s.membrane);
    let moment = bending_stiffness * (d * s.bending);

    // First derivatives of each strain, as 15-vectors.
    let mut de = [[0.0; LOCAL]; 3];
    let mut dk = [[0.0; LOCAL]; 3];
    for c in 0..3 {
        de[0][c] = q[0][c];
        de[1][3 + c] = q[1][c];
        de[2][c] = q[1][c];
        de[2][3 + c] = q[0][c];
    }
    // Per bending component `i`: `v = a_,ab`, `grad g = P v / j`.
    let mut slope = [Vector::zeros(); 3];
    for i in 0..3 {
        let v = q[2 + i];
        let g = (v - v.dot(&n) * n) / j;
        slope[i] = g;
        let w = VOIGT[i];
        let da1 = q[1].cross(&g);
        let da2 = g.cross(&q[0]);
        for c in 0..3 {
            dk[i][c] = w * da1[c];
            dk[i][3 + c] = w * da2[c];
            dk[i][3 * (2 + i) + c] = w * n[c];
        }
    }

    for (k, g) in grad.iter_mut().enumerate() {
        *g = (0..3)
            .map(|i| force[i] * de[i][k] + moment[i] * dk[i][k])
            .sum();
    }

    // Gauss–Newton part: t de^T D de + t^3/12 dk^T D dk, through
    // `(D de)` and `(D dk)` (3 x 15 each) and by symmetry.
    let mut dde = [[0.0; LOCAL]; 3];
    let mut ddk = [[0.0; LOCAL]; 3];
    for i in 0..3 {
        for m in 0..3 {
            let (cm, cb) = (
                membrane_stiffness * d[(i, m)],
                bending_stiffness * d[(i, m)],
            );
            for c in 0..LOCAL {
                dde[i][c] += cm * de[m][c];
                ddk[i][c] += cb * dk[m][c];
            }
        }
    }
    for r in 0..LOCAL {
        for c in r..LOCAL {
            let v = (0..3)
                .map(|i| de[i][r] * dde[i][c] + dk[i][r] * ddk[i][c])
                .sum();
            hess[r][c] = v;
            hess[c][r] = v;
        }
    }

    // Second derivatives of the membrane strains, weighted by `N`.
    let eye = Matrix3::identity();
    add_block(hess, 0, 0, &(force[0] * eye));
    add_block(hess, 1, 1, &(force[1] * eye));
    add_block(hess, 0, 1, &(force[2] * eye));
    add_block(hess, 1, 0, &(force[2] * eye));

    // Second derivatives of the bending strains, weighted by `M`.
    let projector = eye - n * n.transpose();
    let dt1 = -cross_matrix(&q[1]);
    let dt2 = cross_matrix(&q[0]);
    // dn/da_1, dn/da_2.
    let dn1 = projector * dt1 / j;
    let dn2 = projector * dt2 / j;
    for i in 0..3 {
        let weight = moment[i] * VOIGT[i];
        if weight == 0.0 {
            continue;
        }
        let v = q[2 + i];
        let vn = v.dot(&n);
        let hg = (-(v * n.transpose() + n * v.transpose()) - vn * eye
            + 3.0 * vn * n * n.transpose())
            / (j * j);
        let cross = cross_matrix(&slope[i]);
        add_block(hess, 0, 0, &(weight * dt1.transpose() * hg * dt1));
        add_block(hess, 1, 1, &(weight * dt2.transpose() * hg * dt2));
        add_block(hess, 0, 1, &(weight * (dt1.transpose() * hg * dt2 - cross)));
        add_block(hess, 1, 0, &(weight * (dt2.transpose() * hg * dt1 + cross)));
        // d2 (v . n) / dv da_a = dn/da_a.
        add_block(hess, 2 + i, 0, &(weight * dn1));
        add_block(hess, 2 + i, 1, &(weight * dn2));
        add_block(hess, 0, 2 + i, &(weight * dn1.transpose()));
        add_block(hess, 1, 2 + i, &(weight * dn2.transpose()));
    }
    Some(
        0.5 * membrane_stiffness * s.membrane.dot(&(d * s.membrane))
            + 0.5 * bending_stiffness * s.bending.dot(&(d * s.bending)),
    )
}

#[cfg(test)]
mod tests;
