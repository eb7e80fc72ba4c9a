//! A shell in motion: free vibration and implicit time stepping, on a
//! simply supported square plate whose frequencies have a closed form
//! (Navier's, tabulated by Leissa, *Vibration of Plates*, NASA SP-160,
//! 1969): `omega_mn = pi^2 (m^2 + n^2) / a^2 sqrt(D / (rho t))`.

mod shell_charts;

use meshless_engine::cancel::Cancel;
use meshless_engine::math::{Real, Vector};
use meshless_engine::shell::{
    DynamicParams, Grab, Integrator, Load, Material, Mechanics, ShellDynamics, ShellError,
    ShellModel, ShellParams, StaticParams, Support, SupportKind,
};
use shell_charts::UnitSquare as Square;
use std::f64::consts::PI;

const PLATE: Material = Material {
    thickness: 0.01,
    density: 1.0,
    young: 1.0e6,
    poisson: 0.3,
};

fn plate(cells: Real, material: Material) -> ShellModel {
    ShellModel::new(
        &Square,
        [0.0, 0.0],
        [1.0, 1.0],
        material,
        &ShellParams::new(1.0 / cells),
        &Cancel::new(),
    )
    .expect("the plate discretises")
}

/// Every edge held in all three directions (a simply supported plate
/// whose edges cannot slide).
fn simply_supported(model: &ShellModel, cells: Real) -> Vec<Support> {
    let kinds = [
        SupportKind::Displacement(Vector::x()),
        SupportKind::Displacement(Vector::y()),
        SupportKind::Displacement(Vector::z()),
    ];
    let corners = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    (0..4)
        .flat_map(|k| {
            model
                .edge_supports(corners[k], corners[(k + 1) % 4], cells as usize, &kinds)
                .expect("on the chart")
        })
        .collect()
}

/// Navier's `omega_11` of the plate.
fn omega_11(material: &Material) -> Real {
    2.0 * PI * PI * (material.bending_stiffness() / (material.density * material.thickness)).sqrt()
}

/// The four lowest frequencies are Navier's (1,1), (1,2), (2,1) and (2,2)
/// within 2 % at 32 cells a side (1.0018, 1.0123, 1.0123, 1.0085 of them).
#[test]
fn a_simply_supported_plate_vibrates_at_navier_frequencies() {
    let cells = 32.0;
    let model = plate(cells, PLATE);
    let supports = simply_supported(&model, cells);
    let modes = model
        .vibration_modes(&supports, 4, 10.0, &Cancel::new())
        .expect("modes");
    let base = omega_11(&PLATE) / 2.0;
    let expected = [2.0, 5.0, 5.0, 8.0].map(|k| k * base);
    let ratios: Vec<Real> = modes
        .frequencies
        .iter()
        .zip(expected)
        .map(|(w, e)| w / e)
        .collect();
    eprintln!("lowest frequencies over Navier's: {ratios:.4?}");
    assert!(ratios.iter().all(|r| (r - 1.0).abs() < 0.02), "{ratios:?}");
}

/// The centre deflection of a plate's dynamics, sampled each step.
fn centre_history(dynamics: &mut ShellDynamics, steps: usize) -> Vec<(Real, Real)> {
    let cancel = Cancel::new();
    let mut out = Vec::with_capacity(steps);
    for _ in 0..steps {
        dynamics.step(&cancel).expect("a step");
        let w = dynamics
            .model()
            .displacement_at([0.5, 0.5], dynamics.displacement())
            .expect("the centre")[2];
        out.push((dynamics.time(), w));
    }
    out
}

/// The plate released from its deflection under a small pressure.
fn released(cells: Real, integrator: Integrator, dt: Real, mechanics: Mechanics) -> ShellDynamics {
    let model = plate(cells, PLATE);
    let supports = simply_supported(&model, cells);
    // A deflection of about a tenth of the thickness: nearly linear.
    let load = Load {
        pressure: 0.1 * PLATE.thickness * PLATE.bending_stiffness() / 0.00406,
        ..Load::default()
    };
    let statics = model
        .solve_static(&load, &supports, &StaticParams::default(), &Cancel::new())
        .expect("the plate is supported");
    let params = DynamicParams {
        integrator,
        mechanics,
        ..DynamicParams::new(dt)
    };
    let mut dynamics =
        ShellDynamics::new(model, &supports, &Load::default(), params).expect("dynamics");
    let n = statics.displacement.len();
    dynamics
        .set_state(statics.displacement, vec![Vector::zeros(); n])
        .expect("a state");
    dynamics
}

