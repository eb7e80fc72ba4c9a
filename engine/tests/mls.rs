//! Moving-least-squares validation (Adams–Wicke tutorial, Section 3.2;
//! Müller et al. 2004):
//!
//! - consistency: for every dimension 1-3 and order 0-2, on regular and
//!   jittered samplings, MLS reproduces any polynomial of its order
//!   exactly, in value and in gradient (the derivative of the shape
//!   functions and, for orders >= 1, the direct Eq. 37-38 estimate);
//! - Lagrangian precomputation: the stored weights equal the on-the-fly
//!   ones, and recover the exact displacement gradient of an affine
//!   deformation `u = A x + b` at every particle, boundary included.
//!
//! Run with `--nocapture` for the table of maximum errors.

use meshless_engine::approx::{
    GradientKind, GradientWeights, LagrangianGradients, Mls, MlsParams, Order, ShapeFunctions,
};
use meshless_engine::math::{Real, Vector};
use meshless_engine::neighbors::{CandidateSearch, NeighborList, UniformGrid};
use nalgebra::Matrix3;

/// Deterministic numbers in [0, 1) (SplitMix64).
fn uniform(seed: &mut u64) -> Real {
    *seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *seed;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    (z ^ (z >> 31)) as Real / u64::MAX as Real
}

/// The sampled region is centred here, away from the origin, so that the
/// polynomials' constant, linear and quadratic parts all matter.
fn centre(dim: usize) -> Vector {
    let c = Vector::new(3.7, -2.1, 1.3);
    Vector::from_fn(|a, _| if a < dim { c[a] } else { 0.0 })
}

/// `(2 half + 1)^dim` points with `spacing` around [`centre`], each
/// jittered by up to `jitter` spacings per axis.
fn lattice(dim: usize, half: i32, spacing: Real, jitter: Real, seed: &mut u64) -> Vec<Vector> {
    let range = |a: usize| if a < dim { -half..=half } else { 0..=0 };
    let mut points = Vec::new();
    for i in range(0) {
        for j in range(1) {
            for k in range(2) {
                let mut p = Vector::new(i as Real, j as Real, k as Real);
                for a in 0..dim {
                    p[a] += jitter * (2.0 * uniform(seed) - 1.0);
                }
                points.push(centre(dim) + p * spacing);
            }
        }
    }
    points
}

/// A polynomial of degree `order` in `dim` variables with random
/// coefficients in [-1, 1]: `c + b.x + sum_{a <= b} q_ab x_a x_b`.
struct Polynomial {
    dim: usize,
    constant: Real,
    linear: Vector,
    quadratic: Matrix3<Real>,
}

impl Polynomial {
    fn random(dim: usize, order: Order, seed: &mut u64) -> Self {
        let mut coefficient = || 2.0 * uniform(seed) - 1.0;
        let constant = coefficient();
        let mut linear = Vector::zeros();
        let mut quadratic = Matrix3::zeros();
        if order >= Order::Linear {
            for a in 0..dim {
                linear[a] = coefficient();
            }
        }
        if order >= Order::Quadratic {
            for a in 0..dim {
                for b in a..dim {
                    quadratic[(a, b)] = coefficient();
                }
            }
        }
        Self {
            dim,
            constant,
            linear,
            quadratic,
        }
    }

    fn value(&self, x: &Vector) -> Real {
        self.constant + self.linear.dot(x) + x.dot(&(self.quadratic * x))
    }

    fn gradient(&self, x: &Vector) -> Vector {
        let g = self.linear + (self.quadratic + self.quadratic.transpose()) * x;
        Vector::from_fn(|a, _| if a < self.dim { g[a] } else { 0.0 })
    }
}

/// Maximum relative errors of one case.
#[derive(Default)]
struct Errors {
    value: Real,
    gradient: Real,
    direct: Real,
}

