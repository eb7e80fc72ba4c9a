use super::*;
use nalgebra::Rotation3;

/// A curved, sheared reference point: tangents neither unit nor
/// orthogonal, every second derivative non-zero.
fn reference_local() -> Local {
    [
        Vector::new(1.1, 0.1, 0.2),
        Vector::new(0.3, 0.9, -0.1),
        Vector::new(0.05, -0.02, 0.4),
        Vector::new(-0.03, 0.01, -0.25),
        Vector::new(0.02, 0.06, 0.15),
    ]
}

/// `reference_local` moved by a smooth deformation: stretched, sheared,
/// bent and rotated.
fn deformed_local() -> Local {
    let r = Rotation3::from_euler_angles(0.3, -0.2, 0.5);
    let q = reference_local();
    [
        r * (q[0] * 1.2 + Vector::new(0.0, 0.1, 0.05)),
        r * (q[1] * 0.9 + Vector::new(0.04, 0.0, -0.1)),
        r * (q[2] + Vector::new(0.1, 0.2, -0.3)),
        r * (q[3] + Vector::new(-0.2, 0.1, 0.5)),
        r * (q[4] + Vector::new(0.05, -0.1, 0.2)),
    ]
}

fn perturbed(q: &Local, k: usize, by: Real) -> Local {
    let mut p = *q;
    p[k / 3][k % 3] += by;
    p
}

const YOUNG: Real = 2.0e3;
const POISSON: Real = 0.3;
const THICKNESS: Real = 0.2;

fn reference() -> Reference {
    Reference::new(&reference_local(), YOUNG, POISSON).expect("a surface")
}

/// The gradient is the derivative of the energy (central differences).
#[test]
fn the_gradient_is_the_energys_derivative() {
    let r = reference();
    let q = deformed_local();
    let (mut g, mut h) = ([0.0; LOCAL], [[0.0; LOCAL]; LOCAL]);
    let w = gradient_hessian(&r, THICKNESS, &q, &mut g, &mut h).expect("a surface");
    assert!((w - energy(&r, THICKNESS, &q).expect("a surface")).abs() < 1e-12 * w.abs());
    let step = 1e-6;
    for (k, gk) in g.iter().enumerate() {
        let up = energy(&r, THICKNESS, &perturbed(&q, k, step)).expect("a surface");
        let down = energy(&r, THICKNESS, &perturbed(&q, k, -step)).expect("a surface");
        let fd = (up - down) / (2.0 * step);
        assert!(
            (fd - gk).abs() < 1e-6 * (1.0 + gk.abs()),
            "d W / d q[{k}]: {gk} against {fd}"
        );
    }
}

/// The Hessian is the derivative of the gradient (central differences),
/// bending's curvature of the normal included.
#[test]
fn the_hessian_is_the_gradients_derivative() {
    let r = reference();
    let q = deformed_local();
    let (mut g, mut h) = ([0.0; LOCAL], [[0.0; LOCAL]; LOCAL]);
    gradient_hessian(&r, THICKNESS, &q, &mut g, &mut h).expect("a surface");
    let step = 1e-6;
    let scale = h.iter().flatten().fold(0.0 as Real, |m, v| m.max(v.abs()));
    // Row k of the (symmetric) Hessian against the difference along k.
    for (k, row) in h.iter().enumerate() {
        let (mut up, mut down) = ([0.0; LOCAL], [0.0; LOCAL]);
        let mut scratch = [[0.0; LOCAL]; LOCAL];
        gradient_hessian(
            &r,
            THICKNESS,
            &perturbed(&q, k, step),
            &mut up,
            &mut scratch,
        )
        .expect("a surface");
        gradient_hessian(
            &r,
            THICKNESS,
            &perturbed(&q, k, -step),
            &mut down,
            &mut scratch,
        )
        .expect("a surface");
        for (m, (up, down)) in up.iter().zip(&down).enumerate() {
            let fd = (up - down) / (2.0 * step);
            assert!(
                (fd - row[m]).abs() < 1e-6 * scale,
                "d2 W / d q[{m}] d q[{k}]: {} against {fd}",
                row[m]
            );
        }
    }
}

