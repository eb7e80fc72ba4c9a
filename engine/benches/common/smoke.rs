//! Whether a benchmark runs in smoke mode: `MESHLESS_BENCH_SMOKE=1`.
//!
//! Every benchmark the documents cite must keep running, or its command
//! rots unnoticed (`scripts/bench-peers` once broke on a stale lock file),
//! but CI cannot afford the real sizes. In smoke mode a benchmark runs the
//! same code path at its smallest size with one repetition (a few hundred
//! particles, one or two steps) and prints the same table, so that
//! `scripts/smoke-docs` can run it under `cargo test` in a few seconds.
//! Its figures mean nothing; nothing is ever asserted on them. Unset (or
//! any other value), the benchmark is exactly what it always was.
//!
//! The one copy of this check: the engine's benchmarks include it with
//! `#[path = "common/smoke.rs"] mod smoke;`, `meshless-validation`'s and
//! `bench/peers` by their relative path to this file.

/// The environment variable that switches smoke mode on.
pub const VARIABLE: &str = "MESHLESS_BENCH_SMOKE";

/// True when `MESHLESS_BENCH_SMOKE` is `1`: run the smallest size, once.
pub fn smoke() -> bool {
    std::env::var_os(VARIABLE).is_some_and(|v| v == "1")
}

/// `normal` unless in smoke mode, then `small`: the one switch each
/// benchmark's sizes and repetition counts go through.
pub fn pick<T>(normal: T, small: T) -> T {
    if smoke() { small } else { normal }
}
