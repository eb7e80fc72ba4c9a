//! Analytic solid shapes in their own (body) frame: signed distance,
//! outward normal, volume and inertia, and one layer of surface samples.
//!
//! They are the geometry of rigid bodies: the fluid meets a body through
//! particles sampled on its surface (Akinci et al. 2012), is kept out of it
//! by its signed distance, and a dynamic body moves with the mass and
//! inertia of its volume. Every shape is centred on its body's origin, which
//! is also its centre of mass.
//!
//! In 2D the fluid lives in the plane z = 0 and a body only turns about z:
//! a shape then stands for its cross-section in that plane (a box for a
//! rectangle, a sphere for a disc, a capsule for a stadium, a plane for a
//! line), its volume is the area (per metre of depth) and its inertia the
//! polar moment about z. A box's z extent is ignored in 2D.
//!
//! A mesh is a solid of its own ([`MeshSolid`]), in 3D only: centred on its
//! centroid and turned onto its principal axes when it was built, it then
//! answers like the primitives.

use super::MeshSolid;
use crate::math::{Real, Vector};
use rayon::prelude::*;
use std::f64::consts::PI;

/// A solid in its body frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// The box `|x| <= half_extents` on every axis.
    Box {
        /// Half the side length along each local axis (m); z is ignored
        /// in 2D.
        half_extents: Vector,
    },
    /// The ball `|x| <= radius`.
    Sphere {
        /// Radius (m).
        radius: Real,
    },
    /// The points within `radius` of the segment from `(0, -half_length, 0)`
    /// to `(0, half_length, 0)`: a cylinder along local y with
    /// hemispherical caps.
    Capsule {
        /// Half the length of the axis segment, caps excluded (m).
        half_length: Real,
        /// Radius of the cylinder and its caps (m).
        radius: Real,
    },
    /// The half-space `normal . x <= offset` (`normal` is a unit vector
    /// pointing out of the solid, into the fluid). Infinite: no volume, and
    /// only the part of its surface near the domain is sampled.
    Plane {
        /// Unit outward normal, in the body frame.
        normal: Vector,
        /// Signed distance of the plane from the body origin along
        /// `normal` (m).
        offset: Real,
    },
    /// A closed triangle mesh in its principal frame (3D only; `dim` is
    /// not consulted).
    Mesh(MeshSolid),
}

/// Golden angle, the azimuth step of a Fibonacci lattice.
const GOLDEN_ANGLE: Real = 2.399_963_229_728_653;

impl Shape {
    /// Signed distance from `p` (body frame) to the surface: negative
    /// inside the solid. `dim` = 2 measures in the plane z = 0.
    pub fn signed_distance(&self, p: &Vector, dim: usize) -> Real {
        match self {
            Self::Box { half_extents } => {
                let axes = dim.min(3);
                let mut outside = 0.0;
                let mut inside = Real::NEG_INFINITY;
                for a in 0..axes {
                    let q = p[a].abs() - half_extents[a];
                    outside += q.max(0.0).powi(2);
                    inside = inside.max(q);
                }
                outside.sqrt() + inside.min(0.0)
            }
            Self::Sphere { radius } => p.norm() - radius,
            Self::Capsule {
                half_length,
                radius,
            } => {
                let axis = Vector::new(0.0, p.y.clamp(-half_length, *half_length), 0.0);
                (p - axis).norm() - radius
            }
            Self::Plane { normal, offset } => normal.dot(p) - offset,
            Self::Mesh(solid) => solid.signed_distance(p),
        }
    }

