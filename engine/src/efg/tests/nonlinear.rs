//! The full nonlinear EFG dynamics (Guo–Qin Section 5.1, Eq. 18-20;
//! `nonlinear.rs`) against its own definitions (finite differences, rigid
//! motions, the linear stiffness at rest) and against references this code
//! does not share: the linear static deflection at small load, and the
//! Euler elastica of a cantilever bent hard, integrated by shooting here.

use super::super::*;
use super::{BentBeam, beam};
use crate::cancel::Cancel;
use crate::math::{Real, Vector};
use nalgebra::Rotation3;
use std::time::Instant;

/// A free 1 x 0.5 x 0.5 block on octants of 0.25.
fn block() -> EfgSolid {
    let (sdf, _) = beam(1.0, 0.5);
    EfgSolid::build(
        &sdf,
        &FixedSurface::default(),
        Material {
            density: 1000.0,
            young: 1e6,
            poisson: 0.3,
        },
        EfgParams::new(0.25),
        &Cancel::new(),
    )
    .expect("a block")
}

/// A deterministic field of coefficients in `[-scale, scale]` (a seeded
/// linear congruential sequence).
fn scattered(len: usize, scale: Real, seed: u64) -> Vec<Real> {
    let mut state = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
    (0..len)
        .map(|_| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            scale * (2.0 * ((state >> 11) as Real / (1u64 << 53) as Real) - 1.0)
        })
        .collect()
}

fn norm(v: &[Real]) -> Real {
    v.iter().map(|x| x * x).sum::<Real>().sqrt()
}

/// Eq. 18-20 pinned by their derivatives: at a displacement far from
/// linear (strains of some 10 %), the force `dW/du` matches central
/// differences of the energy, and the consistent tangent (material and
/// geometric parts) matches central differences of the force along
/// several directions, to the differences' truncation error.
#[test]
fn force_and_tangent_are_the_derivatives_of_the_energy() {
    let solid = block();
    let n = 3 * solid.nodes().len();
    let mut solver = NonlinearSolver::new(&solid);
    for seed in [1, 2, 3] {
        let u = scattered(n, 0.02, seed);
        let mut g = vec![0.0; n];
        solver.strain_gradient(&solid, &u, &mut g);
        let eps = 1e-6;
        let g_scale = g.iter().fold(0.0, |m: Real, x| m.max(x.abs()));
        for k in (0..n).step_by(7) {
            let mut up = u.clone();
            up[k] += eps;
            let mut down = u.clone();
            down[k] -= eps;
            let fd = (solver.strain_energy(&solid, &up) - solver.strain_energy(&solid, &down))
                / (2.0 * eps);
            assert!(
                (fd - g[k]).abs() <= 1e-6 * g_scale,
                "seed {seed}, dof {k}: force {} against difference {fd}",
                g[k]
            );
        }
        let tangent = solver.strain_tangent(&solid, &u);
        for d_seed in [10, 11] {
            let d = scattered(n, 1.0, seed * 100 + d_seed);
            let kd = solid.pattern().product(&tangent, &d);
            let (mut gp, mut gm) = (vec![0.0; n], vec![0.0; n]);
            let up: Vec<Real> = u.iter().zip(&d).map(|(u, d)| u + eps * d).collect();
            let um: Vec<Real> = u.iter().zip(&d).map(|(u, d)| u - eps * d).collect();
            solver.strain_gradient(&solid, &up, &mut gp);
            solver.strain_gradient(&solid, &um, &mut gm);
            let fd: Vec<Real> = gp
                .iter()
                .zip(&gm)
                .map(|(p, m)| (p - m) / (2.0 * eps))
                .collect();
            let error: Vec<Real> = fd.iter().zip(&kd).map(|(a, b)| a - b).collect();
            assert!(
                norm(&error) <= 1e-6 * norm(&kd),
                "seed {seed}: |K d - difference| = {:e} of {:e}",
                norm(&error),
                norm(&kd)
            );
        }
    }
}

