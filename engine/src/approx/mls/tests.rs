//! Unit tests of the MLS fits: gradients against central differences,
//! partition of unity and linear completeness, the rank fallback on
//! degenerate layouts, scale invariance of the conditioning, the linear
//! direct gradient against Müller et al.'s unscaled Eq. 37-38, and
//! parameter validation.

use super::*;
use crate::testing::uniform;
use nalgebra::Matrix3;

/// A lattice of `(2 half + 1)^dim` points with unit spacing around the
/// origin, each jittered by up to `jitter` spacings per axis.
fn lattice(dim: usize, half: i32, jitter: Real, seed: &mut u64) -> Vec<Vector> {
    let range = |d: usize| if d < dim { -half..=half } else { 0..=0 };
    let mut points = Vec::new();
    for i in range(0) {
        for j in range(1) {
            for k in range(2) {
                let mut p = Vector::new(i as Real, j as Real, k as Real);
                for a in 0..dim {
                    p[a] += jitter * (2.0 * uniform(seed) - 1.0);
                }
                points.push(p);
            }
        }
    }
    points
}

/// A random point in `[-r, r]^dim`.
fn random_point(dim: usize, r: Real, seed: &mut u64) -> Vector {
    let mut x = Vector::zeros();
    for a in 0..dim {
        x[a] = r * (2.0 * uniform(seed) - 1.0);
    }
    x
}

fn mls(dim: usize, order: Order, h: Real) -> Mls {
    Mls::new(dim, MlsParams::new(order, h)).expect("valid parameters")
}

/// The gradients of Eq. 30-31 (centred form) are the derivatives of the
/// shape functions: central differences of `phi_i` agree to 1e-7 of the
/// gradient scale `1/h`, for every dimension and order, on a jittered
/// layout, with each of the smooth weights.
#[test]
fn gradients_match_finite_differences() {
    let mut seed = 11;
    for weight in [
        KernelKind::Poly6,
        KernelKind::CubicSpline,
        KernelKind::WendlandC2,
    ] {
        for dim in 1..=3 {
            let nodes = lattice(dim, 3, 0.3, &mut seed);
            for order in Order::ALL {
                let h = 2.3;
                let params = MlsParams {
                    weight,
                    ..MlsParams::new(order, h)
                };
                let mls = Mls::new(dim, params).expect("valid");
                let mut at = ShapeFunctions::new();
                let (mut plus, mut minus) = (ShapeFunctions::new(), ShapeFunctions::new());
                for _ in 0..5 {
                    let x = random_point(dim, 0.8, &mut seed);
                    let fit = mls.shape_functions(&x, &nodes, &mut at).expect("support");
                    assert_eq!(fit.order, order, "{dim}D {order:?} at {x:?}");
                    let eps = 1e-5;
                    for k in 0..dim {
                        let mut e = Vector::zeros();
                        e[k] = eps;
                        mls.shape_functions(&(x + e), &nodes, &mut plus)
                            .expect("support");
                        mls.shape_functions(&(x - e), &nodes, &mut minus)
                            .expect("support");
                        for i in 0..nodes.len() {
                            let fd = (plus.values()[i] - minus.values()[i]) / (2.0 * eps);
                            let g = at.gradients()[i][k];
                            assert!(
                                (fd - g).abs() < 1e-7 / h,
                                "{weight:?} {dim}D {order:?}: d phi_{i} / dx_{k} = {g}, differences {fd}"
                            );
                        }
                    }
                }
            }
        }
    }
}

