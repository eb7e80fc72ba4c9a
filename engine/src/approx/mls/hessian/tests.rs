use super::*;
use crate::approx::mls::{MlsParams, ShapeFunctions};
use crate::approx::tensor::tensor_weight_hessian;

/// A jittered lattice of unit spacing, `-3..=3` along each of the first
/// `dim` axes, each node moved by up to 0.2 (a fixed hash, so the
/// layout is irregular and the same on every run).
fn nodes(dim: usize) -> Vec<Vector> {
    let jitter = |k: u64| {
        let h = k.wrapping_mul(0x9E37_79B9_7F4A_7C15).rotate_left(17) ^ 0x2545_F491_4F6C_DD1D;
        (h % 10_007) as Real / 10_007.0 * 0.4 - 0.2
    };
    let range = -3..=3i64;
    let mut out = Vec::new();
    let mut id = 0u64;
    for i in range.clone() {
        for j in range.clone() {
            for k in if dim == 3 { range.clone() } else { 0..=0 } {
                let mut x = Vector::new(i as Real, j as Real, k as Real);
                for a in 0..dim {
                    id += 1;
                    x[a] += jitter(id);
                }
                out.push(x);
            }
        }
    }
    out
}

/// Square (cubic) supports of half-width 1.6 spacings, as a quadtree's
/// nodes with eta = 3.2.
const HALF: [Real; 3] = [1.6; 3];

fn fit(dim: usize, order: Order, x: &Vector, nodes: &[Vector]) -> ShapeHessians {
    let mls = Mls::new(dim, MlsParams::new(order, HALF[0])).expect("parameters");
    let mut out = ShapeHessians::new();
    let fit = mls
        .shape_hessians_weighted(
            x,
            nodes,
            |_, d| tensor_weight_hessian(dim, d, &HALF),
            &mut out,
        )
        .expect("covered");
    assert_eq!(fit.order, order, "no rank fallback in this layout");
    out
}

const POINTS: [[Real; 3]; 3] = [
    [0.137_291, -0.291_347, 0.073_113],
    [0.611_723, 0.431_509, -0.383_271],
    [-0.771_919, 0.051_337, 0.522_651],
];

fn point(dim: usize, p: &[Real; 3]) -> Vector {
    Vector::new(p[0], p[1], if dim == 3 { p[2] } else { 0.0 })
}

/// The Hessians are central differences of the gradients, for both bases
/// in 2D and 3D (away from the lines where the spline's curvature jumps:
/// no node lies within 1e-5 of one, checked), and the values and
/// gradients are those of `shape_functions_weighted`.
#[test]
fn hessians_match_differences_of_the_gradients() {
    let e = 1e-6;
    for dim in [2, 3] {
        let nodes = nodes(dim);
        for order in [Order::Linear, Order::Quadratic] {
            for p in &POINTS {
                let x = point(dim, p);
                for xi in &nodes {
                    for a in 0..dim {
                        let s = ((x[a] - xi[a]) / HALF[a]).abs();
                        assert!((s - 0.5).abs() > 1e-5, "a node on a kink: {s}");
                    }
                }
                let at = fit(dim, order, &x, &nodes);
                let mls = Mls::new(dim, MlsParams::new(order, HALF[0])).expect("parameters");
                let mut plain = ShapeFunctions::new();
                mls.shape_functions_weighted(
                    &x,
                    &nodes,
                    |_, d| tensor_weight_hessian(dim, d, &HALF).map(|(w, g, _)| (w, g)),
                    &mut plain,
                )
                .expect("covered");
                let scale = at
                    .hessians()
                    .iter()
                    .map(|h| h.abs().max())
                    .fold(0.0, Real::max);
                assert!(scale > 0.1, "{dim}D {order:?}: Hessians of order one");
                for i in 0..nodes.len() {
                    assert!((at.values()[i] - plain.values()[i]).abs() < 1e-13);
                    assert!((at.gradients()[i] - plain.gradients()[i]).norm() < 1e-12);
                }
                for l in 0..dim {
                    let mut step = Vector::zeros();
                    step[l] = e;
                    let plus = fit(dim, order, &(x + step), &nodes);
                    let minus = fit(dim, order, &(x - step), &nodes);
                    for i in 0..nodes.len() {
                        for k in 0..dim {
                            let fd = (plus.gradients()[i][k] - minus.gradients()[i][k]) / (2.0 * e);
                            let h = at.hessians()[i][(k, l)];
                            assert!(
                                (h - fd).abs() < 1e-5 * scale,
                                "{dim}D {order:?} node {i} ({k}, {l}): {h} against {fd}"
                            );
                        }
                    }
                }
                // Nothing past the dimension.
                if dim == 2 {
                    assert!(at.hessians().iter().all(|h| h.row(2).norm() == 0.0));
                }
            }
        }
    }
}