/// Released from a static deflection, the plate swings at Navier's
/// period (Newmark, 40 steps a period: within 2 %) and, Newmark being
/// energy-conserving, keeps its energy to 1 %; backward Euler damps it,
/// every step.
#[test]
fn a_released_plate_swings_at_its_period() {
    let period = 2.0 * PI / omega_11(&PLATE);
    let mut newmark = released(
        8.0,
        Integrator::Newmark,
        period / 40.0,
        Mechanics::Nonlinear,
    );
    let start = newmark.energy().expect("energy");
    let history = centre_history(&mut newmark, 100);
    // Downward zero crossings, interpolated.
    let crossings: Vec<Real> = history
        .windows(2)
        .filter(|w| w[0].1 > 0.0 && w[1].1 <= 0.0)
        .map(|w| w[0].0 + (w[1].0 - w[0].0) * w[0].1 / (w[0].1 - w[1].1))
        .collect();
    assert!(crossings.len() >= 2, "{crossings:?}");
    let measured = crossings[1] - crossings[0];
    eprintln!("period over Navier's: {:.4}", measured / period);
    assert!(
        (measured / period - 1.0).abs() < 0.02,
        "{measured} against {period}"
    );
    let end = newmark.energy().expect("energy");
    let (e0, e1) = (start.kinetic + start.strain, end.kinetic + end.strain);
    eprintln!(
        "Newmark energy after 2.5 periods: {:.5} of the start",
        e1 / e0
    );
    assert!((e1 / e0 - 1.0).abs() < 0.01, "{e0} -> {e1}");

    let mut euler = released(
        8.0,
        Integrator::BackwardEuler,
        period / 40.0,
        Mechanics::Nonlinear,
    );
    let mut last = euler.energy().expect("energy");
    let first = last.kinetic + last.strain;
    for _ in 0..40 {
        euler.step(&Cancel::new()).expect("a step");
        let e = euler.energy().expect("energy");
        assert!(
            e.kinetic + e.strain < last.kinetic + last.strain,
            "damped every step"
        );
        last = e;
    }
    eprintln!(
        "backward Euler energy after a period: {:.4} of the start",
        (last.kinetic + last.strain) / first
    );
}

/// Linear mechanics (Guo–Qin's Eq. 24: `M` and `K` constant), released
/// from a small deflection (a tenth of the thickness), swings at Navier's
/// period, which is linear theory's (within 2 %, as the nonlinear route),
/// and its Newmark steps keep the energy of a linear system to round-off.
/// The nonlinear route drifts ahead of it: its edges cannot slide, so the
/// membrane stiffens the swing by the square of the deflection.
#[test]
fn linear_mechanics_swings_at_navier_period_and_keeps_its_energy() {
    let period = 2.0 * PI / omega_11(&PLATE);
    let mut runs = [Mechanics::Nonlinear, Mechanics::Linear]
        .map(|m| released(8.0, Integrator::Newmark, period / 40.0, m));
    let start = runs[1].energy().expect("energy");
    let [nonlinear, linear] = &mut runs;
    let (a, b) = (centre_history(nonlinear, 100), centre_history(linear, 100));
    let measured = |history: &[(Real, Real)]| {
        let crossings: Vec<Real> = history
            .windows(2)
            .filter(|w| w[0].1 > 0.0 && w[1].1 <= 0.0)
            .map(|w| w[0].0 + (w[1].0 - w[0].0) * w[0].1 / (w[0].1 - w[1].1))
            .collect();
        crossings[1] - crossings[0]
    };
    let (p_nonlinear, p_linear) = (measured(&a) / period, measured(&b) / period);
    let end = linear.energy().expect("energy");
    let (e0, e1) = (start.kinetic + start.strain, end.kinetic + end.strain);
    eprintln!(
        "periods over Navier's: linear {p_linear:.4}, nonlinear {p_nonlinear:.4}; linear \
         energy {:.3e} off",
        e1 / e0 - 1.0
    );
    assert!((p_linear - 1.0).abs() < 0.02, "{p_linear}");
    assert!(
        p_linear > p_nonlinear,
        "the membrane stiffens the nonlinear swing"
    );
    assert!((e1 / e0 - 1.0).abs() < 1e-9, "{e0} -> {e1}");
}

