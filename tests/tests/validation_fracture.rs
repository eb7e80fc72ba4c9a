//! Validation of the fracturing solids against linear elastic fracture
//! mechanics: Griffith's plate with a central crack (failure stress
//! against crack length) and mode I growth from a slanted edge notch
//! (`validation/src/griffith.rs` has the references and the method).
//!
//!     cargo test -p meshless-tests --test validation_fracture -- --nocapture

use meshless_engine::math::{Real, Vector};
use meshless_engine::solid::fracture::{Discontinuity, Notch};
use meshless_validation::griffith::Griffith;

/// Least-squares slope of `ln y` against `ln x`.
fn log_slope(points: &[(Real, Real)]) -> Real {
    let logs: Vec<(Real, Real)> = points.iter().map(|(x, y)| (x.ln(), y.ln())).collect();
    let n = logs.len() as Real;
    let (mx, my) = logs
        .iter()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let sxy: Real = logs.iter().map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: Real = logs.iter().map(|(x, _)| (x - mx) * (x - mx)).sum();
    sxy / sxx
}

#[test]
fn a_central_crack_runs_at_griffiths_stress_scaled_as_the_inverse_root_of_its_length() {
    let plate = Griffith::default();
    let rc = plate.critical_distance();
    println!(
        "Griffith plate {} x {} m, spacing {} m, r_c = {:.3} m ({:.1} spacings), \
         K_Ic = {:.4e} Pa m^1/2, gamma = {:.4e} J/m^2",
        plate.width,
        plate.height,
        plate.spacing,
        rc,
        rc / plate.spacing,
        plate.toughness,
        plate.surface_energy()
    );
    println!(
        "| a / r_c | a (m) | a / W | particles | measured (Pa) | Griffith (Pa) | point method (Pa) | measured / Griffith | measured / point method |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut ratios = Vec::new();
    let mut corrected = Vec::new();
    for k in [4.0, 6.0, 9.0] {
        let f = plate
            .failure(k * rc)
            .expect("the front runs below the strength");
        let a = f.half_length;
        let (to_griffith, to_point) = (f.stress / f.griffith, f.stress / f.point_method);
        println!(
            "| {:.2} | {a:.4} | {:.3} | {} | {:.4e} | {:.4e} | {:.4e} | {to_griffith:.3} | {to_point:.3} |",
            a / rc,
            a / plate.width,
            f.particles,
            f.stress,
            f.griffith,
            f.point_method
        );
        // Below Griffith by the point method's short-crack factor and the
        // discretisation's sampling of the tip field, never above.
        assert!(
            (0.70..1.0).contains(&to_griffith),
            "a = {a}: {to_griffith} of Griffith's stress"
        );
        assert!(
            (0.85..1.02).contains(&to_point),
            "a = {a}: {to_point} of the point method's stress"
        );
        ratios.push(to_point);
        // Divided by the point method's short-crack factor and the width
        // factor, what is left should follow Griffith's a^(-1/2).
        corrected.push((a, f.stress / f.point_method * plate.infinite(a)));
    }
    let slope = log_slope(&corrected);
    let spread = ratios.iter().cloned().fold(Real::NEG_INFINITY, Real::max)
        / ratios.iter().cloned().fold(Real::INFINITY, Real::min)
        - 1.0;
    println!(
        "exponent of a once the width and short-crack factors are divided out: {slope:.3}; \
         spread of measured / point method: {:.1} %",
        100.0 * spread
    );
    assert!((slope + 0.5).abs() < 0.05, "exponent {slope}, not -1/2");
    assert!(spread < 0.06, "measured / point method varies by {spread}");
}

#[test]
fn the_measured_stress_converges_to_the_point_methods_as_the_spacing_resolves_the_critical_distance()
 {
    // The same plate, crack and material at 2 and 6 spacings per
    // critical distance (the toughness fixed, so r_c stays 3 cm).
    let base = Griffith {
        width: 0.6,
        height: 0.9,
        ..Griffith::default()
    };
    let errors: Vec<Real> = [2.0, 6.0]
        .iter()
        .map(|per| {
            let plate = Griffith {
                spacing: base.critical_distance() / per,
                ..base
            };
            let f = plate
                .failure(0.09)
                .expect("the front runs below the strength");
            let ratio = f.stress / f.point_method;
            println!(
                "r_c = {per} spacings, {} particles, a = {:.4} m: measured {:.4e} Pa, point \
                 method {:.4e} Pa, ratio {ratio:.3}",
                f.particles, f.half_length, f.stress, f.point_method
            );
            (1.0 - ratio).abs()
        })
        .collect();
    assert!(
        errors[1] < 0.05 && errors[1] < 0.5 * errors[0],
        "from 2 to 6 spacings per critical distance the error went from {} to {}",
        errors[0],
        errors[1]
    );
}

#[test]
fn transparency_leaves_a_smoother_strain_field_at_the_tip_than_visibility() {
    // The Griffith plate of the convergence test, held at about half its
    // failure load, its crack's tips a quarter spacing past a column.
    let base = Griffith {
        width: 0.6,
        height: 0.9,
        ..Griffith::default()
    };
    let (a, strain) = (0.0875, 3e-4);
    println!("| criterion | beside the crack | ahead of the tip |");
    println!("|---|---|---|");
    let mut measured = Vec::new();
    for (name, discontinuity) in [
        ("visibility", Discontinuity::Visibility),
        (
            "transparency, kappa = 0.5",
            Discontinuity::Transparency { kappa: 0.5 },
        ),
        (
            "transparency, kappa = 1",
            Discontinuity::Transparency { kappa: 1.0 },
        ),
        (
            "transparency, kappa = 2",
            Discontinuity::Transparency { kappa: 2.0 },
        ),
    ] {
        let plate = Griffith {
            discontinuity,
            ..base
        };
        let r = plate.roughness(a, strain).expect("the plate holds");
        println!("| {name} | {:.2} | {:.2} |", r.beside, r.ahead);
        measured.push(r);
    }
    let (visibility, default) = (measured[0], measured[2]);
    assert!(
        default.beside < 0.75 * visibility.beside && default.ahead < 0.75 * visibility.ahead,
        "transparency at kappa = 1 {default:?} against visibility {visibility:?}"
    );
    // More transparent, the line ahead of the tip fades further.
    assert!(measured[3].ahead < default.ahead, "{measured:?}");
}

/// A central notch at 30 degrees to the plate's width, reaching 0.06 m
/// either side of the centre across the load.
fn slanted_notch() -> Notch {
    let angle = (30.0 as Real).to_radians();
    Notch {
        center: Vector::zeros(),
        normal: Vector::new(-angle.sin(), angle.cos(), 0.0),
        radius: 0.06 / angle.cos(),
    }
}

#[test]
fn a_crack_from_a_slanted_notch_starts_at_its_tips_and_turns_normal_to_the_load() {
    let plate = Griffith {
        width: 0.5,
        height: 0.75,
        ..Griffith::default()
    };
    let notch = slanted_notch();
    let along = Vector::new(notch.normal.y, -notch.normal.x, 0.0) * notch.radius;
    let tips = [notch.center + along, notch.center - along];
    let run = plate
        .notched(notch, 0.06, 200)
        .expect("the notch's front runs below the strength");
    let angle = run.final_angle(0.04).expect("the crack ran 4 cm");
    println!(
        "slanted notch, tips at ({:.3}, {:.3}) and ({:.3}, {:.3}): failure at {:.4e} Pa; the \
         crack ran {} steps, its last 4 cm at {angle:.1} degrees from normal to the load; {} \
         cracks started elsewhere",
        tips[0].x, tips[0].y, tips[1].x, tips[1].y, run.failure, run.steps, run.started
    );
    // The notch's own front ran, from its tips, and nothing else started.
    for (path, tip) in run.paths.iter().zip(tips) {
        assert!(
            (path[0] - tip).norm() < 1e-9,
            "a front began at {:?}",
            path[0]
        );
    }
    assert!(run.advances > 0, "the notch's front never ran");
    assert_eq!(run.started, 0, "a crack started away from the notch");
    assert!(angle.abs() < 10.0, "the crack runs at {angle} degrees");

    // Below the threshold, for ten times the updates the crack needed to
    // run its 6 cm, dynamically: nothing starts and nothing runs; a little
    // above it, the front runs within a hundred.
    let hold = |fraction: Real, updates: usize| {
        plate
            .hold(notch, fraction * run.failure_strain, updates)
            .expect("the plate holds")
    };
    let (started, advanced) = hold(0.95, 10 * run.steps);
    println!(
        "at 95 % of the failure load, {} dynamic updates: {started} cracks started, {advanced} \
         advances",
        10 * run.steps
    );
    assert_eq!((started, advanced), (0, 0));
    let (_, advanced) = hold(1.05, 100);
    println!("at 105 %, 100 dynamic updates: {advanced} advances");
    assert!(advanced > 0, "a front held past its failure load never ran");
}
