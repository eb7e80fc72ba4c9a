//! Particles from meshes: points spread evenly over a surface (boundary
//! particles, as in Akinci et al., "Versatile rigid-fluid coupling for
//! incompressible SPH", ACM TOG 31(4), 2012, which corrects uneven spacing
//! through each particle's volume but still wants it roughly even) and
//! points of a cubic lattice filling a closed mesh (solids and fluid
//! blocks).

use super::topology::feature_edges;
use super::{MeshError, MeshSdf, TriMesh};
use crate::math::{Real, Vector};
use rayon::prelude::*;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// The most samples (or lattice points tried) one call may make: a
/// spacing far too small for the mesh is an error, not an abort.
pub const MAX_SAMPLES: usize = 50_000_000;

/// Minimum distance between surface samples, as a fraction of the spacing.
/// Random sequential addition of disks jams at a covered fraction of
/// 0.547 (Hinrichsen, Feder & Jøssang, J. Stat. Phys. 44, 1986), i.e.
/// 0.547 / (pi r^2 / 4) = 0.697 / r^2 points per area for minimum distance
/// `r`; `r = sqrt(0.697) h = 0.835 h` gives the `1 / h^2` of a square
/// lattice of spacing `h`.
const DISK_FRACTION: Real = 0.835;

/// Candidate points per `r^2` of area: dense enough that a maximal set of
/// them leaves no gap wider than about `r` (a candidate-free disk of
/// radius `r / 4` has odds of about `exp(-50 pi / 16) = 6e-5`).
const CANDIDATES_PER_DISK: Real = 50.0;

/// Edge candidates per `r` of length along sharp edges.
const EDGE_STEPS_PER_DISK: Real = 16.0;

/// Faces meeting at more than 30 degrees make a sharp edge, sampled first.
const SHARP_COS: Real = 0.866;

/// Points on `mesh` about `spacing` apart: no two closer than
/// `0.835 spacing`, every point of the surface within about that of a
/// sample, about `area / spacing^2` in all.
///
/// A Poisson-disk set by random sequential addition (dart throwing) from
/// dense candidates: first the corners (vertices with a number of sharp
/// edges other than two), then points along sharp edges (faces at more
/// than 30 degrees, boundary and non-manifold edges), then random points
/// over the triangles, triangles in random order; a candidate is kept
/// when no kept point is nearer than the minimum distance. Corners and
/// sharp edges are thus always covered, so a box's edges hold a row of
/// particles. The mesh need not be closed. Deterministic (fixed seed), serial.
///
/// # Errors
/// [`MeshError::InvalidSpacing`], [`MeshError::TooManySamples`], and the
/// errors of [`TriMesh::validate`].
pub fn sample_surface(mesh: &TriMesh, spacing: Real) -> Result<Vec<Vector>, MeshError> {
    check_spacing(spacing)?;
    mesh.validate()?;
    check_count(spacing, surface_candidates(mesh.area(), spacing))?;
    let mut disks = DiskSet::new(DISK_FRACTION * spacing);
    let mut rng = SplitMix(0x5EED);

    let sharp = feature_edges(mesh, SHARP_COS);
    let mut sharp_count = vec![0_u32; mesh.vertices.len()];
    for &(a, b) in &sharp {
        sharp_count[a as usize] += 1;
        sharp_count[b as usize] += 1;
    }
    for (v, &count) in sharp_count.iter().enumerate() {
        if count != 0 && count != 2 {
            disks.offer(mesh.vertices[v]);
        }
    }
    for &(a, b) in &sharp {
        let (a, b) = (mesh.vertices[a as usize], mesh.vertices[b as usize]);
        let steps = ((b - a).norm() / disks.radius * EDGE_STEPS_PER_DISK).ceil() as usize;
        for i in 0..=steps {
            disks.offer(a + (b - a) * (i as Real / steps.max(1) as Real));
        }
    }
    let mut order: Vec<usize> = (0..mesh.triangles.len()).collect();
    for i in (1..order.len()).rev() {
        order.swap(i, rng.below(i + 1));
    }
    let density = CANDIDATES_PER_DISK / disks.radius.powi(2);
    for t in order {
        let [a, b, c] = mesh.corners(t);
        let expected = 0.5 * (b - a).cross(&(c - a)).norm() * density;
        // Randomised rounding keeps the expected count exact on small triangles.
        let count = (expected + rng.unit()).floor() as usize;
        for _ in 0..count {
            // Uniform on the triangle (Osada et al., "Shape distributions",
            // ACM TOG 21(4), 2002, Eq. 1).
            let (r1, r2) = (rng.unit().sqrt(), rng.unit());
            disks.offer(a * (1.0 - r1) + b * (r1 * (1.0 - r2)) + c * (r1 * r2));
        }
    }
    Ok(disks.points)
}