/// The Hessian is symmetric.
#[test]
fn the_hessian_is_symmetric() {
    let (mut g, mut h) = ([0.0; LOCAL], [[0.0; LOCAL]; LOCAL]);
    gradient_hessian(&reference(), THICKNESS, &deformed_local(), &mut g, &mut h)
        .expect("a surface");
    let scale = h.iter().flatten().fold(0.0 as Real, |m, v| m.max(v.abs()));
    for (i, row) in h.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            assert!((v - h[j][i]).abs() < 1e-12 * scale, "({i}, {j})");
        }
    }
}

/// A rigid rotation and translation of the reference strains nothing:
/// zero energy and zero force, however large the rotation.
#[test]
fn a_rigid_motion_strains_nothing() {
    let r = reference();
    let rotation = Rotation3::from_axis_angle(&Vector::y_axis(), 2.5);
    let q = reference_local().map(|v| rotation * v);
    let (mut g, mut h) = ([0.0; LOCAL], [[0.0; LOCAL]; LOCAL]);
    let w = gradient_hessian(&r, THICKNESS, &q, &mut g, &mut h).expect("a surface");
    assert!(w.abs() < 1e-20, "energy {w}");
    assert!(g.iter().all(|g| g.abs() < 1e-12), "{g:?}");
}

/// On a flat, unit-metric reference `D` is the plane-stress matrix, and a
/// stretch and a bend give the textbook energies.
#[test]
fn a_flat_plate_has_the_plane_stress_energies() {
    let flat: Local = [
        Vector::x(),
        Vector::y(),
        Vector::zeros(),
        Vector::zeros(),
        Vector::zeros(),
    ];
    let r = Reference::new(&flat, YOUNG, POISSON).expect("a surface");
    let c = YOUNG / (1.0 - POISSON * POISSON);
    let expected = Matrix3::new(c, c * POISSON, 0.0, c * POISSON, c, 0.0, 0.0, 0.0, c * 0.35);
    assert!((r.d - expected).norm() < 1e-9 * c, "{}", r.d);
    // Stretched by 1 % along x: eps_11 = ((1.01)^2 - 1) / 2.
    let mut q = flat;
    q[0] *= 1.01;
    let eps: Real = 0.5 * (1.01 * 1.01 - 1.0);
    let w = energy(&r, THICKNESS, &q).expect("a surface");
    assert!((w - 0.5 * THICKNESS * c * eps * eps).abs() < 1e-12 * w);
    // Bent to curvature 0.5 about y: x_,11 = 0.5 n.
    let mut q = flat;
    q[2] = 0.5 * Vector::z();
    let w = energy(&r, THICKNESS, &q).expect("a surface");
    let expected = THICKNESS.powi(3) / 24.0 * c * 0.25;
    assert!(
        (w - expected).abs() < 1e-12 * expected,
        "{w} against {expected}"
    );
    // Twisted: x_,12 = 0.5 n, energy t^3/24 * 4 * D_33 * 0.25.
    let mut q = flat;
    q[4] = 0.5 * Vector::z();
    let w = energy(&r, THICKNESS, &q).expect("a surface");
    let expected = THICKNESS.powi(3) / 24.0 * 4.0 * c * 0.35 * 0.25;
    assert!(
        (w - expected).abs() < 1e-12 * expected,
        "{w} against {expected}"
    );
}

/// Parallel tangents are no surface: refused, not a NaN.
#[test]
fn a_folded_point_is_refused() {
    let mut q = reference_local();
    q[1] = 2.0 * q[0];
    assert!(Reference::new(&q, YOUNG, POISSON).is_none());
    assert!(energy(&reference(), THICKNESS, &q).is_none());
}
