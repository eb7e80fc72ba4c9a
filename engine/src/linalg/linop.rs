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

/// Every reduction and update split over rayon's threads; the dot
/// product sums fixed chunks ([`par_sum`]), so it rounds the same
/// whatever the thread count and scheduling.
#[derive(Debug, Clone, Copy, Default)]
pub struct Parallel;

/// Every reduction and update in index order on the calling thread.
#[derive(Debug, Clone, Copy, Default)]
pub struct Sequential;

impl<E: Element> Space<E> for Parallel {
    fn dot(a: &[E], b: &[E]) -> Real {
        assert_eq!(a.len(), b.len(), "dot: lengths differ");
        par_sum(a.len(), |i| a[i].dot(&b[i]))
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

/// Terms per partial sum of [`par_sum`].
const SUM_CHUNK: usize = 1024;

/// `sum of term(i) for i in 0..len`, the terms of each fixed chunk of
/// `SUM_CHUNK` (1,024) indices summed in order on one thread, then the chunks'
/// sums in order. rayon's own `sum` splits where threads steal work, so
/// its rounding changes from run to run; this one depends on `len` alone,
/// which keeps a step bit for bit reproducible (a restored snapshot steps
/// as the original did).
pub fn par_sum(len: usize, term: impl Fn(usize) -> Real + Sync) -> Real {
    let partial: Vec<Real> = (0..len.div_ceil(SUM_CHUNK))
        .into_par_iter()
        .map(|chunk| {
            let start = chunk * SUM_CHUNK;
            (start..len.min(start + SUM_CHUNK)).map(&term).sum::<Real>()
        })
        .collect();
    partial.iter().sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Terms whose sum rounds differently in different orders.
    fn term(i: usize) -> Real {
        let x = (i as Real * 0.618_033_988_749_895).fract();
        (x - 0.5) * 10f64.powi((i % 17) as i32 - 8)
    }

    #[test]
    fn par_sum_rounds_the_same_on_any_thread_count() {
        let len = 50_000;
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a pool")
                .install(|| par_sum(len, term))
        };
        let one = on(1);
        for threads in [2, 3, 8] {
            for _ in 0..5 {
                assert_eq!(on(threads).to_bits(), one.to_bits(), "{threads} threads");
            }
        }
        // The same terms summed in another order round differently, so
        // the equality above is not trivial.
        let reversed: Real = (0..len).rev().map(term).sum();
        assert_ne!(reversed.to_bits(), one.to_bits());
        assert!((reversed - one).abs() < 1e-9 * one.abs().max(1.0));
    }
}