/// Candidate points [`sample_surface`] draws for a surface of `area` at
/// `spacing` (it refuses more than [`MAX_SAMPLES`]); about
/// `72 area / spacing^2`, some 70 per sample it keeps.
pub fn surface_candidates(area: Real, spacing: Real) -> Real {
    CANDIDATES_PER_DISK * area / (DISK_FRACTION * spacing).powi(2)
}

/// The points of a cubic lattice of `spacing` that lie inside the closed
/// mesh of `sdf` (signed distance below zero). The lattice starts half a
/// spacing in from the mesh's bounding-box minimum, so each point is the
/// centre of a cube of side `spacing` and a box whose sides are multiples
/// of the spacing is filled exactly, `spacing / 2` from its walls; in
/// general the count times `spacing^3` is a midpoint-rule estimate of the
/// volume. Along each lattice row a point within the last query's
/// |distance| of it takes that query's sign, so a thick solid costs about
/// one query per surface crossing rather than one per point. Runs in
/// parallel (rayon); the order (x fastest, then y, then z) does not depend
/// on the thread count.
///
/// # Errors
/// [`MeshError::InvalidSpacing`], [`MeshError::TooManySamples`] when the
/// bounding box holds more than [`MAX_SAMPLES`] lattice points.
pub fn sample_volume(sdf: &MeshSdf, spacing: Real) -> Result<Vec<Vector>, MeshError> {
    check_spacing(spacing)?;
    let (min, max) = sdf.bounds();
    let counts = (max - min).map(|extent| (extent / spacing).ceil().max(1.0));
    let estimated = counts.product();
    check_count(spacing, estimated)?;
    let [nx, ny, nz] = [0, 1, 2].map(|a| counts[a] as usize);
    let origin = min + Vector::repeat(spacing / 2.0);
    Ok((0..ny * nz)
        .into_par_iter()
        .flat_map_iter(|row| {
            let (y, z) = (row % ny, row / ny);
            // The signed distance is 1-Lipschitz, so a point nearer to the
            // last queried one than that one's |distance| is on the same
            // side: deep inside, one query settles many points of the row.
            let mut last: Option<(Real, Real)> = None;
            (0..nx).filter_map(move |x| {
                let p = origin + Vector::new(x as Real, y as Real, z as Real) * spacing;
                let inside = match last {
                    Some((at, d)) if d.abs() > (p.x - at).abs() => d < 0.0,
                    _ => {
                        let d = sdf.distance(&p);
                        last = Some((p.x, d));
                        d < 0.0
                    }
                };
                inside.then_some(p)
            })
        })
        .collect())
}

fn check_spacing(spacing: Real) -> Result<(), MeshError> {
    if spacing.is_finite() && spacing > 0.0 {
        Ok(())
    } else {
        Err(MeshError::InvalidSpacing { spacing })
    }
}

/// Refuses work beyond [`MAX_SAMPLES`] (or a count that overflowed to NaN).
fn check_count(spacing: Real, estimated: Real) -> Result<(), MeshError> {
    if estimated.is_nan() || estimated > MAX_SAMPLES as Real {
        return Err(MeshError::TooManySamples {
            spacing,
            estimated,
            limit: MAX_SAMPLES,
        });
    }
    Ok(())
}

/// Accepted points with a hash grid of cell `radius`, so a candidate is
/// tested against the points of its 27 neighbouring cells only.
struct DiskSet {
    radius: Real,
    points: Vec<Vector>,
    cells: HashMap<(i64, i64, i64), Vec<u32>, BuildHasherDefault<CellHasher>>,
}

/// A multiply-rotate hash for grid cells: the keys are small integers the
/// program makes, so SipHash's defence against chosen keys buys nothing
/// and costs most of a candidate test.
#[derive(Debug, Default)]
struct CellHasher(u64);

impl Hasher for CellHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u64(&mut self, x: u64) {
        // An odd constant near 2^64 / golden ratio spreads the bits.
        self.0 = (self.0.rotate_left(26) ^ x).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }

    fn write_i64(&mut self, x: i64) {
        self.write_u64(x as u64);
    }
}

impl DiskSet {
    fn new(radius: Real) -> Self {
        DiskSet {
            radius,
            points: Vec::new(),
            cells: HashMap::default(),
        }
    }

