//! Validation of the MLS elastic solids through scenes, as users build
//! them: against Euler–Bernoulli beam theory (the cantilever), against
//! invariances the continuum model promises (rotations, energy), and at
//! the extremes of material and step.
//!
//!     cargo test -p meshless-tests --test validation_solids -- --nocapture

use meshless_engine::approx::mls::Order;
use meshless_engine::math::{Real, Vector};
use meshless_engine::solid::{ImplicitScheme, LinearSolver};
use meshless_engine::{BuildOptions, Scene, StepError, World};
use meshless_validation::cantilever::Cantilever;
use nalgebra::Rotation3;

/// A scene with one solid (`solid` holds its TOML keys) in a 10 m box
/// centred on the origin, without gravity unless `gravity` is given.
fn world(dim: usize, dt: Real, gravity: Real, solid: &str) -> World {
    let text = format!(
        r#"
        dimension = {dim}
        gravity = [0.0, {gravity}, 0.0]
        [domain]
        min = [-5.0, -5.0, -5.0]
        max = [5.0, 5.0, 5.0]
        [time]
        dt = {dt}
        max_substeps = 100000
        [[systems]]
        kind = "solid"
        {solid}
        "#
    );
    Scene::from_toml_str(&text)
        .expect("scene parses")
        .build(&BuildOptions::default())
        .expect("scene builds")
}

fn solid_of(world: &mut World) -> &mut meshless_engine::solid::ElasticSolid {
    world.solid_mut(0).expect("a solid")
}

fn max_norm(v: &[Vector]) -> Real {
    v.iter().map(|f| f.norm()).fold(0.0, Real::max)
}

const BLOCK_2D: &str = r#"
    shape = { type = "box", half_extents = [0.4, 0.1, 0.1] }
    position = [0.0, 0.0, 0.0]
    spacing = 0.025
    young = 1e6
"#;

/// Green–Saint-Venant strain is rotation invariant: a body turned by 90
/// degrees, or by any angle along a spin, carries no elastic force.
#[test]
fn rigid_rotations_produce_no_elastic_force() {
    for dim in [2, 3] {
        let mut w = world(
            dim,
            1e-3,
            0.0,
            &format!("{BLOCK_2D}\npoisson = 0.3\nvolume_stiffness = 1e6"),
        );
        let solid = solid_of(&mut w);
        let n = solid.len();
        let rest = solid.rest_positions().to_vec();
        let stretched = rest
            .iter()
            .map(|x| Vector::new(1.001 * x.x, x.y, x.z))
            .collect();
        solid
            .set_state(stretched, vec![Vector::zeros(); n])
            .expect("state");
        let scale = max_norm(&solid.forces());
        let axis = if dim == 2 {
            Vector::z_axis()
        } else {
            nalgebra::Unit::new_normalize(Vector::new(1.0, 2.0, -0.5))
        };
        let mut worst: Real = 0.0;
        for k in 0..=36 {
            let turn = Rotation3::from_axis_angle(&axis, k as Real * 10f64.to_radians());
            let moved = rest
                .iter()
                .map(|x| turn * x + Vector::new(0.3, -0.2, 0.0))
                .collect();
            solid
                .set_state(moved, vec![Vector::zeros(); n])
                .expect("state");
            worst = worst.max(max_norm(&solid.forces()) / scale);
        }
        println!("{dim}D: worst force under rotation / force of a 0.1 % stretch = {worst:.2e}");
        assert!(worst < 1e-9, "{dim}D: {worst:e}");
    }
}

/// Total energy of an undamped body released from a stretch, under the
/// explicit integrator.
fn energies(w: &mut World, steps: usize) -> Vec<Real> {
    (0..steps)
        .map(|_| {
            w.step().expect("stable");
            let (_, s) = w.solids().next().expect("solid");
            s.kinetic_energy() + s.potential_energy()
        })
        .collect()
}

