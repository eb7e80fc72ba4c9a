//! Approximation building blocks: SPH smoothing kernels (Adams–Wicke
//! tutorial, Section 2 and Appendix A) and the SPH operators built on them
//! (Section 2.2).

pub mod kernels;
pub mod operators;

pub use kernels::{Kernel, KernelKind};
