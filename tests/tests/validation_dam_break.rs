//! Validation against experiment: the collapse of a water column of width
//! a and height 2a (Martin & Moyce 1952). The surge front, nondimensional
//! `Z = x / a` against `T = t sqrt(2 g / a)`, must follow the measurements
//! within 10 % for 1 <= T <= 3 with the shipped dam-break scene.

use meshless_engine::approx::KernelKind;
use meshless_engine::scene::{SolverKind, SystemSpec, WallModel};
use meshless_engine::{BuildOptions, Scene};
use meshless_validation::dam_break::{
    MARTIN_MOYCE_FRONT, dam_break_time_scale, interpolate, surge_front,
};

const A: f64 = 0.3;
const G: f64 = 9.81;

/// Runs the shipped scene with the given wall model (and, for DFSPH, its
/// solver and the consistent cubic spline pair) and returns the simulated
/// `(T, Z)` curve, one point per step, and the worst density error the
/// pressure solver left.
fn simulate(walls: WallModel, solver: SolverKind) -> (Vec<(f64, f64)>, f64) {
    let scene = Scene::from_toml_str(include_str!("../../scenes/dam_break.toml")).expect("scene");
    simulate_scene(scene, walls, solver)
}

fn simulate_scene(
    mut scene: Scene,
    walls: WallModel,
    solver: SolverKind,
) -> (Vec<(f64, f64)>, f64) {
    let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
        panic!("the first system is the fluid")
    };
    fluid.walls = walls;
    fluid.solver = solver;
    if solver == SolverKind::Dfsph {
        fluid.density_kernel = KernelKind::CubicSpline;
        fluid.gradient_kernel = KernelKind::CubicSpline;
    }
    assert_eq!(
        fluid.blocks[0].region.max[0], A,
        "the scene's column is a wide"
    );
    assert_eq!(fluid.blocks[0].region.max[1], 2.0 * A, "and 2a high");
    let mut world = scene.build(&BuildOptions::default()).expect("valid");
    let scale = dam_break_time_scale(A, G);
    let mut curve = Vec::new();
    let mut density_error: f64 = 0.0;
    while world.clock().time * scale < 3.4 {
        let info = world.step().expect("stable");
        density_error = density_error.max(info.density_error);
        let fluid = world.fluid().expect("fluid");
        let front = surge_front(&fluid.positions, A).expect("water on the floor");
        curve.push((world.clock().time * scale, front));
    }
    (curve, density_error)
}

/// The shipped scene (WCSPH, solid walls) within 10 % of the experiment
/// for 1 <= T <= 3. Also reported: reflection-only walls, whose wall-side
/// particles lack density and drag the front (worse), and DFSPH, which is
/// less dissipative and leads the measured front early on (the
/// experiment's gate opening slows its first instants), held to 20 % and
/// to its density tolerance.
#[test]
fn dam_break_front_follows_martin_and_moyce() {
    let (solid, _) = simulate(WallModel::Solid, SolverKind::Wcsph);
    let (reflect, _) = simulate(WallModel::Reflect, SolverKind::Wcsph);
    let (dfsph, density_error) = simulate(WallModel::Solid, SolverKind::Dfsph);
    println!("    T   Z measured   WCSPH solid walls   WCSPH reflecting walls   DFSPH solid walls");
    let (mut worst, mut worst_reflect, mut worst_dfsph): (f64, f64, f64) = (0.0, 0.0, 0.0);
    for (t, z) in MARTIN_MOYCE_FRONT {
        let [zs, zr, zd] =
            [&solid, &reflect, &dfsph].map(|c| interpolate(c, t).expect("simulated up to T = 3.4"));
        let pct = |v: f64| 100.0 * (v - z) / z;
        println!(
            "{t:5.2}   {z:10.2}   {zs:6.2} ({:+5.1} %)     {zr:6.2} ({:+5.1} %)          {zd:6.2} ({:+5.1} %)",
            pct(zs),
            pct(zr),
            pct(zd)
        );
        if (1.0..=3.0).contains(&t) {
            worst = worst.max(((zs - z) / z).abs());
            worst_reflect = worst_reflect.max(((zr - z) / z).abs());
            worst_dfsph = worst_dfsph.max(((zd - z) / z).abs());
        }
    }
    println!(
        "worst error for 1 <= T <= 3: WCSPH solid {:.1} %, reflect {:.1} %, DFSPH {:.1} %; \
         DFSPH worst density error {:.3} %",
        100.0 * worst,
        100.0 * worst_reflect,
        100.0 * worst_dfsph,
        100.0 * density_error
    );
    assert!(
        worst < 0.10,
        "solid walls: worst front error {:.1} %",
        100.0 * worst
    );
    assert!(worst_reflect > worst);
    assert!(
        worst_dfsph < 0.20,
        "DFSPH: worst front error {:.1} %",
        100.0 * worst_dfsph
    );
    assert!(
        density_error <= 0.001 + 1e-12,
        "DFSPH left {density_error} density error"
    );
}

/// The same experiment in 2D (`scenes/dam_break_2d.toml`, 450 particles
/// in the plane at the 3D scene's spacing a / 15): within 10 % of the
/// measured front for 1 <= T <= 3. Refining shows the converged 2D front
/// leading the experiment by about 11 % at T = 1.2 (the measured column
/// was slowed by its gate); the table prints the refined run too.
#[test]
fn dam_break_2d_front_follows_martin_and_moyce() {
    let scene =
        Scene::from_toml_str(include_str!("../../scenes/dam_break_2d.toml")).expect("scene");
    assert_eq!(scene.dimension, 2);
    let mut fine = scene.clone();
    let SystemSpec::Fluid(fluid) = &mut fine.systems[0] else {
        panic!("the first system is the fluid")
    };
    fluid.spacing /= 2.0;
    fluid.support_radius = Some(2.0 * fluid.spacing);
    let (curve, _) = simulate_scene(scene, WallModel::Solid, SolverKind::Wcsph);
    let (fine_curve, _) = simulate_scene(fine, WallModel::Solid, SolverKind::Wcsph);
    let (mut worst, mut worst_fine): (f64, f64) = (0.0, 0.0);
    println!("    T   Z measured   Z 2D, a/15        Z 2D, a/30");
    for (t, z) in MARTIN_MOYCE_FRONT {
        let [zs, zf] =
            [&curve, &fine_curve].map(|c| interpolate(c, t).expect("simulated up to T = 3.4"));
        println!(
            "{t:5.2}   {z:10.2}   {zs:6.2} ({:+5.1} %)   {zf:6.2} ({:+5.1} %)",
            100.0 * (zs - z) / z,
            100.0 * (zf - z) / z
        );
        if (1.0..=3.0).contains(&t) {
            worst = worst.max(((zs - z) / z).abs());
            worst_fine = worst_fine.max(((zf - z) / z).abs());
        }
    }
    println!(
        "worst error for 1 <= T <= 3 in 2D: {:.1} % at a/15, {:.1} % at a/30",
        100.0 * worst,
        100.0 * worst_fine
    );
    assert!(worst < 0.10, "2D: worst front error {:.1} %", 100.0 * worst);
    assert!(
        worst_fine < 0.15,
        "2D refined: worst front error {:.1} %",
        100.0 * worst_fine
    );
}