#[test]
fn explicit_energy_stays_bounded_over_many_periods() {
    // Axial period 4 L / c, c = sqrt(E / rho) (0.8 m, 1e6 Pa): 0.1 s.
    let mut w = world(2, 1e-3, 0.0, &format!("{BLOCK_2D}\npoisson = 0.0"));
    let solid = solid_of(&mut w);
    let n = solid.len();
    let stretched = solid
        .rest_positions()
        .iter()
        .map(|x| Vector::new(1.02 * x.x, x.y, x.z))
        .collect();
    solid
        .set_state(stretched, vec![Vector::zeros(); n])
        .expect("state");
    let e0 = solid.potential_energy();
    let e = energies(&mut w, 3000);
    let period = 100;
    let mean = |s: &[Real]| s.iter().sum::<Real>() / s.len() as Real;
    let drift = (mean(&e[e.len() - period..]) - mean(&e[..period])) / e0;
    let swing = e.iter().map(|x| (x - e0).abs()).fold(0.0, Real::max) / e0;
    println!(
        "30 periods: secular drift {drift:.2e}, largest deviation {swing:.2e} of the initial energy"
    );
    assert!(drift.abs() < 1e-2, "drift {drift}");
    assert!(swing < 6e-2, "swing {swing}");
}

#[test]
fn implicit_is_stable_far_beyond_the_explicit_limit() {
    let limit = {
        let w = world(2, 1e-3, 0.0, BLOCK_2D);
        let (_, s) = w.solids().next().expect("solid");
        s.params.stable_dt(1.0)
    };
    let dt = 100.0 * limit;
    let stretch = |w: &mut World| {
        let solid = solid_of(w);
        let n = solid.len();
        let x = solid
            .rest_positions()
            .iter()
            .map(|x| Vector::new(1.05 * x.x, x.y, x.z))
            .collect();
        solid.set_state(x, vec![Vector::zeros(); n]).expect("state");
    };
    // Explicit, held to one sub-step per step: blows up, and says so.
    let mut explicit = Scene::from_toml_str(&format!(
        r#"
        dimension = 2
        gravity = [0.0, 0.0, 0.0]
        [domain]
        min = [-5.0, -5.0, -5.0]
        max = [5.0, 5.0, 5.0]
        [time]
        dt = {dt}
        max_substeps = 1
        [[systems]]
        kind = "solid"
        {BLOCK_2D}
        "#
    ))
    .expect("scene")
    .build(&BuildOptions::default())
    .expect("world");
    stretch(&mut explicit);
    let failure = (0..50).find_map(|_| explicit.step().err());
    match failure {
        Some(
            e @ (StepError::SolidUnstable { system: 0, .. }
            | StepError::SolidEnergyGained { system: 0, .. }),
        ) => println!("explicit at 100x: {e}"),
        other => panic!("explicit at 100x its limit should fault, got {other:?}"),
    }
    let mut implicit = world(
        2,
        dt,
        0.0,
        &format!("{BLOCK_2D}\nintegrator = \"implicit\""),
    );
    stretch(&mut implicit);
    let e = energies(&mut implicit, 50);
    let e0 = {
        let mut w = world(2, dt, 0.0, BLOCK_2D);
        stretch(&mut w);
        w.solids().next().expect("solid").1.potential_energy()
    };
    assert!(e.iter().all(|x| x.is_finite()));
    // Backward Euler never gains energy (up to round-off of the start).
    assert!(
        e.windows(2).all(|p| p[1] <= p[0] + 1e-12 * e0),
        "energy grew: {e:?}"
    );
    println!(
        "implicit at {dt:.2e} s (100x the explicit limit): energy {:.3e} -> {:.3e} J in 50 steps (from {:.3e})",
        e[0],
        e[e.len() - 1],
        e0
    );
    assert!(e[e.len() - 1] < 0.5 * e0);
}