/// A step a hundred periods long: backward Euler lands on the static
/// deflection (within 0.1 %), Newmark stays bounded; a step a millionth
/// of a period moves the plate by next to nothing, and converges.
#[test]
fn huge_and_tiny_steps_are_stable() {
    let cells = 8.0;
    let period = 2.0 * PI / omega_11(&PLATE);
    let load = Load {
        pressure: PLATE.thickness * PLATE.bending_stiffness() / 0.00406,
        ..Load::default()
    };
    let model = plate(cells, PLATE);
    let supports = simply_supported(&model, cells);
    let statics = model
        .solve_static(&load, &supports, &StaticParams::default(), &Cancel::new())
        .expect("the plate is supported");
    let centre =
        |m: &ShellModel, u: &[Vector]| m.displacement_at([0.5, 0.5], u).expect("centre")[2];
    let expected = centre(&model, &statics.displacement);
    for (integrator, dt, steps) in [
        (Integrator::BackwardEuler, 100.0 * period, 3),
        (Integrator::Newmark, 100.0 * period, 10),
        (Integrator::BackwardEuler, 1e-6 * period, 3),
    ] {
        let params = DynamicParams {
            integrator,
            ..DynamicParams::new(dt)
        };
        let mut dynamics =
            ShellDynamics::new(plate(cells, PLATE), &supports, &load, params).expect("dynamics");
        for _ in 0..steps {
            dynamics.step(&Cancel::new()).expect("a step");
        }
        let w = centre(dynamics.model(), dynamics.displacement());
        eprintln!(
            "{integrator:?}, dt = {:.0e} periods: centre {:.4} of static",
            dt / period,
            w / expected
        );
        match (integrator, dt > period) {
            (Integrator::BackwardEuler, true) => {
                assert!((w / expected - 1.0).abs() < 1e-3, "{w} against {expected}")
            }
            (Integrator::Newmark, _) => assert!(w.abs() <= 2.0 * expected.abs() * 1.01, "{w}"),
            _ => assert!(w.abs() < 1e-6 * expected.abs(), "{w}"),
        }
    }
}

/// A free shell moving at a uniform velocity moves rigidly: no strain,
/// the displacement the velocity times the time, the momentum kept.
#[test]
fn a_free_shell_translates_rigidly() {
    let model = plate(4.0, PLATE);
    let n = model.node_count();
    let velocity = Vector::new(1.0, -2.0, 0.5);
    let mut dynamics = ShellDynamics::new(model, &[], &Load::default(), DynamicParams::new(0.01))
        .expect("dynamics");
    dynamics
        .set_state(vec![Vector::zeros(); n], vec![velocity; n])
        .expect("a state");
    for _ in 0..5 {
        dynamics.step(&Cancel::new()).expect("a step");
    }
    let t = dynamics.time();
    for (u, v) in dynamics.displacement().iter().zip(dynamics.velocity()) {
        assert!((u - velocity * t).norm() < 1e-12, "{u}");
        assert!((v - velocity).norm() < 1e-12, "{v}");
    }
    assert!(dynamics.energy().expect("energy").strain.abs() < 1e-20);
}

