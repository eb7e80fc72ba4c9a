//! The memory estimate of an explicit MLS solid against its measured growth
//! (`footprint/mod.rs`), in a process of its own.
#![cfg(target_os = "linux")]

mod footprint;

#[test]
fn explicit_solid_fits_its_estimate() {
    footprint::check(
        "explicit solid, 27k particles",
        &footprint::block("explicit", 30.0),
    );
}