/// Reproduction errors for one dimension, order and layout: 20 random
/// points inside the sampled region for the shape functions, 20 random
/// interior nodes for the direct gradient (which is defined at samples).
/// Errors are relative to the largest |f| and |grad f| over the nodes.
fn reproduction(dim: usize, order: Order, jitter: Real, seed: &mut u64) -> Errors {
    let spacing = 0.1;
    let nodes = lattice(dim, 4, spacing, jitter, seed);
    let mls = Mls::new(dim, MlsParams::new(order, 2.2 * spacing)).expect("valid parameters");
    let mut shape = ShapeFunctions::new();
    let mut direct = GradientWeights::new();
    let mut errors = Errors::default();
    for _ in 0..5 {
        let f = Polynomial::random(dim, order, seed);
        let values: Vec<Real> = nodes.iter().map(|x| f.value(x)).collect();
        let value_scale = values.iter().fold(0.0, |m: Real, v| m.max(v.abs()));
        let gradient_scale = nodes
            .iter()
            .fold(1e-300, |m: Real, x| m.max(f.gradient(x).norm()));
        for _ in 0..20 {
            let mut x = centre(dim);
            for a in 0..dim {
                x[a] += 1.5 * spacing * (2.0 * uniform(seed) - 1.0);
            }
            let fit = mls
                .shape_functions(&x, &nodes, &mut shape)
                .expect("support");
            assert_eq!(fit.order, order, "{dim}D {order:?} at {x:?}: fell back");
            assert!(shape.values().iter().all(|v| v.is_finite()));
            let value_error = (shape.interpolate(&values) - f.value(&x)).abs() / value_scale;
            let gradient_error = (shape.gradient(&values) - f.gradient(&x)).norm();
            // A constant has no gradient scale; its gradient error is absolute.
            let gradient_error = if order == Order::Constant {
                gradient_error
            } else {
                gradient_error / gradient_scale
            };
            errors.value = errors.value.max(value_error);
            errors.gradient = errors.gradient.max(gradient_error);

            if order >= Order::Linear {
                let i = (uniform(seed) * nodes.len() as Real) as usize;
                let xi = nodes[i];
                if (0..dim).any(|a| (xi[a] - centre(dim)[a]).abs() > 2.5 * spacing) {
                    continue;
                }
                let fit = mls.gradient_weights(&xi, &nodes, &mut direct);
                assert_eq!(fit.order, order, "{dim}D {order:?} direct at node {i}");
                let error = (direct.gradient(&values, values[i]) - f.gradient(&xi)).norm();
                errors.direct = errors.direct.max(error / gradient_scale);
            }
        }
    }
    errors
}

/// Section 3.2: MLS with a basis of order n reproduces polynomials of
/// degree n, so values and gradients agree to rounding (1e-10 relative)
/// in every dimension, order and layout.
#[test]
fn mls_reproduces_polynomials_of_its_order() {
    let mut seed = 2024;
    println!("dim order layout    value      gradient   direct (Eq. 37-38)");
    for dim in 1..=3 {
        for order in Order::ALL {
            for (layout, jitter) in [("regular", 0.0), ("jittered", 0.3)] {
                let e = reproduction(dim, order, jitter, &mut seed);
                let direct = if order == Order::Constant {
                    "-".to_string()
                } else {
                    format!("{:.1e}", e.direct)
                };
                println!(
                    "{dim}D  {:<9} {layout:<9} {:.1e}    {:.1e}    {direct}",
                    format!("{order:?}"),
                    e.value,
                    e.gradient
                );
                for (what, error) in [
                    ("value", e.value),
                    ("gradient", e.gradient),
                    ("direct gradient", e.direct),
                ] {
                    assert!(
                        error < 1e-10,
                        "{dim}D {order:?} {layout}: {what} error {error:e}"
                    );
                }
            }
        }
    }
}

/// A jittered 3D block of particles and its neighbour lists.
fn block(seed: &mut u64, spacing: Real, radius: Real) -> (Vec<Vector>, NeighborList) {
    let positions = lattice(3, 4, spacing, 0.25, seed);
    let pad = Vector::repeat(radius);
    let min = centre(3) - Vector::repeat(5.0 * spacing) - pad;
    let max = centre(3) + Vector::repeat(5.0 * spacing) + pad;
    let mut grid = UniformGrid::new(min, max, radius).expect("small grid");
    grid.rebuild(&positions);
    let mut list = NeighborList::default();
    list.build(&grid, &positions, radius);
    (positions, list)
}

/// Precomputed Lagrangian weights (Section 4, material coordinates) are
/// those an on-the-fly fit gives over the same neighbours, and both
/// estimates recover the gradient `A` of `u = A x + b` exactly at every
/// particle, including the block's faces and corners (where the
/// quadratic order may fall back to linear, which still reproduces it).
#[test]
fn lagrangian_gradients_recover_affine_deformations() {
    let mut seed = 99;
    let spacing = 0.05;
    let h = 2.2 * spacing;
    let (positions, list) = block(&mut seed, spacing, h);
    let a = Matrix3::new(0.3, -0.2, 0.05, 0.1, 0.25, -0.4, -0.15, 0.35, 0.2);
    let b = Vector::new(0.7, -1.1, 0.4);
    let displacement: Vec<Vector> = positions.iter().map(|x| a * x + b).collect();
    let mut gradients = vec![Matrix3::zeros(); positions.len()];
    for order in [Order::Linear, Order::Quadratic] {
        let mls = Mls::new(3, MlsParams::new(order, h)).expect("valid parameters");
        for kind in [GradientKind::Direct, GradientKind::ShapeFunctions] {
            let pre =
                LagrangianGradients::build(&mls, kind, &positions, &list).expect("precompute");
            assert_eq!(pre.len(), positions.len());
            let lowered = pre.orders().iter().filter(|&&o| o != order).count();
            let worst = pre.conditions().iter().fold(0.0, |m: Real, &c| m.max(c));
            println!(
                "{order:?} {kind:?}: {lowered} of {} particles fell back, largest condition {worst:.1e}",
                pre.len()
            );
            assert!(pre.orders().iter().all(|&o| o >= Order::Linear));

            let mut shape = ShapeFunctions::new();
            let mut direct = GradientWeights::new();
            for i in 0..positions.len() {
                let (js, stored) = pre.of(i);
                let nodes: Vec<Vector> = js.iter().map(|&j| positions[j as usize]).collect();
                let fresh = match kind {
                    GradientKind::Direct => {
                        mls.gradient_weights(&positions[i], &nodes, &mut direct);
                        direct.weights()
                    }
                    GradientKind::ShapeFunctions => {
                        mls.shape_functions(&positions[i], &nodes, &mut shape)
                            .expect("support");
                        shape.gradients()
                    }
                };
                assert_eq!(stored, fresh, "{order:?} {kind:?}: particle {i}");
            }

            pre.vector_gradients(&displacement, &mut gradients);
            for (i, g) in gradients.iter().enumerate() {
                let error = (g - a).norm() / a.norm();
                assert!(
                    error < 1e-10,
                    "{order:?} {kind:?}: particle {i} gradient error {error:e}\n{g}"
                );
            }
        }
    }
}