/// Green's strain is blind to rotation: the nodal coefficients of a
/// rigid rotation by 60 degrees (which the linear MLS basis reproduces
/// exactly, so `F = R` at every Gauss point) store no energy and load no
/// node; a linear strain measure would store `(R - I)`'s.
#[test]
fn a_rigid_rotation_stores_no_energy_and_loads_no_node() {
    let solid = block();
    let rotation = Rotation3::from_axis_angle(
        &nalgebra::Unit::new_normalize(Vector::new(1.0, 2.0, -0.5)),
        60f64.to_radians(),
    );
    let u: Vec<Real> = solid
        .nodes()
        .iter()
        .flat_map(|node| {
            let d = rotation * node.position - node.position;
            [d[0], d[1], d[2]]
        })
        .collect();
    let mut solver = NonlinearSolver::new(&solid);
    let energy = solver.strain_energy(&solid, &u);
    let (_, mu) = lame(solid.material().young, solid.material().poisson);
    // A 1 % stretch of the same block stores mu * 1e-4 * volume.
    let reference = mu * 1e-4 * solid.volume();
    assert!(
        energy.abs() < 1e-18 * reference.max(1.0) + 1e-12 * reference,
        "{energy:e}"
    );
    let mut g = vec![0.0; u.len()];
    solver.strain_gradient(&solid, &u, &mut g);
    // A node's force at a 1 % strain: mu * 0.01 * the face of a support.
    let cell = solid.params().cell;
    let force = mu * 0.01 * cell * cell;
    let largest = g.iter().fold(0.0, |m: Real, x| m.max(x.abs()));
    assert!(largest < 1e-9 * force, "{largest:e} against {force:e}");
}

/// At small strain the consistent tangent is the linear stiffness of
/// `assemble.rs` (`B^T D B`), entry by entry: the geometric part and the
/// quadratic terms of Green's strain vanish at rest.
#[test]
fn the_tangent_at_rest_is_the_linear_stiffness() {
    let solid = block();
    let n = 3 * solid.nodes().len();
    let mut solver = NonlinearSolver::new(&solid);
    let tangent = solver.strain_tangent(&solid, &vec![0.0; n]);
    let linear = solid.stiffness();
    assert_eq!(tangent.len(), linear.len());
    let scale = linear.iter().fold(0.0, |m: Real, x| m.max(x.abs()));
    for (i, (a, b)) in tangent.iter().zip(linear).enumerate() {
        assert!((a - b).abs() <= 1e-12 * scale, "entry {i}: {a} against {b}");
    }
    // And nearly so at a strain of 1e-7.
    let u = scattered(n, 1e-8, 7);
    let near = solver.strain_tangent(&solid, &u);
    let worst = near
        .iter()
        .zip(linear)
        .fold(0.0, |m: Real, (a, b)| m.max((a - b).abs()));
    assert!(worst <= 1e-5 * scale, "{worst:e} of {scale:e}");
}

/// Tip of the centreline `(l, h/2, h/2)` from flat coefficients.
fn tip_of(solid: &EfgSolid, u: &[Real], tip: Vector) -> Vector {
    let table = solid.shape_table(&[tip]).expect("covered");
    let nodal: Vec<Vector> = u.chunks(3).map(|c| Vector::new(c[0], c[1], c[2])).collect();
    let mut at = Vec::new();
    table.interpolate(&nodal, &mut at);
    tip + at[0]
}

