//! The thin shells' discretisation on the plate every shell code starts
//! from (Guo–Qin Sections 4.2 and 5.2): a quadtree over the parametric
//! domain (`geometry/quadtree`), MLS shape functions with the
//! tensor-product weight and their second derivatives
//! (`approx/mls/hessian.rs`), Gauss cells, and the Kirchhoff bending
//! energy of a flat plate (the small-deflection limit of the
//! Kirchhoff–Love shell):
//!
//! ```text
//! U = 1/2 int D [ (w_xx + w_yy)^2 - 2 (1 - nu) (w_xx w_yy - w_xy^2) ] dA
//! ```
//!
//! A clamped square plate of side `a` under uniform pressure `q` deflects
//! at its centre by `0.00126 q a^4 / D` (Timoshenko & Woinowsky-Krieger,
//! *Theory of Plates and Shells*, 1959, Table 35, nu = 0.3). The clamp is
//! a penalty on the deflection and the normal slope along the edges,
//! scaled with the cell `h` as `beta D / h^3` and `beta D / h`.
//!
//! Measured (the test prints them all): with `beta = 10` the centre deflection
//! is 0.877, 0.965 and 1.002 of Timoshenko's at 8, 16 and 32 cells a side.
//! The clamp's strength matters at a few per cent: at 32 cells `beta = 3`
//! gave 1.061 (too weak a clamp) and `beta = 100` 0.978 (the penalty
//! stiffening the approximation near the edges); so does the quadrature:
//! one 4 x 4 rule per leaf instead of 2 x 2 cells of it gave 1.060.

use meshless_engine::approx::gauss::gauss_legendre;
use meshless_engine::approx::mls::{Mls, MlsParams, Order, ShapeHessians};
use meshless_engine::approx::tensor::tensor_weight_hessian;
use meshless_engine::cancel::Cancel;
use meshless_engine::geometry::quadtree::{ChartDomain, Point2, Quadtree, QuadtreeParams};
use meshless_engine::math::{Real, Vector};
use nalgebra::{DMatrix, DVector};

/// Timoshenko & Woinowsky-Krieger's coefficient for the clamped square
/// plate's centre deflection, `w = alpha q a^4 / D` (nu = 0.3).
const TIMOSHENKO: Real = 0.00126;

/// The unit square, a flat chart: lambda = 1.
struct UnitSquare;

impl ChartDomain for UnitSquare {
    fn distance(&self, u: Point2) -> Real {
        let dx = (u[0] - 0.5).abs() - 0.5;
        let dy = (u[1] - 0.5).abs() - 0.5;
        let outside = (dx.max(0.0).powi(2) + dy.max(0.0).powi(2)).sqrt();
        if outside > 0.0 { outside } else { dx.max(dy) }
    }

    fn lambda(&self, _: Point2) -> Real {
        1.0
    }
}

/// The shape functions, gradients and Hessians at `u` over every node
/// (a uniform tree: every support of half-width `half`).
fn shape(mls: &Mls, nodes: &[Vector], half: Real, u: Point2, out: &mut ShapeHessians) {
    let fit = mls
        .shape_hessians_weighted(
            &Vector::new(u[0], u[1], 0.0),
            nodes,
            |_, d| tensor_weight_hessian(2, d, &[half; 3]),
            out,
        )
        .expect("covered");
    assert_eq!(fit.order, Order::Quadratic, "no fallback at {u:?}");
}

/// The nodes whose supports hold the point of the last fit.
fn supported(sh: &ShapeHessians) -> Vec<usize> {
    (0..sh.values().len())
        .filter(|&i| sh.values()[i] != 0.0 || sh.gradients()[i].norm() != 0.0)
        .collect()
}