/// A 2D block stretched by half its length between two anchored ends:
/// its area with and without the volume force of Eq. 65. Stable
/// neo-Hookean: with St Venant–Kirchhoff the release inverts a particle
/// (`det F = -0.08` at step 7), which now faults the step.
#[test]
fn the_volume_force_keeps_the_area_under_a_large_stretch() {
    let area = |volume_stiffness: Real| {
        let mut w = world(
            2,
            1e-3,
            0.0,
            &format!(
                r#"{BLOCK_2D}
                poisson = 0.3
                material = "stable_neo_hookean"
                volume_stiffness = {volume_stiffness}
                damping = 200.0
                anchors = [{{ min = [-1.0, -1.0, -1.0], max = [-0.35, 1.0, 1.0] }},
                           {{ min = [0.35, -1.0, -1.0], max = [1.0, 1.0, 1.0] }}]"#
            ),
        );
        let solid = solid_of(&mut w);
        let n = solid.len();
        let rest_area = solid.current_volume();
        let x = solid
            .rest_positions()
            .iter()
            .map(|x| Vector::new(1.5 * x.x, x.y, x.z))
            .collect();
        solid.set_state(x, vec![Vector::zeros(); n]).expect("state");
        for _ in 0..300 {
            w.step().expect("stable");
        }
        let (_, s) = w.solids().next().expect("solid");
        s.current_volume() / rest_area - 1.0
    };
    let off = area(0.0);
    let on = area(2e6);
    println!(
        "area change under a 50 % stretch: volume force off {:+.1} %, on {:+.1} %",
        off * 100.0,
        on * 100.0
    );
    assert!(on.abs() < off.abs(), "on {on} off {off}");
}

/// A block dropped onto the floor, from very soft to very stiff and up to
/// nearly incompressible, runs stably under both integrators (the explicit
/// one sub-stepping as far as it must).
#[test]
fn extreme_materials_run_stably() {
    for integrator in ["explicit", "implicit"] {
        for poisson in [0.0, 0.45, 0.499] {
            for young in [1e3, 1e6, 1e9] {
                let text = format!(
                    r#"
                    dimension = 2
                    [domain]
                    min = [-1.0, 0.0, -1.0]
                    max = [1.0, 1.0, 1.0]
                    [time]
                    dt = 2e-3
                    max_substeps = 100000
                    [[systems]]
                    kind = "solid"
                    shape = {{ type = "box", half_extents = [0.15, 0.05, 0.05] }}
                    position = [0.0, 0.1, 0.0]
                    spacing = 0.025
                    young = {young}
                    poisson = {poisson}
                    damping = 5.0
                    integrator = "{integrator}"
                    "#
                );
                let mut w = Scene::from_toml_str(&text)
                    .expect("scene")
                    .build(&BuildOptions::default())
                    .expect("world");
                for _ in 0..60 {
                    if let Err(e) = w.step() {
                        panic!("{integrator} E = {young:e}, nu = {poisson}: {e}");
                    }
                }
                let (_, s) = w.solids().next().expect("solid");
                let lowest = s
                    .positions
                    .iter()
                    .map(|x| x.y)
                    .fold(Real::INFINITY, Real::min);
                let speed = max_norm(&s.velocities);
                println!(
                    "{integrator:>8} E = {young:.0e} nu = {poisson:<5}: {:>6} sub-steps per step, lowest particle {lowest:.4} m, fastest {speed:.3} m/s",
                    w.last_step().substeps
                );
                // The implicit contact is a stiff penalty: its overlap
                // stays under 1 % of the particle radius.
                assert!(lowest >= 0.0125 * 0.99, "through the floor: {lowest}");
                // Free fall from 0.05 m reaches 1 m/s; bouncing adds nothing.
                assert!(speed < 2.0, "{speed}");
            }
        }
    }
}