    /// Unit outward normal of the surface nearest to `p` (body frame): the
    /// direction in which the signed distance grows fastest. Where that is
    /// undefined (the centre of a sphere), some unit vector.
    pub fn normal(&self, p: &Vector, dim: usize) -> Vector {
        let unit_or = |v: Vector, fallback: Vector| {
            let n = v.norm();
            if n > 1e-12 { v / n } else { fallback }
        };
        match self {
            Self::Box { half_extents } => {
                let axes = dim.min(3);
                let q = Vector::from_fn(|a, _| {
                    if a < axes {
                        p[a].abs() - half_extents[a]
                    } else {
                        Real::NEG_INFINITY
                    }
                });
                let sign = |a: usize| if p[a] < 0.0 { -1.0 } else { 1.0 };
                if (0..axes).any(|a| q[a] > 0.0) {
                    let v = Vector::from_fn(|a, _| {
                        if a < axes {
                            q[a].max(0.0) * sign(a)
                        } else {
                            0.0
                        }
                    });
                    unit_or(v, Vector::y())
                } else {
                    let a = (0..axes).fold(0, |best, a| if q[a] > q[best] { a } else { best });
                    let mut n = Vector::zeros();
                    n[a] = sign(a);
                    n
                }
            }
            Self::Sphere { .. } => unit_or(*p, Vector::y()),
            Self::Capsule { half_length, .. } => {
                let axis = Vector::new(0.0, p.y.clamp(-half_length, *half_length), 0.0);
                unit_or(p - axis, Vector::x())
            }
            Self::Plane { normal, .. } => *normal,
            Self::Mesh(solid) => solid.normal(p),
        }
    }

    /// Volume (area per metre of depth in 2D), m^3; `None` for the
    /// infinite plane.
    pub fn volume(&self, dim: usize) -> Option<Real> {
        let planar = dim == 2;
        match self {
            Self::Box { half_extents: e } => Some(if planar {
                4.0 * e.x * e.y
            } else {
                8.0 * e.x * e.y * e.z
            }),
            Self::Sphere { radius: r } => Some(if planar {
                PI * r * r
            } else {
                4.0 / 3.0 * PI * r.powi(3)
            }),
            Self::Capsule {
                half_length: l,
                radius: r,
            } => Some(if planar {
                4.0 * r * l + PI * r * r
            } else {
                2.0 * PI * r * r * l + 4.0 / 3.0 * PI * r.powi(3)
            }),
            Self::Plane { .. } => None,
            Self::Mesh(solid) => Some(solid.volume()),
        }
    }

    /// Principal moments of inertia of a solid of uniform `density` about
    /// its centre, in the body frame (the body axes are principal for all
    /// these shapes, and a mesh is turned onto its principal axes), kg m^2. In 2D only the z moment (the polar moment of
    /// the cross-section, per metre of depth) is meaningful; the others
    /// are set equal to it. `None` for the plane.
    pub fn inertia(&self, density: Real, dim: usize) -> Option<Vector> {
        let mass = density * self.volume(dim)?;
        let planar = dim == 2;
        let moments = match self {
            Self::Box { half_extents: e } => {
                let (a, b, c) = (e.x * e.x, e.y * e.y, e.z * e.z);
                if planar {
                    Vector::repeat(mass * (a + b) / 3.0)
                } else {
                    Vector::new(b + c, a + c, a + b) * (mass / 3.0)
                }
            }
            Self::Sphere { radius: r } => {
                Vector::repeat(mass * r * r * if planar { 0.5 } else { 0.4 })
            }
            Self::Capsule {
                half_length: l,
                radius: r,
            } => {
                let (l, r) = (*l, *r);
                if planar {
                    // Rectangle 2r x 2l, plus two half discs whose centroids
                    // sit 4r / (3 pi) beyond the rectangle's ends.
                    let rect = density * 4.0 * r * l;
                    let disc = density * PI * r * r;
                    let zz = rect * (4.0 * r * r + 4.0 * l * l) / 12.0
                        + disc * (0.5 * r * r + l * l + 8.0 * l * r / (3.0 * PI));
                    Vector::repeat(zz)
                } else {
                    // Cylinder of length 2l plus two hemispheres (a ball),
                    // each hemisphere shifted from its flat face by l.
                    let cyl = density * 2.0 * PI * r * r * l;
                    let ball = density * 4.0 / 3.0 * PI * r.powi(3);
                    let across = cyl * (r * r / 4.0 + l * l / 3.0)
                        + ball * (0.4 * r * r + l * l + 0.75 * l * r);
                    let along = cyl * r * r / 2.0 + ball * 0.4 * r * r;
                    Vector::new(across, along, across)
                }
            }
            Self::Plane { .. } => return None,
            Self::Mesh(solid) => solid.inertia(density),
        };
        Some(moments)
    }