/// Inputs out of range are refused with what to change.
#[test]
fn bad_shell_inputs_are_refused() {
    let incompressible = Material {
        poisson: 0.5,
        ..PLATE
    };
    let refused = ShellModel::new(
        &Square,
        [0.0, 0.0],
        [1.0, 1.0],
        incompressible,
        &ShellParams::new(0.25),
        &Cancel::new(),
    );
    assert!(
        matches!(
            refused,
            Err(ShellError::Parameter {
                what: "poisson",
                ..
            })
        ),
        "{refused:?}"
    );
    let model = plate(4.0, PLATE);
    for dt in [0.0, -1.0, Real::NAN] {
        let e = ShellDynamics::new(model.clone(), &[], &Load::default(), DynamicParams::new(dt))
            .expect_err("a bad step");
        assert!(e.to_string().contains("dt"), "{e}");
    }
    let massless = plate(
        4.0,
        Material {
            density: 0.0,
            ..PLATE
        },
    );
    assert!(ShellDynamics::new(massless, &[], &Load::default(), DynamicParams::new(0.01)).is_err());
    // A free plate has rigid motions: the static route says so.
    let e = model
        .solve_static(
            &Load {
                pressure: 1.0,
                ..Load::default()
            },
            &[],
            &StaticParams::default(),
            &Cancel::new(),
        )
        .expect_err("nothing holds it");
    assert_eq!(e, ShellError::Singular);
}

/// A grab pulls the centre of a simply supported plate to its target
/// (its spring a thousand times the plate's stiffness there: within 1 %),
/// follows the target as it is dragged, and lets go: the plate returns
/// to rest. A bad grab is refused and the grabs stay as they were.
#[test]
fn a_grab_pulls_drags_and_lets_go() {
    for mechanics in [Mechanics::Nonlinear, Mechanics::Linear] {
        grab_pulls_drags_and_lets_go(mechanics);
    }
}

/// The simply supported plate at 8 cells along, unloaded, stepped by
/// `mechanics` with backward-Euler steps of `dt`.
fn unloaded_plate(mechanics: Mechanics, dt: Real) -> ShellDynamics {
    let cells = 8.0;
    let model = plate(cells, PLATE);
    let supports = simply_supported(&model, cells);
    ShellDynamics::new(
        model,
        &supports,
        &Load::default(),
        DynamicParams {
            mechanics,
            ..DynamicParams::new(dt)
        },
    )
    .expect("dynamics")
}

fn grab_pulls_drags_and_lets_go(mechanics: Mechanics) {
    let period = 2.0 * PI / omega_11(&PLATE);
    // Huge steps of backward Euler: each lands on the equilibrium.
    let mut dynamics = unloaded_plate(mechanics, 100.0 * period);
    let centre = |d: &ShellDynamics| {
        d.model()
            .displacement_at([0.5, 0.5], d.displacement())
            .expect("the centre")[2]
    };
    let settle = |d: &mut ShellDynamics| {
        for _ in 0..3 {
            d.step(&Cancel::new()).expect("a step");
        }
    };
    // The plate's own stiffness under a centre load, P / w = D / (0.0116 a^2).
    let stiffness = 1e3 * PLATE.bending_stiffness() / 0.0116;
    let lift = 0.1 * PLATE.thickness;
    dynamics
        .set_grabs(&[Grab {
            at: [0.5, 0.5],
            target: Some(Vector::new(0.5, 0.5, lift)),
            rotation: None,
            stiffness,
        }])
        .expect("a grab");
    settle(&mut dynamics);
    let w = centre(&dynamics);
    eprintln!("grabbed centre at {:.5} of the target", w / lift);
    assert!((w / lift - 1.0).abs() < 0.01, "{w} against {lift}");

    dynamics
        .move_grab(0, Some(Vector::new(0.5, 0.5, -lift)), None)
        .expect("a grab to drag");
    settle(&mut dynamics);
    assert!((centre(&dynamics) / -lift - 1.0).abs() < 0.01);

    for bad in [
        Grab {
            at: [0.5, 0.5],
            target: Some(Vector::zeros()),
            rotation: None,
            stiffness: -1.0,
        },
        Grab {
            at: [0.5, 0.5],
            target: Some(Vector::new(Real::NAN, 0.0, 0.0)),
            rotation: None,
            stiffness,
        },
        Grab {
            at: [7.0, 0.5],
            target: Some(Vector::zeros()),
            rotation: None,
            stiffness,
        },
    ] {
        let e = dynamics.set_grabs(&[bad]).expect_err("a bad grab");
        eprintln!("refused: {e}");
    }
    assert!(dynamics.move_grab(3, Some(Vector::zeros()), None).is_err());
    // The drag still holds: the refusals changed nothing.
    settle(&mut dynamics);
    assert!((centre(&dynamics) / -lift - 1.0).abs() < 0.01);

    dynamics.set_grabs(&[]).expect("let go");
    settle(&mut dynamics);
    let w = centre(&dynamics);
    assert!(w.abs() < 1e-6 * lift, "released, the plate rests: {w}");
}

