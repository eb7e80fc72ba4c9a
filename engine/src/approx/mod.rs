//! Approximation building blocks: SPH smoothing kernels (Adams–Wicke
//! tutorial, Section 2 and Appendix A) and the SPH operators built on them
//! (Section 2.2), and moving-least-squares shape functions and gradients
//! with safe inversion and rank fallback (Section 3), with either radial
//! weights or the tensor-product weight of the Element-Free Galerkin solids
//! (Guo–Qin, Eq. 12-13), and the Gauss–Legendre rules their integration
//! cells use.

pub mod gauss;
pub mod kernels;
pub mod layers;
pub mod mls;
pub mod operators;
pub mod tensor;

pub use kernels::{Kernel, KernelKind};
pub use mls::{
    Fit, GradientKind, GradientWeights, LagrangianGradients, Mls, MlsError, MlsParams, Order,
    ShapeFunctions,
};