/// A block with a detached single-layer plate (all its neighbours on one
/// plane) and an isolated particle: their fits fall back to the constant
/// order, reported per particle, and their gradients stay finite: zero
/// for the direct form (no direction resolved), Shepard's for the shape
/// functions (summing to zero). The block's particles still recover `A`
/// to rounding, which grows with each fit's condition number.
#[test]
fn lagrangian_gradients_fall_back_on_degenerate_particles() {
    let mut seed = 7;
    let spacing = 0.05;
    let h = 2.2 * spacing;
    let mut positions = lattice(3, 3, spacing, 0.2, &mut seed);
    let block = positions.len();
    let plate_origin = centre(3) + Vector::new(0.0, 0.0, 0.4);
    for i in -2..=2 {
        for j in -2..=2 {
            positions.push(plate_origin + Vector::new(i as Real, j as Real, 0.0) * spacing);
        }
    }
    let isolated = positions.len();
    positions.push(centre(3) + Vector::new(0.0, 0.0, -0.4));
    let radius = h;
    let mut grid = UniformGrid::new(
        centre(3) - Vector::repeat(0.5),
        centre(3) + Vector::repeat(0.5),
        radius,
    )
    .expect("small grid");
    grid.rebuild(&positions);
    let mut list = NeighborList::default();
    list.build(&grid, &positions, radius);

    let a = Matrix3::new(0.3, -0.2, 0.05, 0.1, 0.25, -0.4, -0.15, 0.35, 0.2);
    let displacement: Vec<Vector> = positions.iter().map(|x| a * x).collect();
    let mut gradients = vec![Matrix3::zeros(); positions.len()];
    for order in [Order::Linear, Order::Quadratic] {
        let mls = Mls::new(3, MlsParams::new(order, h)).expect("valid parameters");
        for kind in [GradientKind::Direct, GradientKind::ShapeFunctions] {
            let pre =
                LagrangianGradients::build(&mls, kind, &positions, &list).expect("precompute");
            pre.vector_gradients(&displacement, &mut gradients);
            for (i, g) in gradients.iter().enumerate() {
                assert!(
                    g.iter().all(|v| v.is_finite()),
                    "{order:?} {kind:?}: particle {i}: {g}"
                );
                assert!(
                    pre.conditions()[i].is_finite(),
                    "{order:?} {kind:?}: particle {i}"
                );
                if i < block {
                    // Rounding grows with the conditioning: a corner fits
                    // 9 quadratic coefficients to 9 neighbours (condition
                    // ~2e7, error ~1e-9).
                    let condition = pre.conditions()[i];
                    let error = (g - a).norm() / a.norm();
                    assert!(
                        error < 1e-12 + 1e-15 * condition,
                        "{order:?} {kind:?}: particle {i}: error {error:e}, condition {condition:e}"
                    );
                } else {
                    assert_eq!(
                        pre.orders()[i],
                        Order::Constant,
                        "{order:?} {kind:?}: particle {i}"
                    );
                    match kind {
                        GradientKind::Direct => assert_eq!(*g, Matrix3::zeros(), "particle {i}"),
                        // Shepard's gradients: only constants are
                        // reproduced, sum_j grad phi_j = 0.
                        GradientKind::ShapeFunctions => {
                            let sum: Vector = pre.of(i).1.iter().sum();
                            assert!(sum.norm() < 1e-12 / h, "{order:?}: particle {i}: {sum:?}");
                        }
                    }
                }
            }
            assert_eq!(pre.of(isolated).0, &[isolated as u32]);
        }
    }
}
