//! Validation of the viscous term and of no-slip walls against analytic
//! solutions of unsteady viscous flow (references in
//! `meshless_validation::viscous`): start-up Poiseuille and Couette flow
//! between no-slip walls (Morris, Fox & Zhu 1997) at two resolutions, a
//! viscous fluid in rigid rotation that must keep its angular momentum,
//! and its spin-down in a no-slip container against the Bessel series.

use meshless_engine::math::Vector;
use meshless_engine::{BuildOptions, Scene, World};
use meshless_validation::viscous::{SpinDown, couette, poiseuille};

/// Channel height, kinematic viscosity and rest density of the channel
/// flows: `L^2 / (pi^2 nu)`, the slowest mode's time, is 0.1 s.
const L: f64 = 1.0;
const NU: f64 = 1.0;
const RHO: f64 = 1000.0;

/// A 2D channel `0 <= y <= L`, periodic along x over 0.6 m, with no-slip
/// walls, `across` particles between the walls, driven by the body force
/// `force` along x (the scene's `body_force`, standing in for the pressure
/// gradient of a periodic channel) and the upper wall moving at `lid`
/// along x. The Tait stiffness puts the
/// sound speed at 1.3 m/s, ten times the fastest flow here, so the flow
/// is nearly incompressible (density variations of order 1 %).
fn channel(across: usize, force: f64, lid: f64, support: f64, model: &str) -> World {
    let dx = L / across as f64;
    let h = support * dx;
    let mu = NU * RHO;
    let lid = if lid == 0.0 {
        String::new()
    } else {
        format!("wall_velocity = {{ max_y = [{lid}, 0.0, 0.0] }}")
    };
    let text = format!(
        r#"
dimension = 2
periodic = [true, false, false]
gravity = [0.0, 0.0, 0.0]
[domain]
min = [0.0, 0.0, 0.0]
max = [0.6, {L}, 0.0]
[time]
dt = 0.005
[[systems]]
kind = "fluid"
spacing = {dx}
support_radius = {h}
stiffness = 250.0
viscosity = {mu}
viscosity_model = "{model}"
xsph = 0.0
wall_slip = "no"
body_force = ["{force}", "0", "0"]
{lid}
[[systems.blocks]]
region = {{ min = [0.0, 0.0, 0.0], max = [0.6, {L}, 0.0] }}
"#
    );
    Scene::from_toml_str(&text)
        .expect("scene parses")
        .build(&BuildOptions::default())
        .expect("scene is valid")
}

/// The mean x velocity of each lattice row of the channel (rows of height
/// `L / across`), at the rows' centres.
fn row_profile(world: &World, across: usize) -> Vec<(f64, f64)> {
    let fluid = world.fluid().expect("fluid");
    let mut sums = vec![(0.0, 0usize); across];
    for (x, v) in fluid.positions.iter().zip(&fluid.velocities) {
        let row = ((x.y / L * across as f64) as usize).min(across - 1);
        sums[row].0 += v.x;
        sums[row].1 += 1;
    }
    sums.iter()
        .enumerate()
        .filter(|(_, (_, n))| *n > 0)
        .map(|(row, (sum, n))| ((row as f64 + 0.5) * L / across as f64, sum / *n as f64))
        .collect()
}

/// Runs a channel flow and returns, at each of `times`, the largest
/// difference between the row profile and `exact(y, t)`, over `scale`.
fn channel_errors(
    mut world: World,
    across: usize,
    times: &[f64],
    scale: f64,
    exact: impl Fn(f64, f64) -> f64,
) -> Vec<f64> {
    let mut errors = Vec::new();
    for &t in times {
        while world.clock().time < t - 1e-9 {
            world.step().expect("stable");
        }
        let t = world.clock().time;
        let profile = row_profile(&world, across);
        let worst = profile
            .iter()
            .map(|&(y, u)| (u - exact(y, t)).abs())
            .fold(0.0, f64::max);
        if t >= TIMES[TIMES.len() - 1] - 1e-9 {
            let rows: Vec<String> = profile
                .iter()
                .step_by((across / 10).max(1))
                .map(|&(y, u)| format!("{y:.3}: {u:.4} ({:.4})", exact(y, t)))
                .collect();
            println!(
                "  {across} across at t = {t:.2} s, y: u (exact): {}",
                rows.join(", ")
            );
        }
        errors.push(worst / scale);
    }
    errors
}