    fn cell(&self, p: &Vector) -> (i64, i64, i64) {
        let [i, j, k] = [0, 1, 2].map(|a| (p[a] / self.radius).floor() as i64);
        (i, j, k)
    }

    /// Keeps `p` when no kept point is nearer than `radius`.
    fn offer(&mut self, p: Vector) {
        let (i, j, k) = self.cell(&p);
        let r2 = self.radius * self.radius;
        for di in -1..=1 {
            for dj in -1..=1 {
                for dk in -1..=1 {
                    if let Some(members) = self.cells.get(&(i + di, j + dj, k + dk))
                        && members
                            .iter()
                            .any(|&m| (self.points[m as usize] - p).norm_squared() < r2)
                    {
                        return;
                    }
                }
            }
        }
        self.cells
            .entry((i, j, k))
            .or_default()
            .push(self.points.len() as u32);
        self.points.push(p);
    }
}

/// SplitMix64 (Steele, Lea & Flood, OOPSLA 2014): a tiny seeded generator,
/// enough for shuffling and placing candidates.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    fn unit(&mut self) -> Real {
        (self.next() >> 11) as Real / (1_u64 << 53) as Real
    }

    /// Uniform in 0..n (n > 0), by multiply-shift.
    fn below(&mut self, n: usize) -> usize {
        ((self.next() as u128 * n as u128) >> 64) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::uniform;

    /// Distance from each point to its nearest other point (brute force).
    fn nearest_neighbour_distances(points: &[Vector]) -> Vec<Real> {
        points
            .par_iter()
            .enumerate()
            .map(|(i, p)| {
                points
                    .iter()
                    .enumerate()
                    .filter(|&(j, _)| j != i)
                    .map(|(_, q)| (p - q).norm())
                    .fold(Real::INFINITY, Real::min)
            })
            .collect()
    }

    fn cube() -> TriMesh {
        TriMesh::cuboid(-Vector::repeat(1.0), Vector::repeat(1.0))
    }

    /// The statistics the sampler promises, on a box (sharp edges and
    /// corners, two large triangles per face), a fine icosphere (triangles
    /// smaller than the spacing) and a coarse one (larger): about
    /// `area / h^2` points, nearest neighbours between `0.835 h` (the disk
    /// radius, exactly) and `1.5 h`, no surface point farther than `0.95 h`
    /// from a sample, and every sample on the surface.
    #[test]
    fn surface_samples_are_evenly_spread_on_boxes_and_spheres() {
        for (name, mesh, h) in [
            ("cube", cube(), 0.1),
            (
                "fine sphere",
                TriMesh::icosphere(Vector::zeros(), 1.0, 4),
                0.05,
            ),
            (
                "coarse sphere",
                TriMesh::icosphere(Vector::zeros(), 1.0, 1),
                0.05,
            ),
        ] {
            let points = sample_surface(&mesh, h).expect("samples");
            let nn = nearest_neighbour_distances(&points);
            let min = nn.iter().copied().fold(Real::INFINITY, Real::min) / h;
            let max = nn.iter().copied().fold(0.0, Real::max) / h;
            let mean = nn.iter().sum::<Real>() / nn.len() as Real / h;
            let ratio = points.len() as Real * h * h / mesh.area();
            let sdf = MeshSdf::new(&mesh).expect("closed");
            let mut seed = 1;
            let mut gap: Real = 0.0;
            for _ in 0..1000 {
                let q = Vector::from_fn(|_, _| 4.0 * uniform(&mut seed) - 2.0);
                let s = sdf.closest(&q).point;
                let nearest = points
                    .iter()
                    .map(|p| (p - s).norm())
                    .fold(Real::INFINITY, Real::min);
                gap = gap.max(nearest / h);
            }
            let report = format!(
                "{name}: {} points, {ratio:.3} area/h^2, nearest neighbour {min:.3}..{max:.3} \
                 (mean {mean:.3}) h, largest gap {gap:.3} h",
                points.len()
            );
            eprintln!("{report}");
            assert!((0.9..1.1).contains(&ratio), "{report}");
            assert!(
                min >= DISK_FRACTION * (1.0 - 1e-12) && max <= 1.5,
                "{report}"
            );
            assert!((0.85..0.95).contains(&mean), "{report}");
            assert!(gap <= 0.95, "{report}");
            assert!(
                points.iter().all(|p| sdf.distance(p).abs() < 1e-12),
                "{name}: off the surface"
            );
        }
    }

    /// Every corner of a box gets a particle and its six faces get equal
    /// shares; an open box (no lid) samples too, its rim corners included.
    #[test]
    fn box_corners_are_sampled_and_faces_share_evenly() {
        let h = 0.1;
        let points = sample_surface(&cube(), h).expect("samples");
        for corner in cube().vertices {
            assert!(points.contains(&corner), "corner {corner:?} not sampled");
        }
        let mut per_face = [0_usize; 6];
        for p in &points {
            let on: Vec<usize> = (0..3)
                .filter(|&a| (p[a].abs() - 1.0).abs() < 1e-12)
                .collect();
            if let [a] = on[..] {
                per_face[2 * a + usize::from(p[a] > 0.0)] += 1;
            }
        }
        let mean = per_face.iter().sum::<usize>() as Real / 6.0;
        for count in per_face {
            assert!((count as Real - mean).abs() < 0.05 * mean, "{per_face:?}");
        }

        let mut open = cube();
        open.triangles
            .retain(|t| !t.iter().all(|&v| open.vertices[v as usize].z > 0.0));
        assert_eq!(open.edge_report().boundary, 4);
        let points = sample_surface(&open, h).expect("open meshes sample");
        let ratio = points.len() as Real * h * h / open.area();
        assert!((0.9..1.1).contains(&ratio), "open box: {ratio}");
        for corner in open.vertices.iter().filter(|v| v.z > 0.0) {
            assert!(points.contains(corner), "rim corner {corner:?} not sampled");
        }
    }

    #[test]
    fn bad_spacings_and_meshes_are_errors() {
        let sdf = MeshSdf::new(&cube()).expect("closed");
        for spacing in [0.0, -0.1, Real::NAN, Real::INFINITY] {
            let expected = MeshError::InvalidSpacing { spacing };
            let same = |e: MeshError| e.to_string() == expected.to_string();
            assert!(sample_surface(&cube(), spacing).is_err_and(same));
            assert!(sample_volume(&sdf, spacing).is_err_and(same));
        }
        let err = sample_surface(&cube(), 1e-5).expect_err("too fine");
        assert!(matches!(err, MeshError::TooManySamples { .. }), "{err}");
        let err = sample_volume(&sdf, 1e-4).expect_err("too fine");
        assert!(err.to_string().contains("raise the spacing"), "{err}");
        let mut bad = cube();
        bad.triangles[0][1] = 8;
        assert!(matches!(
            sample_surface(&bad, 0.1),
            Err(MeshError::BadTriangle { .. })
        ));
    }

    /// Lattice counts are exact where the box's sides fit the lattice
    /// (`floor(L / h + 1/2)` points per side) and within 1% of
    /// `volume / h^3` for a sphere; every point is inside, on the lattice,
    /// and the result does not depend on the thread count.
    #[test]
    fn volume_samples_fill_boxes_exactly_and_spheres_by_volume() {
        let h = 0.1;
        let sdf = MeshSdf::new(&cube()).expect("closed");
        assert_eq!(sample_volume(&sdf, h).expect("fill").len(), 20 * 20 * 20);

        let slab = MeshSdf::new(&TriMesh::cuboid(
            Vector::zeros(),
            Vector::new(1.0, 0.57, 0.3),
        ))
        .expect("closed");
        let points = sample_volume(&slab, h).expect("fill");
        assert_eq!(points.len(), 10 * 6 * 3);
        assert!(points.iter().all(|p| p.min() > 0.049 && p.x < 0.951));

        let h = 0.05;
        let sphere =
            MeshSdf::new(&TriMesh::icosphere(Vector::new(0.3, 0.0, 0.1), 1.0, 4)).expect("closed");
        let points = sample_volume(&sphere, h).expect("fill");
        let volume = sphere.mesh().signed_volume();
        let error = (points.len() as Real * h.powi(3) - volume) / volume;
        eprintln!(
            "sphere fill: {} points, volume error {error:.5}",
            points.len()
        );
        assert!(error.abs() < 0.01, "volume error {error}");
        let origin = sphere.bounds().0 + Vector::repeat(h / 2.0);
        for p in &points {
            assert!(sphere.distance(p) < 0.0);
            let cell = (p - origin) / h;
            assert!(
                (cell - cell.map(Real::round)).norm() < 1e-9,
                "{p:?} off the lattice"
            );
        }
        let serial = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool")
            .install(|| sample_volume(&sphere, h))
            .expect("fill");
        assert_eq!(serial, points);
    }
}