/// `sum phi_i = 1`, `sum phi_i x_i = x`, `sum grad phi_i = 0` and
/// `sum x_i grad phi_i^T = I` (the identity field's gradient), to 1e-12.
#[test]
fn partition_of_unity_and_linear_completeness() {
    let mut seed = 3;
    for dim in 1..=3 {
        let nodes = lattice(dim, 3, 0.25, &mut seed);
        for order in [Order::Linear, Order::Quadratic] {
            let mls = mls(dim, order, 2.2);
            let mut out = ShapeFunctions::new();
            for _ in 0..10 {
                let x = random_point(dim, 1.0, &mut seed);
                mls.shape_functions(&x, &nodes, &mut out).expect("support");
                let sum: Real = out.values().iter().sum();
                assert!(
                    (sum - 1.0).abs() < 1e-12,
                    "{dim}D {order:?}: sum phi = {sum}"
                );
                let first: Vector = out.values().iter().zip(&nodes).map(|(p, xi)| xi * *p).sum();
                assert!(
                    (first - x).norm() < 1e-12,
                    "{dim}D {order:?}: sum phi x = {first:?}, x = {x:?}"
                );
                let grad_sum: Vector = out.gradients().iter().sum();
                assert!(
                    grad_sum.norm() < 1e-12,
                    "{dim}D {order:?}: sum grad phi = {grad_sum:?}"
                );
                let jacobian: Matrix3<Real> = out
                    .gradients()
                    .iter()
                    .zip(&nodes)
                    .map(|(g, xi)| xi * g.transpose())
                    .sum();
                let mut identity = Matrix3::zeros();
                for a in 0..dim {
                    identity[(a, a)] = 1.0;
                }
                assert!(
                    (jacobian - identity).norm() < 1e-12,
                    "{dim}D {order:?}: {jacobian}"
                );
            }
        }
    }
}

/// Asserts that every value and gradient is finite.
fn assert_finite(out: &ShapeFunctions, what: &str) {
    assert!(
        out.values().iter().all(|v| v.is_finite()),
        "{what}: values {:?}",
        out.values()
    );
    assert!(
        out.gradients()
            .iter()
            .all(|g| g.iter().all(|v| v.is_finite())),
        "{what}: gradients {:?}",
        out.gradients()
    );
}

/// All neighbours on the plane z = 0 in 3D: the z column of the linear
/// moment matrix vanishes (tutorial Section 3.3), so linear and quadratic
/// fits fall back to the constant order, whose Shepard functions are
/// finite, sum to one and reproduce constants. The evaluation point lies
/// off the plane, so the centred basis does not hide the degeneracy. The
/// direct gradient at a node falls back to zero the same way.
#[test]
fn nodes_on_a_plane_fall_back_to_constant() {
    let mut seed = 5;
    let nodes: Vec<Vector> = lattice(2, 3, 0.2, &mut seed);
    let x = Vector::new(0.2, -0.1, 0.3);
    let mut out = ShapeFunctions::new();
    let mut direct = GradientWeights::new();
    for order in [Order::Linear, Order::Quadratic] {
        let mls = mls(3, order, 2.0);
        let fit = mls.shape_functions(&x, &nodes, &mut out).expect("support");
        assert_eq!(fit.order, Order::Constant, "{order:?}");
        assert_finite(&out, "plane");
        let sum: Real = out.values().iter().sum();
        assert!((sum - 1.0).abs() < 1e-12);
        let grad: Vector = out.gradients().iter().sum();
        assert!(grad.norm() < 1e-12);
        // The direct form pins the fit at a sample point: on the plane.
        let fit = mls.gradient_weights(&nodes[20], &nodes, &mut direct);
        assert_eq!(fit.order, Order::Constant, "direct {order:?}");
        assert!(direct.weights().iter().all(|g| *g == Vector::zeros()));
    }
    // In 2D the same layout is full rank.
    let fit = mls(2, Order::Quadratic, 2.0)
        .shape_functions(&x, &nodes, &mut out)
        .expect("support");
    assert_eq!(fit.order, Order::Quadratic);
}