/// Support radius of the flows compared with series, in spacings.
const SUPPORT: f64 = 3.0;

const TIMES: [f64; 5] = [0.02, 0.05, 0.1, 0.2, 0.6];

fn print_table(name: &str, rows: &[(usize, Vec<f64>)]) {
    println!("{name}: worst row error / reference speed at t [s] = {TIMES:?}");
    for (across, errors) in rows {
        let cells: Vec<String> = errors
            .iter()
            .map(|e| format!("{:.2} %", 100.0 * e))
            .collect();
        println!("  {across} particles across: {}", cells.join(" | "));
    }
}

/// Asserts every sample of each run under the given bounds at (20, 40)
/// particles across, and that refining lowers the worst error of the run
/// (the steady errors alone, 0.10 % for Couette at both, are too close to
/// order).
fn check_channel(name: &str, rows: &[(usize, Vec<f64>)], bounds: [f64; 2]) {
    print_table(name, rows);
    for ((across, errors), bound) in rows.iter().zip(bounds) {
        for (t, e) in TIMES.iter().zip(errors) {
            assert!(
                *e < bound,
                "{name}, {across} across, t = {t} s: error {:.2} %",
                100.0 * e
            );
        }
    }
    let worst = |r: &(usize, Vec<f64>)| r.1.iter().cloned().fold(0.0, f64::max);
    assert!(
        worst(&rows[1]) < worst(&rows[0]),
        "{name}: refining did not help: {rows:?}"
    );
}

/// Poiseuille flow from rest under a body force F = 1 m/s^2 (peak 0.125
/// m/s, Re = 0.125), support 3 spacings, Monaghan's form: the row means
/// follow Morris et al.'s series within 10 % of the steady peak at 20 and
/// 40 particles across, converging. Measured (docs/validation.md): 0.5 %
/// early, 9.3 % at steady state (20 across); 0.3 % and 9.0 % (40); before
/// the walls' ghosts were extrapolated in full, 13.1 % and 10.9 %. What is
/// left is the form's anisotropy on a lattice: its response to a shear
/// `u = y^2` sums `x^2 y^2` moments over the neighbours, which the lattice
/// gives at 0.91 of the continuum's at support 3 (0.65 at support 2), so
/// shear sees a viscosity 9 % low. That is the price of conserving angular
/// momentum (Morris's form, isotropic, exerts a torque, and meets the
/// series within 5 %: `channel_flows_at_30_across_by_support_and_form`).
#[test]
fn poiseuille_start_up_follows_the_series_solution() {
    let force = 1.0;
    let peak = force * L * L / (8.0 * NU);
    let rows: Vec<(usize, Vec<f64>)> = [20, 40]
        .into_iter()
        .map(|across| {
            let world = channel(across, force, 0.0, SUPPORT, "monaghan");
            let errors = channel_errors(world, across, &TIMES, peak, |y, t| {
                poiseuille(y, t, L, force, NU)
            });
            (across, errors)
        })
        .collect();
    check_channel("Poiseuille", &rows, [0.10, 0.10]);
}

/// Couette flow from rest, the upper wall set moving at V = 0.1 m/s: the
/// profile follows the series within 4 % of V at 20 and 40 particles
/// across, and ends linear within 1 % (measured: 2.6 % early, 0.1 %
/// steady at 20 across; 2.3 % and 0.1 % at 40; with the ghosts' capped
/// extrapolation 5.3 %, 0.9 %, 3.6 % and 0.5 %). The steady profile does
/// not depend on the viscosity; the early boundary layer, a few spacings
/// thick, does, and converges as it is resolved.
#[test]
fn couette_start_up_follows_the_series_solution() {
    let speed = 0.1;
    let rows: Vec<(usize, Vec<f64>)> = [20, 40]
        .into_iter()
        .map(|across| {
            let world = channel(across, 0.0, speed, SUPPORT, "monaghan");
            let errors = channel_errors(world, across, &TIMES, speed, |y, t| {
                couette(y, t, L, speed, NU)
            });
            (across, errors)
        })
        .collect();
    check_channel("Couette", &rows, [0.04, 0.04]);
    for (across, errors) in &rows {
        assert!(
            errors[TIMES.len() - 1] < 0.01,
            "{across} across: {errors:?}"
        );
    }
}

