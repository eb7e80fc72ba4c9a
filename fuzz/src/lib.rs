//! # meshless-fuzz
//!
//! The bodies of the cargo-fuzz targets in `fuzz/libfuzzer`, one public
//! function per target, each taking the fuzzer's bytes. They live in a
//! workspace crate rather than in the cargo-fuzz crate so that the replay
//! test (`tests/corpus.rs`) runs every checked-in input and reproducer
//! under plain `cargo test`, with no cargo-fuzz and no nightly compiler,
//! and so that the instrumented build links only the engine, the wire
//! conversions and the protocol.
//!
//! A body panics only when a property fails, so every panic is a finding:
//! besides "no panic, no runaway allocation" on any input, each asserts
//! what an accepted input must satisfy (a scene survives the trip through
//! the protocol, a frame's lengths agree, a mesh's indices are in range)
//! and that an error quotes no more than a short prefix of its input
//! ([`echo`]). How to run them, and what they found: `docs/fuzzing.md`.

pub mod echo;
mod frame;
mod mesh;
mod requests;
mod scene;
mod snapshot;

pub use frame::frame;
pub use mesh::{mesh_obj, mesh_ply};
pub use requests::requests;
pub use scene::{scene_spec, scene_toml};
pub use snapshot::snapshot;

/// A target's body: the fuzzer's bytes in, a panic when a property fails.
pub type Target = fn(&[u8]);

/// Every target by name (the names of `fuzz/libfuzzer/fuzz_targets/*.rs`
/// and of the directories under `fuzz/corpus/`), for the replay test.
pub const TARGETS: &[(&str, Target)] = &[
    ("scene_toml", scene_toml),
    ("scene_spec", scene_spec),
    ("requests", requests),
    ("frame", frame),
    ("mesh_obj", mesh_obj),
    ("mesh_ply", mesh_ply),
    ("snapshot", snapshot),
];
