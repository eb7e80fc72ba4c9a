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
