//! Precision and dimension aliases, in one place so that a change of
//! precision is one edit.

/// The scalar the engine computes in.
pub type Real = f64;

/// A 3D vector of [`Real`].
pub type Vector = nalgebra::Vector3<Real>;

/// Converts a `[x, y, z]` array from a scene into a [`Vector`].
pub fn vector(v: [Real; 3]) -> Vector {
    Vector::new(v[0], v[1], v[2])
}

/// The corners `(lo, hi)` of the box around `points` (infinite, lo above
/// hi, for none).
pub fn bounds<'a>(points: impl IntoIterator<Item = &'a Vector>) -> (Vector, Vector) {
    points.into_iter().fold(
        (
            Vector::repeat(Real::INFINITY),
            Vector::repeat(Real::NEG_INFINITY),
        ),
        |(lo, hi), p| (lo.inf(p), hi.sup(p)),
    )
}

/// A number as a message shows it: plainly between 1e-4 and 1e6, in
/// scientific notation beyond. `{}` of an `f64` writes every digit, so
/// 1e300 became a 301-character message that repeated its input's digits
/// (found by the `scene_toml` fuzz target). The server's messages use it
/// too.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Brief(pub Real);

impl std::fmt::Display for Brief {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let x = self.0;
        if x == 0.0 || !x.is_finite() || (1e-4..1e6).contains(&x.abs()) {
            write!(f, "{x}")
        } else {
            write!(f, "{x:e}")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn brief_numbers_stay_short() {
        assert_eq!(Brief(0.04).to_string(), "0.04");
        assert_eq!(Brief(-1000.0).to_string(), "-1000");
        assert_eq!(Brief(1e300).to_string(), "1e300");
        assert_eq!(Brief(5.555e126).to_string(), "5.555e126");
        assert_eq!(Brief(1e-7).to_string(), "1e-7");
        assert_eq!(Brief(2.5e7).to_string(), "2.5e7");
        assert_eq!(Brief(Real::NAN).to_string(), "NaN");
        assert_eq!(Brief(0.0).to_string(), "0");
        assert!(Brief(-Real::MAX).to_string().len() < 30);
    }
}