/// A 2D disc of water (radius `R` = 0.2 m, spacing 0.01 m, no gravity, no
/// XSPH) spinning at 2 rad/s inside a circular container of the given
/// slip, with the fluid viscosity `mu`, viscosity model and support (in
/// spacings). WCSPH with a sound speed of 8.4 m/s, 21 times the rim
/// speed: DFSPH, held to many short viscous sub-steps, pumped energy into
/// this flow until the energy watch faulted it (docs/validation.md).
fn spinning_disc(slip: &str, mu: f64, model: &str, support: f64) -> World {
    let support = support * 0.01;
    let text = format!(
        r#"
dimension = 2
gravity = [0.0, 0.0, 0.0]
[domain]
min = [0.0, 0.0, 0.0]
max = [0.6, 0.6, 0.0]
[time]
dt = 0.01
[[systems]]
kind = "fluid"
stiffness = 1e4
spacing = 0.01
support_radius = {support}
xsph = 0.0
viscosity = {mu}
viscosity_model = "{model}"
[[systems.blocks]]
region = {{ min = [0.0, 0.0, 0.0], max = [0.6, 0.6, 0.0] }}
[[systems]]
kind = "rigid_body"
shape = {{ type = "sphere", radius = 0.2 }}
position = [0.3, 0.3, 0.0]
hollow = true
slip = "{slip}"
"#
    );
    let mut world = Scene::from_toml_str(&text)
        .expect("scene parses")
        .build(&BuildOptions::default())
        .expect("scene is valid");
    let fluid = world.fluid_mut().expect("fluid");
    for (x, v) in fluid.positions.iter().zip(fluid.velocities.iter_mut()) {
        *v = Vector::z().cross(&(x - CENTRE)) * OMEGA;
    }
    world
}

const CENTRE: Vector = Vector::new(0.3, 0.3, 0.0);
const OMEGA: f64 = 2.0;
const RADIUS: f64 = 0.2;

/// Angular momentum of the fluid about the container's centre, per metre
/// of depth.
fn angular_momentum(world: &World) -> f64 {
    let fluid = world.fluid().expect("fluid");
    fluid
        .positions
        .iter()
        .zip(&fluid.velocities)
        .map(|(x, v)| (x - CENTRE).cross(v).z * fluid.params.mass)
        .sum()
}

/// Angular momentum left after each of `steps` steps of 0.01 s.
fn angular_momentum_trace(world: &mut World, steps: usize) -> Vec<f64> {
    let start = angular_momentum(world);
    (0..steps)
        .map(|_| {
            world.step().expect("stable");
            angular_momentum(world) / start
        })
        .collect()
}

/// A viscous fluid (nu = 0.01 m^2/s) in rigid rotation inside a free-slip
/// container is an exact steady solution: it must keep rotating. With the
/// default (Monaghan's) viscosity it keeps 99 % of its angular momentum
/// for 0.5 s, as the inviscid fluid does; Morris's form, whose pair forces
/// are not along the pairs, is measured beside it and loses several times
/// more (13.7 % per second at any resolution when it was the default).
#[test]
fn a_viscous_fluid_in_rigid_rotation_keeps_its_angular_momentum() {
    let kept = |mu: f64, model: &str| {
        let trace = angular_momentum_trace(&mut spinning_disc("free", mu, model, 2.0), 50);
        trace[trace.len() - 1]
    };
    let inviscid = kept(0.0, "monaghan");
    let monaghan = kept(10.0, "monaghan");
    let morris = kept(10.0, "morris");
    println!(
        "angular momentum kept after 0.5 s in a free-slip container: inviscid {inviscid:.4}, \
         monaghan {monaghan:.4}, morris {morris:.4}"
    );
    assert!(
        monaghan > 0.99,
        "Monaghan's viscosity kept only {monaghan} of the angular momentum"
    );
    assert!(
        (monaghan - inviscid).abs() < 0.005,
        "viscosity changed the angular momentum of a rigid rotation: {monaghan} against {inviscid}"
    );
    assert!(
        1.0 - morris > 3.0 * (1.0 - monaghan),
        "Morris's form lost {} against Monaghan's {}",
        1.0 - morris,
        1.0 - monaghan
    );
}

