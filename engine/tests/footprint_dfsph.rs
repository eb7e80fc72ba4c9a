//! The memory estimate of a DFSPH fluid (its cached pair gradients)
//! against its measured growth
//! (`footprint/mod.rs`), in a process of its own.
#![cfg(target_os = "linux")]

mod footprint;

#[test]
fn dfsph_fluid_fits_its_estimate() {
    footprint::check("DFSPH fluid, 102k particles", &footprint::column("dfsph"));
}