/// Plastic flow (Eq. 69): a bar released from a 10 % stretch keeps part
/// of it, an elastic one springs back. Undamped, each vibrates about its
/// rest length: the mean over its last two periods.
#[test]
fn plastic_bars_keep_a_permanent_set() {
    let set = |plasticity: &str| {
        let mut w = world(
            2,
            1e-3,
            0.0,
            &format!(
                r#"{BLOCK_2D}
                poisson = 0.0
                anchors = [{{ min = [-1.0, -1.0, -1.0], max = [-0.35, 1.0, 1.0] }}]
                {plasticity}"#
            ),
        );
        let solid = solid_of(&mut w);
        let n = solid.len();
        let length = |x: &[Vector]| {
            let xs = x.iter().map(|p| p.x);
            xs.clone().fold(Real::NEG_INFINITY, Real::max) - xs.fold(Real::INFINITY, Real::min)
        };
        let rest = length(solid.rest_positions());
        let x = solid
            .rest_positions()
            .iter()
            .map(|x| {
                Vector::new(
                    if x.x > -0.35 {
                        1.1 * (x.x + 0.35) - 0.35
                    } else {
                        x.x
                    },
                    x.y,
                    x.z,
                )
            })
            .collect();
        solid.set_state(x, vec![Vector::zeros(); n]).expect("state");
        // Axial period 4 L / c = 0.1 s.
        let mut mean = 0.0;
        for step in 0..500 {
            w.step().expect("stable");
            if step >= 300 {
                let (_, s) = w.solids().next().expect("solid");
                mean += length(&s.positions) / rest - 1.0;
            }
        }
        mean / 200.0
    };
    let elastic = set("");
    let plastic = set("plasticity = { yield = 0.005, creep = 0.2, max = 1.0 }");
    println!(
        "elongation left after release: elastic {:+.2} %, plastic {:+.2} %",
        elastic * 100.0,
        plastic * 100.0
    );
    // Saint-Venant–Kirchhoff is softer in compression, which shifts an
    // elastic vibration's mean slightly below the rest length.
    assert!(elastic.abs() < 0.01, "elastic {elastic}");
    assert!(plastic > 0.04, "plastic {plastic}");
}

/// A soft block falls onto a static disc (a rigid body as an obstacle, no
/// fluid in the scene): no particle enters it. Stable neo-Hookean: with
/// St Venant–Kirchhoff a particle draped over the disc is squeezed to 0.15
/// of its volume at step 127, which now faults the step.
#[test]
fn solids_collide_with_static_bodies() {
    let text = r#"
        dimension = 2
        [domain]
        min = [-1.0, 0.0, -1.0]
        max = [1.0, 1.5, 1.0]
        [time]
        dt = 2e-3
        [[systems]]
        kind = "rigid_body"
        shape = { type = "sphere", radius = 0.2 }
        position = [0.05, 0.4, 0.0]
        [[systems]]
        kind = "solid"
        shape = { type = "box", half_extents = [0.25, 0.1, 0.1] }
        position = [0.0, 0.9, 0.0]
        spacing = 0.025
        young = 2e4
        poisson = 0.3
        material = "stable_neo_hookean"
        volume_stiffness = 1e4
        damping = 5.0
    "#;
    let mut w = Scene::from_toml_str(text)
        .expect("scene")
        .build(&BuildOptions::default())
        .expect("world");
    let centre = Vector::new(0.05, 0.4, 0.0);
    let mut closest = Real::INFINITY;
    for _ in 0..400 {
        w.step().expect("stable");
        let (_, s) = w.solids().next().expect("solid");
        closest = s
            .positions
            .iter()
            .map(|x| (x - centre).norm())
            .fold(closest, Real::min);
    }
    println!(
        "closest approach to the disc's centre: {closest:.4} m (radius 0.2, particle radius 0.0125)"
    );
    assert!(closest >= 0.2 + 0.0125 - 1e-6, "{closest}");
}