/// Spin-down in a no-slip container (nu = 0.01 m^2/s, R = 0.2 m, support
/// 3 spacings: the slowest mode decays in R^2 / (j_1^2 nu) = 0.27 s),
/// against the Bessel series over 0.5 s: within 10 % of L0 and 5 % of
/// Omega R. The container is a rigid body with one layer of boundary
/// samples; the fluid stands farther off them than a lattice's half
/// spacing, and their friction at the body's own velocity held the fluid
/// back too weakly: it kept 58 % of its angular momentum at 0.1 s against
/// the series' 43 % (worst 16.4 % of L0), its near-wall ring running at
/// 0.115 m/s against 0.066 (12.3 % of Omega R). The samples' friction is
/// now scaled to what a ghost lattice filling the neighbourhood's missing
/// volume, with Morris's extrapolation, would exert (`rigid/ghosts.rs`):
/// 9.3 % of L0 and 2.7 % of Omega R. What is left is mostly the bulk: at
/// support 3 Monaghan's form sees 0.91 of the viscosity, and the late
/// decay runs at 0.95 of the series' rate.
#[test]
fn spin_down_follows_the_bessel_series() {
    let nu = 0.01;
    let exact = SpinDown::new(OMEGA, RADIUS, nu, 100);
    let mut world = spinning_disc("no", nu * 1000.0, "monaghan", SUPPORT);
    let start = angular_momentum(&world);
    let mut worst_momentum: f64 = 0.0;
    let mut worst_profile: f64 = 0.0;
    println!("t [s]  L/L0 SPH  L/L0 Bessel");
    for step in 1..=50 {
        world.step().expect("stable");
        let t = world.clock().time;
        let measured = angular_momentum(&world) / start;
        let reference = exact.angular_momentum(t);
        worst_momentum = worst_momentum.max((measured - reference).abs());
        if step % 10 == 0 {
            println!("{t:.2}  {measured:.4}  {reference:.4}");
        }
        if step == 10 || step == 30 {
            let fluid = world.fluid().expect("fluid");
            let rings = 8;
            let mut sums = vec![(0.0, 0.0, 0usize); rings];
            for (x, v) in fluid.positions.iter().zip(&fluid.velocities) {
                let r = x - CENTRE;
                let ring = (r.norm() / RADIUS * rings as f64) as usize;
                if ring < rings {
                    let azimuthal = Vector::z().cross(&r).dot(v) / r.norm().max(1e-12);
                    sums[ring].0 += r.norm();
                    sums[ring].1 += azimuthal;
                    sums[ring].2 += 1;
                }
            }
            for (r, u, n) in sums.into_iter().filter(|s| s.2 > 0) {
                let (r, u) = (r / n as f64, u / n as f64);
                let reference = exact.velocity(r, t);
                println!("  r = {r:.3} m: u = {u:.4} m/s, Bessel {reference:.4} m/s");
                worst_profile = worst_profile.max((u - reference).abs() / (OMEGA * RADIUS));
            }
        }
    }
    println!(
        "worst angular momentum error {:.2} % of L0, worst ring velocity error {:.2} % of Omega R",
        100.0 * worst_momentum,
        100.0 * worst_profile
    );
    assert!(
        worst_momentum < 0.10,
        "angular momentum off by {worst_momentum}"
    );
    assert!(worst_profile < 0.05, "ring velocity off by {worst_profile}");
    assert!(
        angular_momentum(&world) / start < 0.5,
        "the no-slip container hardly braked the fluid"
    );
}

/// Where the steady Poiseuille profile's parabola, fitted by least squares
/// to the row means, meets zero: the distances of its roots from the floor
/// and from the lid, in spacings (positive outside the channel).
fn no_slip_planes(world: &World, across: usize) -> (f64, f64) {
    let profile = row_profile(world, across);
    // Normal equations of u = a y^2 + b y + c.
    let mut normal = nalgebra::Matrix3::<f64>::zeros();
    let mut rhs = nalgebra::Vector3::<f64>::zeros();
    for &(y, u) in &profile {
        let basis = nalgebra::Vector3::new(y * y, y, 1.0);
        normal += basis * basis.transpose();
        rhs += basis * u;
    }
    let [a, b, c] = normal
        .lu()
        .solve(&rhs)
        .expect("the rows span a parabola")
        .into();
    let root = (b * b - 4.0 * a * c).sqrt();
    let (low, high) = ((-b + root) / (2.0 * a), (-b - root) / (2.0 * a));
    let (low, high) = (low.min(high), low.max(high));
    let dx = L / across as f64;
    (-low / dx, (high - L) / dx)
}

