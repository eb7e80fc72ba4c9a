//! MLS elastic solids (tutorial Section 7): particles carry the
//! deformation field of a solid body, and high-resolution surfaces embedded
//! in it follow that field.

pub mod embedded;