/// Small loads: the 1 x 0.1 x 0.1 m steel-stiff cantilever (E = 2e11 Pa)
/// under its own weight deflects the tip by 5e-5 of its length, where
/// Green's strain is linear to about 1e-4; the nonlinear static solve (the same
/// energy minimised by Newton, no inertia) meets the linear EFG static
/// deflection `K u = f` (which the tests of `tests.rs` hold to
/// Timoshenko) to 1 %, and damped backward-Euler steps settle there too.
#[test]
fn at_small_load_the_nonlinear_tip_is_the_linear_one() {
    let (l, h) = (1.0, 0.1);
    let (sdf, fixed) = beam(l, h);
    let material = Material {
        density: 7800.0,
        young: 2e11,
        poisson: 0.3,
    };
    let solid = EfgSolid::build(&sdf, &fixed, material, EfgParams::new(0.05), &Cancel::new())
        .expect("a cantilever");
    let load = solid.body_load(&Vector::new(0.0, 0.0, -9.81));
    let linear = solid.static_displacement(&load).expect("held");
    let tip = Vector::new(l, 0.5 * h, 0.5 * h);
    let linear_tip = tip_of(&solid, &linear, tip) - tip;
    let mut solver = NonlinearSolver::new(&solid);
    let mut state = NonlinearState::rest(solid.nodes().len());
    let info = solver
        .solve_static(
            &solid,
            &mut state,
            &load,
            NewtonParams::default().max_iterations,
        )
        .expect("a static solve");
    let static_tip = tip_of(&solid, &state.displacements, tip) - tip;
    // Heavily damped steps from rest (a = 2000 / s, about five times the
    // first mode's frequency: critically damped), 40 of 5 ms.
    let mut settled = NonlinearState::rest(solid.nodes().len());
    let params = NewtonParams {
        damping: (2000.0, 0.0),
        ..NewtonParams::default()
    };
    for _ in 0..40 {
        solver
            .step(
                &solid,
                &mut settled,
                StepInput {
                    h: Some(5e-3),
                    load: &load,
                    springs: &[],
                },
                &params,
                &Cancel::new(),
            )
            .expect("a step");
    }
    let settled_tip = tip_of(&solid, &settled.displacements, tip) - tip;
    println!(
        "small load: linear tip {:.4e}, nonlinear static {:.4e} ({} iterations, residual {:.1e}), \
         settled {:.4e}",
        linear_tip.z, static_tip.z, info.iterations, info.residual, settled_tip.z
    );
    assert!(info.converged, "{info:?}");
    assert!(
        (static_tip.z / linear_tip.z - 1.0).abs() < 0.01,
        "{static_tip:?} against {linear_tip:?}"
    );
    assert!(
        (settled_tip.z / linear_tip.z - 1.0).abs() < 0.01,
        "{settled_tip:?} against {linear_tip:?}"
    );
}

/// The Euler elastica of a cantilever of length 1 under a dead uniform
/// load, `theta'' = -k (1 - s) cos(theta)` with `k = q L^3 / (E I)`,
/// `theta(0) = 0` (clamped) and `theta'(1) = 0` (free end), solved by
/// shooting on `theta'(0)` (bisection, RK4 on 4,000 steps). Returns the
/// tip `(x, z)` over `L` (z downwards negative) and the tip rotation.
fn elastica(k: Real) -> (Real, Real, Real) {
    let steps = 4000;
    let ds = 1.0 / steps as Real;
    let run = |slope: Real| -> (Real, Real, Real, Real) {
        let (mut theta, mut omega, mut x, mut z) = (0.0 as Real, slope, 0.0, 0.0);
        let f = |s: Real, theta: Real| -k * (1.0 - s) * theta.cos();
        for i in 0..steps {
            let s = i as Real * ds;
            // RK4 on (theta, omega, x, z).
            let k1 = (omega, f(s, theta), theta.cos(), -theta.sin());
            let t2 = theta + 0.5 * ds * k1.0;
            let o2 = omega + 0.5 * ds * k1.1;
            let k2 = (o2, f(s + 0.5 * ds, t2), t2.cos(), -t2.sin());
            let t3 = theta + 0.5 * ds * k2.0;
            let o3 = omega + 0.5 * ds * k2.1;
            let k3 = (o3, f(s + 0.5 * ds, t3), t3.cos(), -t3.sin());
            let t4 = theta + ds * k3.0;
            let o4 = omega + ds * k3.1;
            let k4 = (o4, f(s + ds, t4), t4.cos(), -t4.sin());
            theta += ds / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
            omega += ds / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
            x += ds / 6.0 * (k1.2 + 2.0 * k2.2 + 2.0 * k3.2 + k4.2);
            z += ds / 6.0 * (k1.3 + 2.0 * k2.3 + 2.0 * k3.3 + k4.3);
        }
        (theta, omega, x, z)
    };
    // theta'(1) grows with theta'(0) on [0, k / 2] (the linear answer is
    // k / 2, a bent beam's is smaller).
    let (mut lo, mut hi) = (0.0, 0.5 * k);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if run(mid).1 > 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let (theta, _, x, z) = run(0.5 * (lo + hi));
    (x, z, theta)
}

/// One solution of the bent beam.
struct Bent {
    tip: Vector,
    rotation: Real,
    stretch: Real,
}