/// Cantilever under its own weight against Euler–Bernoulli: the static tip
/// deflection converges as the spacing shrinks, for the linear basis
/// (support 2 spacings) and the quadratic one (support 3), and is within
/// 10 % at 12 particles across the beam (linear) or 8 (quadratic).
#[test]
fn cantilever_deflection_converges_to_euler_bernoulli() {
    println!(
        "cantilever L = 1 m, H = 0.1 m, E = 1.5e8 Pa, nu = 0, 2D; tip deflection / Euler-Bernoulli - 1:"
    );
    println!(
        "{:>9} {:>8} {:>10} {:>10}",
        "spacing", "across", "linear", "quadratic"
    );
    let spacings = [0.025, 0.0167, 0.0125, 0.01, 0.00833, 0.00625];
    let mut errors = Vec::new();
    for &spacing in &spacings {
        let run = |order, support| {
            Cantilever {
                spacing,
                order,
                support,
                ..Cantilever::default()
            }
            .settle(1e-6)
            .expect("settles")
            .error
        };
        let (linear, quadratic) = (run(Order::Linear, 2.0), run(Order::Quadratic, 3.0));
        println!(
            "{spacing:>9} {:>8.0} {:>9.1}% {:>9.1}%",
            0.1 / spacing,
            linear * 100.0,
            quadratic * 100.0
        );
        errors.push((linear, quadratic));
    }
    for pair in errors.windows(2) {
        assert!(
            pair[1].0.abs() < pair[0].0.abs(),
            "linear does not converge: {errors:?}"
        );
        assert!(
            pair[1].1.abs() < pair[0].1.abs(),
            "quadratic does not converge: {errors:?}"
        );
    }
    assert!(
        errors[4].0.abs() < 0.10,
        "linear at 12 across: {}",
        errors[4].0
    );
    assert!(
        errors[2].1.abs() < 0.10,
        "quadratic at 8 across: {}",
        errors[2].1
    );
}

/// The static scheme solves the equilibrium in one step: the 2D
/// cantilever (8 across) lands where backward Euler steps of a hundred
/// beam periods settle it, at rest, and a free solid is refused it.
#[test]
fn a_static_step_solves_the_equilibrium() {
    let beam = Cantilever {
        integrator: meshless_engine::scene::IntegratorKind::Implicit,
        ..Cantilever::default()
    };
    let settled = beam.settle(1e-6).expect("settles");
    let mut scene = beam.scene().expect("valid");
    let meshless_engine::scene::SystemSpec::Solid(solid) = &mut scene.systems[0] else {
        panic!("the beam is a solid")
    };
    solid.implicit.scheme = ImplicitScheme::Static;
    let mut world = scene.build(&BuildOptions::default()).expect("valid");
    let info = world.step().expect("solves");
    let tip = beam.tip(&world);
    println!(
        "static step: tip {tip:.6e} m in {} Newton and CG iterations; settled {:.6e} m",
        info.solid_iterations, settled.value
    );
    assert_eq!(info.unconverged, 0);
    assert!(((tip - settled.value) / settled.value).abs() < 1e-3);
    let (_, solid) = world.solids().next().expect("the beam");
    assert!(solid.velocities.iter().all(|v| *v == Vector::zeros()));

    let meshless_engine::scene::SystemSpec::Solid(solid) = &mut scene.systems[0] else {
        panic!("the beam is a solid")
    };
    solid.anchors.clear();
    let Err(meshless_engine::scene::SceneError::Invalid { field, .. }) =
        scene.validate(&BuildOptions::default())
    else {
        panic!("a free static solid was accepted")
    };
    assert_eq!(field, "systems[0].implicit.scheme");
}

/// A slender 3D cantilever (L/H = 10, 6 particles across, 2.4k
/// particles) settled with the default `auto` linear solver: CG cannot
/// converge on it (auto stayed on CG and missed by +29 to +35 %, varying
/// from run to run), so auto switches to Cholesky and lands on Cholesky's
/// answer.
#[test]
fn auto_solver_converges_on_a_slender_3d_cantilever() {
    let run = |linear_solver| {
        Cantilever {
            dim: 3,
            spacing: 0.1 / 6.0,
            linear_solver,
            ..Cantilever::default()
        }
        .settle(1e-6)
        .expect("settles")
    };
    let (auto, cholesky) = (run(LinearSolver::Auto), run(LinearSolver::Cholesky));
    println!(
        "3D cantilever, 6 across ({} particles): auto {:+.2} %, cholesky {:+.2} % against Euler-Bernoulli",
        auto.particles,
        100.0 * auto.error,
        100.0 * cholesky.error
    );
    assert!(
        (auto.error - cholesky.error).abs() < 1e-3,
        "auto {} against cholesky {}",
        auto.error,
        cholesky.error
    );
}

