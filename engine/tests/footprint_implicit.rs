//! The memory estimate of an implicit MLS solid (its Newton matrix) against its measured growth
//! (`footprint/mod.rs`), in a process of its own.
#![cfg(target_os = "linux")]

mod footprint;

fn block(integrator: &str, n: f64) -> String {
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

#[test]
fn implicit_solid_fits_its_estimate() {
    footprint::check("implicit solid, 8k particles", &block("implicit", 20.0));
}
