//! Validation against experiment: the collapse of a water column of width
//! a and height 2a (Martin & Moyce 1952). The surge front, nondimensional
//! `Z = x / a` against `T = t sqrt(2 g / a)`, must follow the measurements
//! within 10 % for 1 <= T <= 3 with the shipped dam-break scene.

use meshless_engine::approx::KernelKind;
use meshless_engine::experiments::{
    MARTIN_MOYCE_FRONT, dam_break_time_scale, interpolate, surge_front,
};
use meshless_engine::scene::{SolverKind, SystemSpec, WallModel};
use meshless_engine::{BuildOptions, Scene};

const A: f64 = 0.3;
const G: f64 = 9.81;

/// Runs the shipped scene with the given wall model (and, for DFSPH, its
/// solver and the consistent cubic spline pair) and returns the simulated
/// `(T, Z)` curve, one point per step, and the worst density error the
/// pressure solver left.
fn simulate(walls: WallModel, solver: SolverKind) -> (Vec<(f64, f64)>, f64) {
    let mut scene =
        Scene::from_toml_str(include_str!("../../scenes/dam_break.toml")).expect("scene");
    let SystemSpec::Fluid(fluid) = &mut scene.systems[0];
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