/// Nodes on a line in 2D and 3D: linear and quadratic fall back to the
/// constant order; in 1D along that line they do not.
#[test]
fn nodes_on_a_line_fall_back_to_constant() {
    let direction = Vector::new(0.6, 0.8, 0.0);
    let nodes: Vec<Vector> = (-4..=4).map(|k| direction * (0.5 * k as Real)).collect();
    let x = direction * 0.3;
    let mut out = ShapeFunctions::new();
    for dim in [2, 3] {
        for order in [Order::Linear, Order::Quadratic] {
            let fit = mls(dim, order, 1.6)
                .shape_functions(&x, &nodes, &mut out)
                .expect("support");
            assert_eq!(fit.order, Order::Constant, "{dim}D {order:?}");
            assert_finite(&out, "line");
        }
    }
    let along: Vec<Vector> = (-4..=4)
        .map(|k| Vector::new(0.5 * k as Real, 0.0, 0.0))
        .collect();
    let fit = mls(1, Order::Quadratic, 1.6)
        .shape_functions(&Vector::new(0.3, 0.0, 0.0), &along, &mut out)
        .expect("support");
    assert_eq!(fit.order, Order::Quadratic);
}

/// Too few neighbours: 4 non-collinear nodes in 2D cannot fix 6 quadratic
/// coefficients, so the fit drops to linear and still reproduces a linear
/// field; 2 nodes in 2D drop to the constant order.
#[test]
fn too_few_neighbours_lower_the_order() {
    let nodes = [
        Vector::new(0.0, 0.0, 0.0),
        Vector::new(0.5, 0.1, 0.0),
        Vector::new(-0.2, 0.6, 0.0),
        Vector::new(0.3, -0.4, 0.0),
    ];
    let x = Vector::new(0.1, 0.1, 0.0);
    let mut out = ShapeFunctions::new();
    let fit = mls(2, Order::Quadratic, 1.0)
        .shape_functions(&x, &nodes, &mut out)
        .expect("support");
    assert_eq!(fit.order, Order::Linear);
    assert_finite(&out, "four nodes");
    let f = |p: &Vector| 2.0 - 3.0 * p.x + 0.5 * p.y;
    let values: Vec<Real> = nodes.iter().map(f).collect();
    assert!((out.interpolate(&values) - f(&x)).abs() < 1e-12);
    assert!((out.gradient(&values) - Vector::new(-3.0, 0.5, 0.0)).norm() < 1e-12);

    let fit = mls(2, Order::Quadratic, 1.0)
        .shape_functions(&x, &nodes[..2], &mut out)
        .expect("support");
    assert_eq!(fit.order, Order::Constant);
    assert_finite(&out, "two nodes");
}

/// One node: Shepard's `phi = 1`, zero gradient, at every requested
/// order. No node within `h` (or none at all, or a non-finite point): the
/// documented error, and zeros in the output. The direct gradient has no
/// error case: with no other node in the support it is zero, at the
/// constant order.
#[test]
fn single_and_missing_neighbours() {
    let node = [Vector::new(0.3, 0.2, 0.1)];
    let mut out = ShapeFunctions::new();
    for dim in 1..=3 {
        for order in Order::ALL {
            let mls = mls(dim, order, 1.0);
            let fit = mls
                .shape_functions(&Vector::zeros(), &node, &mut out)
                .expect("support");
            assert_eq!(fit.order, Order::Constant);
            assert!((out.values()[0] - 1.0).abs() < 1e-15, "{:?}", out.values());
            assert_eq!(out.gradients()[0], Vector::zeros());

            // The direct form at the node itself resolves no direction.
            let mut direct = GradientWeights::new();
            let fit = mls.gradient_weights(&node[0], &node, &mut direct);
            assert_eq!((fit.order, fit.support), (Order::Constant, 1));
            assert_eq!(direct.weights(), &[Vector::zeros()]);

            let far = [Vector::new(5.0, 0.0, 0.0)];
            for (nodes, x) in [
                (&far[..], Vector::zeros()),
                (&[][..], Vector::zeros()),
                (&node[..], Vector::repeat(Real::NAN)),
            ] {
                let err = mls
                    .shape_functions(&x, nodes, &mut out)
                    .expect_err("no support");
                assert!(matches!(err, MlsError::NoSupport { .. }), "{err}");
                assert!(err.to_string().contains("support radius h = 1"), "{err}");
                assert_finite(&out, "no support");
                let fit = mls.gradient_weights(&x, nodes, &mut direct);
                assert_eq!((fit.order, fit.support), (Order::Constant, 0));
                assert!(direct.weights().iter().all(|g| *g == Vector::zeros()));
            }
        }
    }
}

