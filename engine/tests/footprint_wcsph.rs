//! The memory estimate of a WCSPH fluid against its measured growth
//! (`footprint/mod.rs`), in a process of its own.
#![cfg(target_os = "linux")]

mod footprint;

#[test]
fn wcsph_fluid_fits_its_estimate() {
    footprint::check("WCSPH fluid, 102k particles", &footprint::column("wcsph"));
}
