//! Approximation building blocks: SPH smoothing kernels (Adams–Wicke
//! tutorial, Appendix A).

pub mod kernels;

pub use kernels::{Kernel, Poly6, Spiky};
