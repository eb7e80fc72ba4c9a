//! The seams of the iterative solvers: the operator `y = A x`, the
//! preconditioner `z = M^-1 r`, and the vector space both act on.
//!
//! A vector is a slice of [`Element`]s: plain scalars (the optimiser's
//! unknowns) or one small vector per particle (a solid's velocities). How
//! its reductions and updates run is the [`Space`]: [`Parallel`] (rayon)
//! or [`Sequential`]. The two give different bits for a dot product (a
//! parallel sum adds in another order), so each caller keeps the one its
//! results were made with.

use crate::math::{Real, Vector};
use rayon::prelude::*;
use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

/// An entry of a solver's vector: a scalar, or a particle's vector.
pub trait Element:
    Copy
    + Send
    + Sync
    + Add<Output = Self>
    + Sub<Output = Self>
    + Neg<Output = Self>
    + Mul<Real, Output = Self>
    + AddAssign
    + SubAssign
{
    /// The additive identity.
    fn zero() -> Self;
    /// The inner product of two entries; a vector's dot product sums these.
    fn dot(&self, other: &Self) -> Real;
}

impl Element for Real {
    fn zero() -> Self {
        0.0
    }

    fn dot(&self, other: &Self) -> Real {
        self * other
    }
}

impl Element for Vector {
    fn zero() -> Self {
        Vector::zeros()
    }

    fn dot(&self, other: &Self) -> Real {
        nalgebra::Matrix::dot(self, other)
    }
}

/// A linear operator, `y = A x` (symmetric positive definite for
/// conjugate gradients). `&mut self` so that it may keep scratch buffers.
pub trait LinOp<E: Element> {
    /// Writes `A x` into `y` (of the same length).
    fn apply(&mut self, x: &[E], y: &mut [E]);
}

/// A preconditioner, `z = M^-1 r` with `M` symmetric positive definite.
pub trait Precond<E: Element> {
    /// Writes `M^-1 r` into `z` (of the same length).
    fn apply(&self, r: &[E], z: &mut [E]);
}

/// How the vector reductions and updates of a solver run.
pub trait Space<E: Element> {
    /// `a . b`, summed in this space's order.
    fn dot(a: &[E], b: &[E]) -> Real;
    /// `y = x`.
    fn copy(x: &[E], y: &mut [E]);
    /// `y = 0`.
    fn zero(y: &mut [E]);
    /// `y += x alpha`.
    fn add_scaled(y: &mut [E], x: &[E], alpha: Real);
    /// `y -= x alpha`.
    fn sub_scaled(y: &mut [E], x: &[E], alpha: Real);
    /// `y = x + y beta`.
    fn scale_add(y: &mut [E], x: &[E], beta: Real);
}

/// Every reduction and update split over rayon's threads: the dot
/// product's sum depends on how rayon splits it, so it is reproducible
/// only on a fixed thread count.
#[derive(Debug, Clone, Copy, Default)]
pub struct Parallel;

/// Every reduction and update in index order on the calling thread.
#[derive(Debug, Clone, Copy, Default)]
pub struct Sequential;

impl<E: Element> Space<E> for Parallel {
    fn dot(a: &[E], b: &[E]) -> Real {
        a.par_iter().zip(b).map(|(a, b)| a.dot(b)).sum()
    }

    fn copy(x: &[E], y: &mut [E]) {
        y.par_iter_mut().zip(x).for_each(|(y, x)| *y = *x);
    }

    fn zero(y: &mut [E]) {
        y.par_iter_mut().for_each(|y| *y = E::zero());
    }

    fn add_scaled(y: &mut [E], x: &[E], alpha: Real) {
        y.par_iter_mut().zip(x).for_each(|(y, x)| *y += *x * alpha);
    }

    fn sub_scaled(y: &mut [E], x: &[E], alpha: Real) {
        y.par_iter_mut().zip(x).for_each(|(y, x)| *y -= *x * alpha);
    }

    fn scale_add(y: &mut [E], x: &[E], beta: Real) {
        y.par_iter_mut()
            .zip(x)
            .for_each(|(y, x)| *y = *x + *y * beta);
    }
}

impl<E: Element> Space<E> for Sequential {
    fn dot(a: &[E], b: &[E]) -> Real {
        a.iter().zip(b).map(|(a, b)| a.dot(b)).sum()
    }

    fn copy(x: &[E], y: &mut [E]) {
        y.copy_from_slice(x);
    }

    fn zero(y: &mut [E]) {
        y.fill(E::zero());
    }

    fn add_scaled(y: &mut [E], x: &[E], alpha: Real) {
        for (y, x) in y.iter_mut().zip(x) {
            *y += *x * alpha;
        }
    }

    fn sub_scaled(y: &mut [E], x: &[E], alpha: Real) {
        for (y, x) in y.iter_mut().zip(x) {
            *y -= *x * alpha;
        }
    }

    fn scale_add(y: &mut [E], x: &[E], beta: Real) {
        for (y, x) in y.iter_mut().zip(x) {
            *y = *x + *y * beta;
        }
    }
}
