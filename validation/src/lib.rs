//! # meshless-validation
//!
//! Reference data with their sources, the experiments that reproduce
//! them through the engine, and the measurements that compare the two.
//! The validation tests, `meshless study` and the benchmarks share them,
//! so a figure in a test, a study table and a benchmark come from the same
//! code. Kept out of the engine, which stays the numerics alone; this
//! crate depends on the engine and nothing networked.
//!
//! - [`dam_break`]: the collapsing water column against Martin & Moyce
//!   (1952);
//! - [`cantilever`]: an elastic beam under its own weight against
//!   Euler–Bernoulli theory;
//! - [`modal_cantilever`]: a modal EFG beam (Guo–Qin's solids) under its
//!   own weight against Timoshenko theory;
//! - [`shell_cantilever`]: a thin-shell cantilever plate (Guo–Qin's
//!   shells, through a scene) against Euler–Bernoulli's sag and period;
//! - [`griffith`]: a plate with a central crack under tension against
//!   Griffith's failure stress;
//! - [`design`]: the optimiser's Figure 13 stretch and the cube passing a
//!   ball;
//! - [`viscous`]: start-up Poiseuille and Couette flow and the spin-down
//!   of a rotating fluid, the references of viscosity and no-slip walls.

pub mod cantilever;
pub mod dam_break;
pub mod design;
pub mod griffith;
pub mod modal_cantilever;
pub mod shell_cantilever;
pub mod viscous;