/// The no-slip condition holds on the walls themselves: the steady
/// Poiseuille profile at 30 particles across, extrapolated as the
/// parabola it is, vanishes within 0.05 spacings of each wall, in both
/// pair forms. With Morris et al.'s cap on the ghosts' extrapolation the
/// planes lay 0.2 (Monaghan) to 0.3 (Morris) spacings outside each wall,
/// and the row next to the floor ran 53 % fast.
#[test]
fn the_no_slip_plane_lies_on_the_wall() {
    let (across, force) = (30, 1.0);
    let mut worst: f64 = 0.0;
    for model in ["monaghan", "morris"] {
        let mut world = channel(across, force, 0.0, SUPPORT, model);
        while world.clock().time < 0.6 - 1e-9 {
            world.step().expect("stable");
        }
        let (floor, lid) = no_slip_planes(&world, across);
        let (y, u) = row_profile(&world, across)[0];
        let row = u / poiseuille(y, 0.6, L, force, NU) - 1.0;
        println!(
            "{model}: no-slip planes {floor:+.3} (floor) and {lid:+.3} (lid) spacings outside \
             the walls; the floor row runs {:+.1} %",
            100.0 * row
        );
        worst = worst.max(floor.abs()).max(lid.abs());
    }
    assert!(
        worst < 0.05,
        "a no-slip plane lies {worst:.3} spacings off its wall"
    );
}

/// Poiseuille and Couette start-up at 30 particles across, at support 3
/// spacings and at the default support of 2, in both pair forms: the worst
/// row error over the run (as in the tables above) against the series.
/// With the no-slip condition on the wall, Morris's form, isotropic on a
/// lattice, meets both series within 5 % at both supports (measured 4.4 %
/// and 2.7 % for Poiseuille, at most 1.1 % for Couette). Monaghan's form,
/// the default because it conserves angular momentum, pushes along the
/// pair and sees a shear at 0.91 of the viscosity at support 3 and 0.65 at
/// 2 (`monaghans_form_sees_shear_at_a_fraction_of_the_viscosity`): its
/// Poiseuille flow runs 9 % and 42 % fast there, bounded here at 10 % and
/// 45 % so that the figures docs/validation.md gives cannot drift unseen.
#[test]
fn channel_flows_at_30_across_by_support_and_form() {
    let (across, force, speed) = (30, 1.0, 0.1);
    let peak = force * L * L / (8.0 * NU);
    // (support, form, Poiseuille bound, Couette bound)
    let cases = [
        (3.0, "morris", 0.05, 0.05),
        (2.0, "morris", 0.05, 0.05),
        (3.0, "monaghan", 0.10, 0.05),
        (2.0, "monaghan", 0.45, 0.12),
    ];
    let mut failures = Vec::new();
    for (support, model, poiseuille_bound, couette_bound) in cases {
        let flows = [
            (
                "Poiseuille",
                channel_errors(
                    channel(across, force, 0.0, support, model),
                    across,
                    &TIMES,
                    peak,
                    |y, t| poiseuille(y, t, L, force, NU),
                ),
                poiseuille_bound,
            ),
            (
                "Couette",
                channel_errors(
                    channel(across, 0.0, speed, support, model),
                    across,
                    &TIMES,
                    speed,
                    |y, t| couette(y, t, L, speed, NU),
                ),
                couette_bound,
            ),
        ];
        for (name, errors, bound) in flows {
            print_table(
                &format!("{name}, {model}, support {support}"),
                &[(across, errors.clone())],
            );
            let worst = errors.iter().cloned().fold(0.0, f64::max);
            if worst >= bound {
                failures.push(format!("{name}, {model}, support {support}: {worst:.4}"));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}