    /// The shape with its surface moved inward by `depth` (outward for a
    /// negative `depth`), the set of points at least `depth` inside; `None`
    /// when nothing would remain.
    pub fn inset(&self, depth: Real) -> Option<Shape> {
        let shape = match self {
            Self::Box { half_extents } => Self::Box {
                half_extents: half_extents.add_scalar(-depth),
            },
            Self::Sphere { radius } => Self::Sphere {
                radius: radius - depth,
            },
            Self::Capsule {
                half_length,
                radius,
            } => Self::Capsule {
                half_length: *half_length,
                radius: radius - depth,
            },
            Self::Plane { normal, offset } => Self::Plane {
                normal: *normal,
                offset: offset - depth,
            },
            Self::Mesh(solid) => return solid.inset(depth).map(Self::Mesh),
        };
        let empty = match &shape {
            Self::Box { half_extents } => half_extents.xy().min() <= 0.0,
            Self::Sphere { radius } | Self::Capsule { radius, .. } => *radius <= 0.0,
            Self::Plane { .. } | Self::Mesh(_) => false,
        };
        (!empty).then_some(shape)
    }

    /// Radius of a ball about the origin that holds the solid; infinite for
    /// the plane.
    pub fn bounding_radius(&self, dim: usize) -> Real {
        match self {
            Self::Box { half_extents: e } => {
                if dim == 2 {
                    e.xy().norm()
                } else {
                    e.norm()
                }
            }
            Self::Sphere { radius } => *radius,
            Self::Capsule {
                half_length,
                radius,
            } => half_length + radius,
            Self::Plane { .. } => Real::INFINITY,
            Self::Mesh(solid) => solid.bounding_radius(),
        }
    }

    /// The solid filled with particles: the points of a lattice of
    /// `spacing`, centred on the body origin (cell centres at
    /// `(k + 1/2) spacing`), that lie inside. Each stands for the volume
    /// `spacing^dim`, so a body of density `rho` gets particle mass
    /// `rho spacing^dim`; a box whose sides are whole multiples of the
    /// spacing is filled exactly. In 2D, the cross-section in z = 0. `None`
    /// for the infinite plane, a spacing that is not positive and finite, or
    /// a lattice over the bounding cube of more than
    /// [`super::MAX_SAMPLES`] points.
    pub fn sample_volume(&self, spacing: Real, dim: usize) -> Option<Vec<Vector>> {
        if !(spacing.is_finite() && spacing > 0.0) {
            return None;
        }
        let reach = self.bounding_radius(dim);
        if !reach.is_finite() {
            return None;
        }
        let n = (reach / spacing).ceil() as i64;
        let side = 2 * n as usize;
        let depth = if dim == 2 { 1 } else { side };
        if (side as f64).powi(2) * depth as f64 > super::MAX_SAMPLES as f64 {
            return None;
        }
        let at = |k: i64| (k as Real + 0.5) * spacing;
        let points = (0..depth)
            .into_par_iter()
            .flat_map_iter(|kz| {
                let z = if dim == 2 { 0.0 } else { at(kz as i64 - n) };
                (-n..n).flat_map(move |ky| {
                    (-n..n).filter_map(move |kx| {
                        let p = Vector::new(at(kx), at(ky), z);
                        (self.signed_distance(&p, dim) < 0.0).then_some(p)
                    })
                })
            })
            .collect();
        Some(points)
    }