/// The first bending period, from a release under the explicit
/// integrator, converges to beam theory's too.
#[test]
fn cantilever_period_converges_to_euler_bernoulli() {
    let mut last = Real::INFINITY;
    for spacing in [0.025, 0.0167, 0.0125] {
        let c = Cantilever {
            spacing,
            ..Cantilever::default()
        };
        let measured = c.period().expect("period");
        println!(
            "spacing {spacing}: first period {:.4} s, Euler-Bernoulli {:.4} s ({:+.1} %)",
            measured.value,
            c.first_period(),
            measured.error * 100.0
        );
        assert!(measured.error.abs() < last, "no convergence at {spacing}");
        last = measured.error.abs();
    }
    assert!(last < 0.1, "{last}");
}

/// A 2D block (0.2 m square, rho = 1000 kg/m^3, nu = 0.3) dropped 1 cm
/// onto the floor and left to rest, integrated implicitly: backward
/// Euler with contact inside its energy never gains energy, and the
/// block settles compressed by its own weight as elasticity says,
/// `rho g H^2 (1 - nu^2) / (2 E)` (plane strain, free sides). Contact
/// projected after each step used to store the step's fall as strain:
/// the block at E = 1e5 Pa gained 38 % of its energy scale and settled
/// squashed by 1.1 cm against the 1.8 mm elasticity gives; at 1e7 Pa it
/// gained 41 times its scale and was squashed by 1 cm against 18 um. At
/// 1e12 Pa most steps end with Newton at its cap, its residual at
/// 1.3-1.8e-6 against the 1e-6 tolerance: the rounding of a strain of
/// 1e-9 measured from positions of 0.1 m is 2e-6 of the block's weight.
#[test]
fn an_implicit_block_dropped_on_the_floor_loses_energy_and_rests_as_elasticity_says() {
    let (rho, nu, g, height) = (1000.0, 0.3, 9.81, 0.2);
    for young in [1e5, 1e7, 1e12] {
        let mut w = Scene::from_toml_str(&format!(
            r#"
            dimension = 2
            [domain]
            min = [-0.5, 0.0, -0.5]
            max = [0.5, 0.6, 0.5]
            [time]
            dt = 0.01
            [[systems]]
            kind = "solid"
            shape = {{ type = "box", half_extents = [0.1, 0.1, 0.1] }}
            position = [0.0, 0.11, 0.0]
            spacing = 0.025
            young = {young}
            poisson = {nu}
            integrator = "implicit"
            "#
        ))
        .expect("scene")
        .build(&BuildOptions::default())
        .expect("world");
        let gravity = Vector::new(0.0, -g, 0.0);
        let energy = |w: &World| {
            let (_, s) = w.solids().next().expect("solid");
            (
                s.mechanical_energy(&gravity, 0.01),
                s.energy_scale(&gravity),
            )
        };
        let (mut last, scale) = energy(&w);
        let mut unconverged = 0;
        for step in 0..150 {
            let info = w.step().expect("the block stays sound");
            unconverged += info.unconverged;
            let (now, _) = energy(&w);
            assert!(
                now <= last + 1e-9 * scale,
                "E = {young:e}: energy rose by {:e} of its scale in step {step}",
                (now - last) / scale
            );
            last = now;
        }
        let (_, s) = w.solids().next().expect("solid");
        let (low, top) = s
            .positions
            .iter()
            .fold((Real::INFINITY, Real::NEG_INFINITY), |(lo, hi), x| {
                (lo.min(x.y), hi.max(x.y))
            });
        let rest_span = height - 0.025;
        let squeezed = rest_span - (top - low);
        let elastic = rho * g * height * height * (1.0 - nu * nu) / (2.0 * young);
        println!(
            "E = {young:.0e} Pa: compression {squeezed:.3e} m, elasticity {elastic:.3e} m; lowest particle {low:.5} m; {unconverged} unconverged steps"
        );
        assert!(low > 0.0125 * 0.99, "through the floor: {low}");
        assert!(
            (squeezed - elastic).abs() < 0.35 * elastic,
            "E = {young:e}: compressed by {squeezed:e} m, elasticity says {elastic:e} m"
        );
    }
}
