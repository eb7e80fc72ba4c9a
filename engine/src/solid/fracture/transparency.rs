//! How a crack between two particles weakens their weight: the
//! visibility criterion and the transparency weights of tutorial Eq. 70,
//! and the under-sampling measure of Eq. 71 built from them.
//!
//! The MLS weight of a pair is `w_ij = W(q)`, `q = |X_i - X_j| / h`
//! (evaluated in reference coordinates). Eq. 70 (Organ et al. 1996, as
//! Pauly et al. 2005 use it) replaces it, for a pair whose segment crosses
//! a crack at a point `d_s` from the crack's front, by
//!
//! ```text
//! w'_ij = W(q + (d_s / (kappa s))^2)
//! ```
//!
//! with `s` the particle spacing near the crossing and `kappa` the
//! opacity scale: at the front (`d_s = 0`) the weight is unchanged, so the
//! shape functions stay continuous around the crack tip, and behind it the
//! pair's distance grows until it leaves the support (`q' >= 1`). The
//! visibility criterion (Belytschko et al. 1994) is the limit `kappa -> 0`:
//! any crossing removes the pair. A pair crossing several cracks adds
//! their terms.

use super::params::Discontinuity;
use crate::approx::KernelKind;
use crate::math::Real;

/// The term one crossing adds to a pair's normalised distance: `(d_s /
/// (kappa spacing))^2`, or infinity under the visibility criterion.
pub fn opacity(discontinuity: Discontinuity, to_front: Real, spacing: Real) -> Real {
    match discontinuity {
        Discontinuity::Visibility => Real::INFINITY,
        Discontinuity::Transparency { kappa } => {
            let x = to_front / (kappa * spacing);
            x * x
        }
    }
}

/// The weight `W(q + extra)` of a pair at normalised distance `q = r / h`
/// whose crossings added `extra`; `None` outside the (lengthened) support.
pub fn transparent_weight(kernel: KernelKind, q: Real, extra: Real) -> Option<Real> {
    let q = q + extra;
    if q.is_nan() || q >= 1.0 {
        return None;
    }
    let w = kernel.profile(q)[0];
    (w > 0.0).then_some(w)
}

/// Eq. 71: `Q_i = sum_j w'_ij / w_ij` over `i`'s neighbours `j` in the
/// support (itself excluded), given each neighbour's normalised distance
/// `q` and added term `extra`. Without cracks it counts the neighbours;
/// every crack that passes between `i` and a neighbour lowers it.
pub fn undersampling(kernel: KernelKind, pairs: impl Iterator<Item = (Real, Real)>) -> Real {
    pairs
        .filter_map(|(q, extra)| {
            let plain = transparent_weight(kernel, q, 0.0)?;
            Some(transparent_weight(kernel, q, extra).unwrap_or(0.0) / plain)
        })
        .sum()
}