    /// One layer of points on the surface, about `spacing` apart (body
    /// frame). In 2D, the outline in the plane z = 0. A plane is sampled on
    /// the square (3D) or segment (2D) of half-width `reach` around the
    /// point of the plane nearest to `around`; bounded shapes ignore both.
    ///
    /// Boxes are sampled on a lattice that includes their edges and
    /// corners, spheres and capsule caps on Fibonacci lattices (equal area
    /// per point), circles and cylinders on rings, meshes by Poisson-disk
    /// sampling ([`MeshSolid::sample_surface`]; none when the spacing would
    /// make too many, which scene validation rules out).
    pub fn sample_surface(
        &self,
        spacing: Real,
        dim: usize,
        around: &Vector,
        reach: Real,
    ) -> Vec<Vector> {
        let count = |length: Real| (length / spacing).round().max(1.0) as usize;
        let mut points = Vec::new();
        match self {
            Self::Box { half_extents: e } => {
                let axes = if dim == 2 { 2 } else { 3 };
                let n: Vec<usize> = (0..axes).map(|a| count(2.0 * e[a])).collect();
                let coordinate = |a: usize, i: usize| -e[a] + 2.0 * e[a] * i as Real / n[a] as Real;
                let on_face = |i: usize, a: usize| i == 0 || i == n[a];
                let nz = if axes == 3 { n[2] } else { 0 };
                for k in 0..=nz {
                    for j in 0..=n[1] {
                        for i in 0..=n[0] {
                            let surface =
                                on_face(i, 0) || on_face(j, 1) || (axes == 3 && on_face(k, 2));
                            if surface {
                                let z = if axes == 3 { coordinate(2, k) } else { 0.0 };
                                points.push(Vector::new(coordinate(0, i), coordinate(1, j), z));
                            }
                        }
                    }
                }
            }
            Self::Sphere { radius } => {
                if dim == 2 {
                    circle(*radius, count(2.0 * PI * radius), &mut points);
                } else {
                    let n = count(4.0 * PI * radius * radius / spacing);
                    fibonacci_cap(*radius, n, -1.0, 1.0, &mut points);
                }
            }
            Self::Capsule {
                half_length,
                radius,
            } => {
                let (l, r) = (*half_length, *radius);
                let rows = if l > 0.0 { count(2.0 * l) } else { 0 };
                let row_y = |i: usize| -l + 2.0 * l * (i as Real + 0.5) / rows as Real;
                if dim == 2 {
                    for i in 0..rows {
                        points.push(Vector::new(r, row_y(i), 0.0));
                        points.push(Vector::new(-r, row_y(i), 0.0));
                    }
                    let arc = count(PI * r);
                    for j in 0..arc {
                        let theta = PI * (j as Real + 0.5) / arc as Real;
                        let (s, c) = theta.sin_cos();
                        points.push(Vector::new(r * c, l + r * s, 0.0));
                        points.push(Vector::new(-r * c, -l - r * s, 0.0));
                    }
                } else {
                    for i in 0..rows {
                        ring(r, row_y(i), count(2.0 * PI * r), &mut points);
                    }
                    let n = count(2.0 * PI * r * r / spacing);
                    let mut cap = Vec::new();
                    fibonacci_cap(r, n, 0.0, 1.0, &mut cap);
                    for p in cap {
                        points.push(Vector::new(p.x, p.y + l, p.z));
                        points.push(Vector::new(-p.x, -p.y - l, p.z));
                    }
                }
            }
            Self::Plane { normal, offset } => {
                let centre = around - normal * (normal.dot(around) - offset);
                let n = (reach / spacing).ceil() as i64;
                if dim == 2 {
                    let t = Vector::new(-normal.y, normal.x, 0.0);
                    for i in -n..=n {
                        points.push(centre + t * (i as Real * spacing));
                    }
                } else {
                    let seed = if normal.x.abs() < 0.9 {
                        Vector::x()
                    } else {
                        Vector::y()
                    };
                    let t1 = normal.cross(&seed).normalize();
                    let t2 = normal.cross(&t1);
                    for i in -n..=n {
                        for j in -n..=n {
                            points.push(centre + (t1 * i as Real + t2 * j as Real) * spacing);
                        }
                    }
                }
            }
            Self::Mesh(solid) => points = solid.sample_surface(spacing).unwrap_or_default(),
        }
        points
    }
}

/// `n` points evenly around the circle of `radius` about the y axis, in
/// the plane `y = height`.
fn ring(radius: Real, height: Real, n: usize, out: &mut Vec<Vector>) {
    for k in 0..n {
        let (s, c) = (2.0 * PI * (k as Real + 0.5) / n as Real).sin_cos();
        out.push(Vector::new(radius * c, height, radius * s));
    }
}

/// `n` points evenly around the circle of `radius` in the plane z = 0.
fn circle(radius: Real, n: usize, out: &mut Vec<Vector>) {
    for k in 0..n {
        let (s, c) = (2.0 * PI * (k as Real + 0.5) / n as Real).sin_cos();
        out.push(Vector::new(radius * c, radius * s, 0.0));
    }
}

