//! The memory estimate of an implicit MLS solid (its Newton matrix) against its measured growth
//! (`footprint/mod.rs`), in a process of its own.
#![cfg(target_os = "linux")]

mod footprint;

#[test]
fn implicit_solid_fits_its_estimate() {
    footprint::check(
        "implicit solid, 8k particles",
        &footprint::block("implicit", 20.0),
    );
}