/// The linear route keeps the grabs' springs out of its matrices and
/// adds them by the Woodbury identity; the nonlinear route assembles them
/// into its tangent. At a millionth of the thickness and a microradian,
/// where the two mechanics differ by about the strain (1e-6 of the
/// displacement), two grabs (one held in place and turned, nine springs;
/// one pulled, three) settle both to the same displacement within 1e-5
/// of it; letting go of one and dragging the other, again.
#[test]
fn linear_grabs_match_the_assembled_springs() {
    let lift = 1e-6 * PLATE.thickness;
    let stiffness = 1e3 * PLATE.bending_stiffness() / 0.0116;
    let grabs = [
        Grab {
            at: [0.3, 0.4],
            target: Some(Vector::new(0.3, 0.4, lift)),
            rotation: Some(Vector::new(0.0, 1e-6, 0.0)),
            stiffness,
        },
        Grab {
            at: [0.7, 0.6],
            target: Some(Vector::new(0.7, 0.6, -lift)),
            rotation: None,
            stiffness,
        },
    ];
    let settled = |mechanics: Mechanics| {
        let mut dynamics = unloaded_plate(mechanics, 1e3);
        let settle = |d: &mut ShellDynamics| {
            for _ in 0..3 {
                d.step(&Cancel::new()).expect("a step");
            }
            d.displacement().to_vec()
        };
        dynamics.set_grabs(&grabs).expect("two grabs");
        let both = settle(&mut dynamics);
        dynamics.set_grabs(&grabs[1..]).expect("one let go");
        dynamics
            .move_grab(0, Some(Vector::new(0.7, 0.6, 2.0 * lift)), None)
            .expect("a drag");
        (both, settle(&mut dynamics))
    };
    let (linear, nonlinear) = (settled(Mechanics::Linear), settled(Mechanics::Nonlinear));
    for (what, a, b) in [
        ("two grabs", &linear.0, &nonlinear.0),
        ("one dragged", &linear.1, &nonlinear.1),
    ] {
        let largest = b.iter().map(|u| u.norm()).fold(0.0, Real::max);
        let apart = a
            .iter()
            .zip(b)
            .map(|(x, y)| (x - y).norm())
            .fold(0.0, Real::max);
        eprintln!("{what}: linear and nonlinear {apart:.2e} apart of {largest:.2e}");
        assert!(largest > 0.5 * lift, "{what}: the grabs moved the plate");
        assert!(apart < 1e-5 * largest, "{what}: {apart} of {largest}");
    }
}

/// The per-node shares frames stream add up to the shell's totals: the
/// lumped masses to `rho t A` (the partition of unity), the nodal
/// energies to the assembled membrane and bending energy of a bent plate.
#[test]
fn nodal_masses_and_energies_add_up_to_the_shells() {
    let model = plate(8.0, PLATE);
    let mass: Real = model.lumped_masses().iter().sum();
    let expected = PLATE.density * PLATE.thickness;
    assert!((mass / expected - 1.0).abs() < 1e-12, "{mass}");
    let u: Vec<Vector> = model
        .reference()
        .iter()
        .map(|x| Vector::new(0.0, 0.0, 0.05 * (PI * x.x).sin() * (PI * x.y).sin()))
        .collect();
    let shares: Real = model.nodal_energies(&u).expect("no fold").iter().sum();
    let (_, energy) = model.internal_forces(&u).expect("no fold");
    assert!(energy > 0.0);
    assert!(
        (shares / energy - 1.0).abs() < 1e-12,
        "{shares} vs {energy}"
    );
}
