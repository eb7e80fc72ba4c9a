//! Approximation building blocks: SPH smoothing kernels (Adams–Wicke
//! tutorial, Section 2 and Appendix A).

pub mod kernels;

pub use kernels::{Kernel, KernelKind};