/// The clamped plate's centre deflection over `q a^4 / D` with cells of
/// `cell` (a = q = D = 1), the clamp's penalty scaled by `beta`,
/// `subdivision^2` integration cells per leaf.
fn clamped_plate(cell: Real, beta: Real, subdivision: usize) -> Real {
    let nu = 0.3;
    // Supports of 5.5 cells: a corner of the domain lies under three
    // nodes along each axis, the nine a quadratic basis wants.
    let params = QuadtreeParams {
        eta: 5.5,
        subdivision,
        ..QuadtreeParams::new(cell)
    };
    let tree = Quadtree::build(&UnitSquare, [0.0, 0.0], [1.0, 1.0], &params, &Cancel::new())
        .expect("tree");
    let nodes: Vec<Vector> = tree
        .nodes()
        .iter()
        .map(|u| Vector::new(u[0], u[1], 0.0))
        .collect();
    let n = nodes.len();
    let half = tree.half_width(0);
    let mls = Mls::new(2, MlsParams::new(Order::Quadratic, half)).expect("parameters");
    let shape = |u: Point2, out: &mut ShapeHessians| shape(&mls, &nodes, half, u, out);
    let mut k = DMatrix::<Real>::zeros(n, n);
    let mut f = DVector::<Real>::zeros(n);
    let mut sh = ShapeHessians::new();
    for g in tree.gauss_points() {
        shape(g.at, &mut sh);
        let h = sh.hessians();
        let near = supported(&sh);
        for &i in &near {
            let hi = &h[i];
            f[i] += g.weight * sh.values()[i];
            for &j in &near {
                let hj = &h[j];
                let bend = (hi[(0, 0)] + hi[(1, 1)]) * (hj[(0, 0)] + hj[(1, 1)])
                    - (1.0 - nu)
                        * (hi[(0, 0)] * hj[(1, 1)] + hi[(1, 1)] * hj[(0, 0)]
                            - 2.0 * hi[(0, 1)] * hj[(0, 1)]);
                k[(i, j)] += g.weight * bend;
            }
        }
    }
    // The clamp: w = 0 and dw/dn = 0 along the edges, as a penalty over
    // 4-point Gauss rules on each cell-long piece of edge.
    let (alpha_w, alpha_t) = (beta / cell.powi(3), beta / cell);
    let pieces = (1.0 / cell).round() as usize;
    let (x, w) = gauss_legendre(4);
    for piece in 0..pieces {
        for (xa, wa) in x.iter().zip(w) {
            let s = (piece as Real + 0.5 * (1.0 + xa)) * cell;
            let length = 0.5 * wa * cell;
            for (at, normal) in [
                ([s, 0.0], 1usize),
                ([s, 1.0], 1),
                ([0.0, s], 0),
                ([1.0, s], 0),
            ] {
                shape(at, &mut sh);
                let (v, g) = (sh.values(), sh.gradients());
                let near = supported(&sh);
                for &i in &near {
                    for &j in &near {
                        k[(i, j)] += length
                            * (alpha_w * v[i] * v[j] + alpha_t * g[i][normal] * g[j][normal]);
                    }
                }
            }
        }
    }
    let w = k.cholesky().expect("positive definite").solve(&f);
    shape([0.5, 0.5], &mut sh);
    sh.values()
        .iter()
        .zip(w.iter())
        .map(|(p, w)| p * w)
        .sum::<Real>()
        / TIMOSHENKO
}

/// The centre deflection converges on Timoshenko's as the cells shrink,
/// to within 1 % at 32 cells a side; at 32 cells a weaker clamp lets the
/// plate sag further, a stiffer one less, and one Gauss rule per leaf
/// misjudges the bending energy (the test could fail every way; it
/// prints the figures the module's documentation gives).
#[test]
fn a_clamped_square_plate_deflects_as_timoshenko_says() {
    let ratios: Vec<Real> = [8.0, 16.0, 32.0]
        .iter()
        .map(|n| clamped_plate(1.0 / n, 10.0, 2))
        .collect();
    eprintln!("centre deflection / Timoshenko at 8, 16, 32 cells: {ratios:.3?}");
    let errors: Vec<Real> = ratios.iter().map(|r| (r - 1.0).abs()).collect();
    assert!(errors[0] > errors[1] && errors[1] > errors[2], "{ratios:?}");
    assert!(errors[2] < 0.01, "{ratios:?}");
    let (weak, stiff, one_rule) = (
        clamped_plate(1.0 / 32.0, 3.0, 2),
        clamped_plate(1.0 / 32.0, 100.0, 2),
        clamped_plate(1.0 / 32.0, 10.0, 1),
    );
    eprintln!(
        "at 32 cells: beta = 3 {weak:.3}, beta = 100 {stiff:.3}, one rule per leaf {one_rule:.3}"
    );
    assert!(weak > ratios[2] + 0.03, "a weaker clamp sags more: {weak}");
    assert!(
        stiff < ratios[2] - 0.01,
        "a stiffer clamp sags less: {stiff}"
    );
    assert!(one_rule > ratios[2] + 0.03, "one rule per leaf: {one_rule}");
}