/// A quadratic basis reproduces the Hessian of every quadratic field, a
/// linear one gives a linear field none; both sum to zero (the partition
/// of unity's second derivatives).
#[test]
fn second_derivatives_of_polynomials_are_reproduced() {
    for dim in [2, 3] {
        let nodes = nodes(dim);
        // f = 1 + 2x - 3y + z + x^2/2 + 3xy/2 - 2y^2 + yz - z^2/4 + 2xz.
        let z = if dim == 3 { 1.0 } else { 0.0 };
        let quadratic = |x: &Vector| {
            1.0 + 2.0 * x.x - 3.0 * x.y + z * x.z + 0.5 * x.x * x.x + 1.5 * x.x * x.y
                - 2.0 * x.y * x.y
                + z * (x.y * x.z - 0.25 * x.z * x.z + 2.0 * x.x * x.z)
        };
        let expected = Matrix3::new(1.0, 1.5, 2.0 * z, 1.5, -4.0, z, 2.0 * z, z, -0.5 * z);
        let linear = |x: &Vector| 1.0 + 2.0 * x.x - 3.0 * x.y + z * x.z;
        let f: Vec<Real> = nodes.iter().map(quadratic).collect();
        let g: Vec<Real> = nodes.iter().map(linear).collect();
        let ones = vec![1.0; nodes.len()];
        for p in &POINTS {
            let x = point(dim, p);
            let q = fit(dim, Order::Quadratic, &x, &nodes);
            let error = (q.hessian(&f) - expected).abs().max();
            assert!(error < 1e-10, "{dim}D quadratic: {error:e}");
            assert!(
                (q.values().iter().zip(&f).map(|(a, b)| a * b).sum::<Real>() - quadratic(&x)).abs()
                    < 1e-12
            );
            assert!(q.hessian(&ones).abs().max() < 1e-11);
            let l = fit(dim, Order::Linear, &x, &nodes);
            assert!(l.hessian(&g).abs().max() < 1e-10, "{dim}D linear");
            assert!(l.hessian(&ones).abs().max() < 1e-11);
            // The linear basis does not reproduce the quadratic's
            // curvature: the test could fail.
            assert!((l.hessian(&f) - expected).abs().max() > 1e-3);
        }
    }
}

/// A point no node covers is refused, and the results are zeros.
#[test]
fn an_uncovered_point_is_refused() {
    let nodes = nodes(2);
    let mls = Mls::new(2, MlsParams::new(Order::Linear, HALF[0])).expect("parameters");
    let mut out = ShapeHessians::new();
    let far = Vector::new(50.0, 0.0, 0.0);
    let error = mls
        .shape_hessians_weighted(
            &far,
            &nodes,
            |_, d| tensor_weight_hessian(2, d, &HALF),
            &mut out,
        )
        .expect_err("refused");
    assert!(matches!(error, MlsError::NoSupport { .. }));
    assert!(out.hessians().iter().all(|h| h.abs().max() == 0.0));
}