fn bent(beam: &BentBeam, deformed: &[Vector]) -> Bent {
    let last = deformed.len() - 1;
    let end = deformed[last] - deformed[last - 1];
    Bent {
        tip: deformed[last],
        rotation: (-end.z).atan2(end.x).to_degrees(),
        stretch: beam.stretch(deformed),
    }
}

/// The cantilever of `modal_warping_shortens_a_beam_bent_hard` (10 x 1 x
/// 1 m, E = 5e7 Pa, 189 nodes) bent by its weight times 1 to 16, three
/// ways: modal warping (24 modes, settled), the full nonlinear EFG
/// (static Newton, each load started from the last), and the Euler
/// elastica, an inextensible rod integrated here by shooting. The rod
/// takes the EFG's own bending stiffness, `E I` measured from the linear
/// EFG's tip under the smallest load (`q L^4 / 8 delta`; it folds in the
/// coarse octree's stiffness and the shear deflection, 13 % above beam
/// theory's `E h^4 / 12`), so the comparison is of the geometric
/// nonlinearity alone. Nonlinear EFG keeps the centreline's length to
/// under 1 % where warping loses 4 % and 7 %, and its tip meets the
/// elastica's to a few per cent of the length.
#[test]
fn the_nonlinear_efg_cantilever_bent_hard_follows_the_elastica_and_keeps_its_length() {
    let beam = BentBeam::new();
    let solid = &beam.solid;
    let (l, h) = (beam.length, 1.0);
    let g = 9.81;
    let q = solid.material().density * g * h * h;
    let weight = solid.body_load(&Vector::new(0.0, 0.0, -g));
    let root = Vector::new(0.0, 0.5 * h, 0.5 * h);
    let linear = solid.static_displacement(&weight).expect("held");
    let linear_tip = tip_of(solid, &linear, Vector::new(l, 0.5 * h, 0.5 * h));
    let ei = q * l.powi(4) / (8.0 * (0.5 * h - linear_tip.z));
    println!(
        "E I: {ei:.4e} from the linear EFG, {:.4e} by beam theory",
        solid.material().young * h.powi(4) / 12.0
    );
    let mut solver = NonlinearSolver::new(solid);
    let mut state = NonlinearState::rest(solid.nodes().len());
    let nodal = |u: &[Real]| -> Vec<Vector> {
        u.chunks(3).map(|c| Vector::new(c[0], c[1], c[2])).collect()
    };
    println!(
        "load | tip rotation [deg]: warping / nonlinear / elastica | tip z/L: warping / nonlinear \
         / elastica | tip x/L: warping / nonlinear / elastica | length: warping / nonlinear | \
         Newton iterations, time"
    );
    let mut rows = Vec::new();
    for load in [1.0, 2.0, 4.0, 8.0, 16.0] {
        let warped = bent(&beam, &beam.settle(load, true));
        let f: Vec<Real> = weight.iter().map(|f| f * load).collect();
        let clock = Instant::now();
        let info = solver
            .solve_static(solid, &mut state, &f, 60)
            .expect("a static solve");
        let time = clock.elapsed();
        let mut d = Vec::new();
        beam.table.interpolate(&nodal(&state.displacements), &mut d);
        let deformed: Vec<Vector> = beam.centreline.iter().zip(&d).map(|(x, d)| x + d).collect();
        let exact = bent(&beam, &deformed);
        let (ex, ez, etheta) = elastica(load * q * l.powi(3) / ei);
        println!(
            "{load:4} | {:5.1} / {:5.1} / {:5.1} | {:+.4} / {:+.4} / {:+.4} | {:.4} / {:.4} / \
             {:.4} | {:+.2} % / {:+.3} % | {}, {:.2} s",
            warped.rotation,
            exact.rotation,
            etheta.to_degrees(),
            (warped.tip.z - root.z) / l,
            (exact.tip.z - root.z) / l,
            ez,
            warped.tip.x / l,
            exact.tip.x / l,
            ex,
            100.0 * warped.stretch,
            100.0 * exact.stretch,
            info.iterations,
            time.as_secs_f64()
        );
        assert!(info.converged, "load {load}: {info:?}");
        rows.push((load, warped, exact, (ex, ez, etheta.to_degrees())));
    }
    for (load, warped, exact, (ex, ez, etheta)) in &rows {
        // The full solution keeps the centreline's length where warping
        // loses it.
        assert!(
            exact.stretch.abs() < 0.01,
            "load {load}: {:+e}",
            exact.stretch
        );
        // Its tip meets the elastica's to 1.5 % of the length (measured: 0.5 %).
        let dz = (exact.tip.z - root.z) / l - ez;
        let dx = exact.tip.x / l - ex;
        assert!(
            dz.abs() < 0.015 && dx.abs() < 0.015,
            "load {load}: tip off the elastica's by ({dx:+.4}, {dz:+.4}) L"
        );
        assert!(
            (exact.rotation - etheta).abs() < 0.05 * etheta.max(10.0),
            "load {load}: rotation {} against {etheta}",
            exact.rotation
        );
        if *etheta > 45.0 {
            assert!(warped.stretch < -0.03, "load {load}: {:+e}", warped.stretch);
        }
    }
    assert!(rows.last().is_some_and(|r| r.3.2 > 70.0), "bent hard");
}

