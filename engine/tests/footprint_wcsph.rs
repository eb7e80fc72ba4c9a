//! The memory estimate of a WCSPH fluid against its measured growth
//! (`footprint/mod.rs`), in a process of its own.
#![cfg(target_os = "linux")]

mod footprint;

fn column(solver: &str) -> String {
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

#[test]
fn wcsph_fluid_fits_its_estimate() {
    footprint::check("WCSPH fluid, 102k particles", &column("wcsph"));
}
