//! The shell cantilever `meshless study --knob shell-*` sweeps, at its
//! defaults: the static sag and the first half period against
//! Euler–Bernoulli, through a served scene.

use meshless_validation::shell_cantilever::{ShellCantilever, ShellMeasure};

#[test]
fn the_default_plate_sags_and_swings_as_euler_bernoulli_says() {
    let plate = ShellCantilever::default();
    let sag = plate.measure(ShellMeasure::Static).expect("settles");
    eprintln!("static: {sag:?}");
    assert!(sag.error.abs() < 0.02, "{sag:?}");
    let swing = plate.measure(ShellMeasure::Period).expect("swings");
    eprintln!("period: {swing:?}");
    assert!(swing.error.abs() < 0.03, "{swing:?}");
    // Newmark lengthens the period with the step: at 5 steps a period,
    // by about (omega h)^2 / 12 = 13 %.
    let coarse = ShellCantilever {
        dt: 2.0 * std::f64::consts::PI / plate.omega() / 5.0,
        ..plate
    }
    .measure(ShellMeasure::Period)
    .expect("swings");
    eprintln!("coarse period: {coarse:?}");
    assert!(coarse.error > swing.error + 0.05, "{coarse:?}");
}