/// Where the tangent is not positive definite the step does not fail:
/// a free block (its stiffness singular: six rigid motions) squeezed to
/// 55 % in every direction, past the stretch `1/sqrt(3)` where St
/// Venant–Kirchhoff stops resisting compression (its tangent indefinite),
/// and let go statically. The factorisation fails, `sigma M` is added
/// until it succeeds, and the line search walks the block back to a
/// stress-free shape.
#[test]
fn an_indefinite_tangent_is_shifted_by_the_mass_and_the_solve_recovers() {
    let solid = block();
    let u: Vec<Real> = solid
        .nodes()
        .iter()
        .flat_map(|n| {
            let d = n.position * -0.45;
            [d[0], d[1], d[2]]
        })
        .collect();
    let mut solver = NonlinearSolver::new(&solid);
    let start = solver.strain_energy(&solid, &u);
    let mut state = NonlinearState {
        displacements: u,
        velocities: vec![0.0; 3 * solid.nodes().len()],
    };
    let load = vec![0.0; state.velocities.len()];
    let info = solver
        .solve_static(&solid, &mut state, &load, 100)
        .expect("a shifted solve");
    let end = solver.strain_energy(&solid, &state.displacements);
    println!("squeezed block: energy {start:.3e} -> {end:.3e}, {info:?}");
    assert!(info.shifts > 0, "the tangent needed a shift: {info:?}");
    assert!(end < 1e-8 * start, "{end:e} of {start:e}");
}

/// Bad input is an error naming it, never a panic, and a raised cancel
/// flag stops the solve; the state is unchanged either way.
#[test]
fn bad_steps_and_cancellation_leave_the_state_alone() {
    let solid = block();
    let n = 3 * solid.nodes().len();
    let mut solver = NonlinearSolver::new(&solid);
    let mut state = NonlinearState::rest(solid.nodes().len());
    let before = state.clone();
    let load = vec![1.0; n];
    let params = NewtonParams::default();
    let step = |solver: &mut NonlinearSolver,
                state: &mut NonlinearState,
                h: Option<Real>,
                load: &[Real],
                cancel: &Cancel| {
        solver.step(
            &solid,
            state,
            StepInput {
                h,
                load,
                springs: &[],
            },
            &params,
            cancel,
        )
    };
    let cancel = Cancel::new();
    assert!(matches!(
        step(&mut solver, &mut state, Some(-1.0), &load, &cancel),
        Err(NonlinearError::BadStep(_))
    ));
    assert!(matches!(
        step(&mut solver, &mut state, Some(0.01), &load[1..], &cancel),
        Err(NonlinearError::BadVector { what: "load", .. })
    ));
    let mut nan = load.clone();
    nan[4] = Real::NAN;
    assert!(matches!(
        step(&mut solver, &mut state, Some(0.01), &nan, &cancel),
        Err(NonlinearError::BadVector { what: "load", .. })
    ));
    cancel.cancel();
    assert!(matches!(
        step(&mut solver, &mut state, Some(0.01), &load, &cancel),
        Err(NonlinearError::Cancelled)
    ));
    assert_eq!(state, before);
}
