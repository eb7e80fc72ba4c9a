//! The measurement the footprint tests share: the memory estimate a host
//! admits scenes by (`Scene::check`) against the resident memory a
//! built world really holds after two steps. It must never be below the
//! measurement (a host would admit more than it can hold) and stay within
//! three times it (or it would refuse scenes it could hold). Each scene is
//! measured in its own test binary, so in a fresh process: memory freed by
//! an earlier measurement would be reused and hide the growth. Linux only:
//! it reads `/proc/self/statm`.

// Each test binary measures one scene, so the other builder is unused there.
#![allow(dead_code)]

use meshless_engine::{BuildOptions, Scene};
/// Resident bytes of this process.
fn resident_bytes() -> f64 {
    let statm = std::fs::read_to_string("/proc/self/statm").expect("statm");
    let pages: f64 = statm
        .split_whitespace()
        .nth(1)
        .and_then(|p| p.parse().ok())
        .expect("resident pages");
    pages * 4096.0
}

/// Estimate and measured growth of building `toml` and stepping twice.
fn estimate_and_measure(toml: &str) -> (f64, f64) {
    let scene = Scene::from_toml_str(toml).expect("scene");
    let options = BuildOptions::default();
    let checked = scene.check(&options).expect("valid");
    let estimate = checked.footprint().bytes;
    let before = resident_bytes();
    let mut world = checked.build();
    world.step().expect("steps");
    world.step().expect("steps");
    let measured = resident_bytes() - before;
    drop(world);
    (estimate, measured)
}

/// Asserts that `toml`'s estimate covers its measured growth, within 3x.
pub fn check(what: &str, toml: &str) {
    let (estimate, measured) = estimate_and_measure(toml);
    println!(
        "{what}: estimate {:.1} MB, measured {:.1} MB, ratio {:.2}",
        estimate / 1e6,
        measured / 1e6,
        estimate / measured
    );
    assert!(
        estimate >= measured,
        "{what}: estimate {estimate:.3e} B below the measured {measured:.3e} B"
    );
    assert!(
        estimate <= 3.0 * measured,
        "{what}: estimate {estimate:.3e} B over three times the measured {measured:.3e} B"
    );
}

/// The 3D dam-break column (102k particles at 0.025 m) under `solver`.
pub fn column(solver: &str) -> String {
    format!(
        r#"
        [domain]
        min = [0.0, 0.0, 0.0]
        max = [4.0, 3.0, 1.0]
        [time]
        dt = 0.004
        [[systems]]
        kind = "fluid"
        solver = "{solver}"
        spacing = 0.025
        stiffness = 5.7e5
        [[systems.blocks]]
        region = {{ min = [0.0, 0.0, 0.0], max = [1.0, 2.0, 0.8] }}
        "#
    )
}

/// A free 1 m elastic cube, `n` particles along each edge, under
/// `integrator`.
pub fn block(integrator: &str, n: f64) -> String {
    format!(
        r#"
        gravity = [0.0, 0.0, 0.0]
        [domain]
        min = [-2.0, -2.0, -2.0]
        max = [2.0, 2.0, 2.0]
        [time]
        dt = 0.001
        [[systems]]
        kind = "solid"
        shape = {{ type = "box", half_extents = [0.5, 0.5, 0.5] }}
        position = [0.0, 0.0, 0.0]
        spacing = {}
        young = 1e6
        density = 1000.0
        integrator = "{integrator}"
        "#,
        1.0 / n
    )
}