/// The point of centring and scaling (Eq. 28-29): the same layout scaled
/// by 1e-3 and by 1e3, with h scaled alike, has the same moment-matrix
/// condition number, to rounding.
#[test]
fn conditioning_does_not_depend_on_scale() {
    let mut seed = 17;
    for dim in 1..=3 {
        let nodes = lattice(dim, 3, 0.3, &mut seed);
        let x = random_point(dim, 0.7, &mut seed);
        for order in Order::ALL {
            let condition = |scale: Real| {
                let scaled: Vec<Vector> = nodes.iter().map(|p| p * scale).collect();
                let mut out = ShapeFunctions::new();
                let fit = mls(dim, order, 2.2 * scale)
                    .shape_functions(&(x * scale), &scaled, &mut out)
                    .expect("support");
                assert_eq!(fit.order, order);
                fit.condition
            };
            let (unit, small, large) = (condition(1.0), condition(1e-3), condition(1e3));
            for c in [small, large] {
                assert!(
                    (c - unit).abs() < 1e-8 * unit,
                    "{dim}D {order:?}: {c} vs {unit} at scale 1"
                );
            }
            assert!(unit < 1e4, "{dim}D {order:?}: condition {unit}");
        }
    }
}

/// The linear direct gradient is Eq. 37-38 exactly: `A_i = sum_j w_ij
/// x_ij x_ij^T` and `grad f = A_i^-1 sum_j w_ij (f_j - f_i) x_ij`,
/// computed here unscaled with nalgebra's 3x3 inverse.
#[test]
fn linear_direct_gradient_is_eq_37() {
    let mut seed = 23;
    let nodes = lattice(3, 2, 0.3, &mut seed);
    let h = 1.8;
    let mls = mls(3, Order::Linear, h);
    let xi = nodes[nodes.len() / 2 + 1];
    let f: Vec<Real> = nodes
        .iter()
        .map(|p| (p.x * 1.3).sin() + p.y * p.z)
        .collect();
    let fi = (xi.x * 1.3).sin() + xi.y * xi.z;
    let mut direct = GradientWeights::new();
    let fit = mls.gradient_weights(&xi, &nodes, &mut direct);
    assert_eq!(fit.order, Order::Linear);
    let mut a = Matrix3::zeros();
    let mut rhs = Vector::zeros();
    for (xj, fj) in nodes.iter().zip(&f) {
        let xij = xj - xi;
        let w = KernelKind::Poly6.profile(xij.norm() / h)[0];
        if xij.norm() < h {
            a += w * xij * xij.transpose();
            rhs += w * (fj - fi) * xij;
        }
    }
    let expected = a.try_inverse().expect("invertible") * rhs;
    let got = direct.gradient(&f, fi);
    assert!(
        (got - expected).norm() < 1e-12 * expected.norm(),
        "{got:?} vs {expected:?}"
    );
}

#[test]
fn invalid_parameters_name_the_field() {
    let field = |dim, params| match Mls::new(dim, params) {
        Err(MlsError::InvalidParameter { field, .. }) => field,
        other => panic!("expected a parameter error, got {other:?}"),
    };
    let ok = MlsParams::new(Order::Linear, 1.0);
    assert_eq!(field(4, ok), "dim");
    assert_eq!(field(0, ok), "dim");
    assert_eq!(field(3, MlsParams { h: 0.0, ..ok }), "h");
    assert_eq!(field(3, MlsParams { h: Real::NAN, ..ok }), "h");
    assert_eq!(
        field(
            3,
            MlsParams {
                rank_tolerance: 0.0,
                ..ok
            }
        ),
        "rank_tolerance"
    );
    assert_eq!(
        field(
            3,
            MlsParams {
                weight: KernelKind::Spiky,
                ..ok
            }
        ),
        "weight"
    );
    assert_eq!(
        field(
            3,
            MlsParams {
                weight: KernelKind::Viscosity,
                ..ok
            }
        ),
        "weight"
    );
}