/// `n` points of a Fibonacci lattice on the zone `y_lo <= y / radius <=
/// y_hi` of the sphere of `radius` about the origin: equal area per point,
/// since a sphere's area is uniform in y (Archimedes' hat-box theorem).
fn fibonacci_cap(radius: Real, n: usize, y_lo: Real, y_hi: Real, out: &mut Vec<Vector>) {
    for k in 0..n {
        let y = y_lo + (y_hi - y_lo) * (k as Real + 0.5) / n as Real;
        let rho = (1.0 - y * y).max(0.0).sqrt();
        let (s, c) = (k as Real * GOLDEN_ANGLE).sin_cos();
        out.push(Vector::new(rho * c, y, rho * s) * radius);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box with sides of whole spacings is filled exactly; a ball, a
    /// capsule and a disc get their volume (area) over the cell size
    /// within the lattice's surface error; every point is inside; the
    /// plane and a bad spacing get none.
    #[test]
    fn volumes_fill_with_one_particle_per_cell() {
        let cube = Shape::Box {
            half_extents: Vector::new(0.1, 0.06, 0.2),
        };
        assert_eq!(
            cube.sample_volume(0.02, 3).map(|p| p.len()),
            Some(10 * 6 * 20)
        );
        assert_eq!(cube.sample_volume(0.02, 2).map(|p| p.len()), Some(10 * 6));
        let cases = [
            (Shape::Sphere { radius: 0.1 }, 3, 0.005),
            (
                Shape::Capsule {
                    half_length: 0.1,
                    radius: 0.05,
                },
                3,
                0.005,
            ),
            (Shape::Sphere { radius: 0.1 }, 2, 0.002),
        ];
        for (shape, dim, spacing) in cases {
            let points = shape.sample_volume(spacing, dim).expect("finite solid");
            let volume = shape.volume(dim).expect("finite solid");
            let filled = points.len() as Real * spacing.powi(dim as i32);
            assert!(
                (filled / volume - 1.0).abs() < 0.01,
                "{shape:?} in {dim}D: {filled} against {volume}"
            );
            assert!(points.iter().all(|p| shape.signed_distance(p, dim) < 0.0));
            assert!(dim == 3 || points.iter().all(|p| p.z == 0.0));
        }
        // A mesh fills through its signed distance: a 0.2 x 0.12 x 0.4 m
        // cuboid mesh like the box above, up to ties on its faces.
        let mesh = crate::geometry::TriMesh::cuboid(
            Vector::new(-0.1, -0.06, -0.2),
            Vector::new(0.1, 0.06, 0.2),
        );
        let solid = Shape::Mesh(MeshSolid::new(&mesh).expect("closed cuboid"));
        let count = solid.sample_volume(0.02, 3).expect("finite").len();
        assert_eq!(count, 10 * 6 * 20);
        let plane = Shape::Plane {
            normal: Vector::y(),
            offset: 0.0,
        };
        assert!(plane.sample_volume(0.1, 3).is_none());
        assert!(cube.sample_volume(0.0, 3).is_none());
        assert!(cube.sample_volume(Real::NAN, 3).is_none());
        assert!(
            cube.sample_volume(1e-6, 3).is_none(),
            "10^15 lattice points"
        );
    }

    fn shapes() -> Vec<Shape> {
        vec![
            Shape::Box {
                half_extents: Vector::new(0.1, 0.15, 0.2),
            },
            Shape::Sphere { radius: 0.12 },
            Shape::Capsule {
                half_length: 0.1,
                radius: 0.05,
            },
        ]
    }

    /// Samples lie on the surface (zero distance), and they are one
    /// roughly uniform layer: every sample's nearest other sample is
    /// between 0.4 and 1.5 spacings away.
    #[test]
    fn samples_lie_on_the_surface_about_a_spacing_apart() {
        let spacing = 0.01;
        for dim in [2, 3] {
            for shape in shapes() {
                let points = shape.sample_surface(spacing, dim, &Vector::zeros(), 0.0);
                assert!(points.len() > 10, "{shape:?}");
                for p in &points {
                    let d = shape.signed_distance(p, dim);
                    assert!(
                        d.abs() < 1e-9,
                        "{shape:?} {dim}D: sample {p:?} at distance {d}"
                    );
                    if dim == 2 {
                        assert_eq!(p.z, 0.0);
                    }
                }
                let (mut lo, mut hi) = (Real::INFINITY, 0.0 as Real);
                for (i, p) in points.iter().enumerate() {
                    let nearest = points
                        .iter()
                        .enumerate()
                        .filter(|&(j, _)| j != i)
                        .map(|(_, q)| (p - q).norm())
                        .fold(Real::INFINITY, Real::min);
                    lo = lo.min(nearest);
                    hi = hi.max(nearest);
                }
                assert!(
                    lo > 0.4 * spacing && hi < 1.5 * spacing,
                    "{shape:?} {dim}D: nearest-sample distances in [{lo}, {hi}]"
                );
            }
        }
    }

    /// Volume and inertia against midpoint quadrature of the indicator
    /// `signed_distance < 0` on a fine grid (an independent route to the
    /// closed forms): within 1 % in 2D and 2 % in 3D.
    #[test]
    fn volume_and_inertia_match_quadrature() {
        for dim in [2, 3] {
            // The staircase of the grid errs by about a cell over the
            // surface: 0.1 % in 2D, 1 % in 3D at these resolutions.
            let (n, tolerance) = if dim == 2 { (1000, 0.01) } else { (200, 0.02) };
            for shape in shapes() {
                let reach = shape.bounding_radius(dim);
                let cell = 2.0 * reach / n as Real;
                let nz = if dim == 2 { 1 } else { n };
                let (mut volume, mut moments) = (0.0, Vector::zeros());
                for k in 0..nz {
                    for j in 0..n {
                        for i in 0..n {
                            let at = |m: usize| -reach + (m as Real + 0.5) * cell;
                            let z = if dim == 2 { 0.0 } else { at(k) };
                            let p = Vector::new(at(i), at(j), z);
                            if shape.signed_distance(&p, dim) < 0.0 {
                                let dv = cell.powi(dim as i32);
                                volume += dv;
                                moments += Vector::new(
                                    p.y * p.y + p.z * p.z,
                                    p.x * p.x + p.z * p.z,
                                    p.x * p.x + p.y * p.y,
                                ) * dv;
                            }
                        }
                    }
                }
                let exact = shape.volume(dim).expect("bounded");
                assert!(
                    (volume - exact).abs() < tolerance * exact,
                    "{shape:?} {dim}D: volume {exact} against quadrature {volume}"
                );
                let inertia = shape.inertia(1.0, dim).expect("bounded");
                let axes = if dim == 2 { 2..3 } else { 0..3 };
                for a in axes {
                    assert!(
                        (inertia[a] - moments[a]).abs() < tolerance * moments[a],
                        "{shape:?} {dim}D axis {a}: inertia {} against quadrature {}",
                        inertia[a],
                        moments[a]
                    );
                }
            }
        }
    }

    /// Normals point out of the solid: stepping along one raises the
    /// signed distance at the rate 1 (it is a distance).
    #[test]
    fn normals_point_outward() {
        let mut seed = 3;
        for dim in [2, 3] {
            for shape in shapes() {
                for _ in 0..200 {
                    let p = Vector::from_fn(|a, _| {
                        if a == 2 && dim == 2 {
                            0.0
                        } else {
                            (crate::testing::uniform(&mut seed) - 0.5) * 0.5
                        }
                    });
                    let n = shape.normal(&p, dim);
                    let step = 1e-6;
                    let rate = (shape.signed_distance(&(p + n * step), dim)
                        - shape.signed_distance(&p, dim))
                        / step;
                    assert!(
                        (rate - 1.0).abs() < 1e-3,
                        "{shape:?} {dim}D at {p:?}: rate {rate}"
                    );
                }
            }
        }
        let plane = Shape::Plane {
            normal: Vector::y(),
            offset: 0.1,
        };
        assert!(plane.signed_distance(&Vector::zeros(), 3) < 0.0);
        let samples = plane.sample_surface(0.05, 3, &Vector::new(0.0, 5.0, 0.0), 0.2);
        assert_eq!(samples.len(), 81);
        assert!(samples.iter().all(|p| (p.y - 0.1).abs() < 1e-12));
    }
}
