//! Every candidate search, through [`NeighborList::build`], must find
//! exactly the neighbours a brute-force scan finds: on uniform points, on
//! strongly varying density, outside the grid's box and with coincident
//! points, in 3D and in 2D layouts (z = 0).

use super::*;
use crate::math::Real;
use crate::testing::uniform;

/// Sorted neighbours of every particle by an O(n^2) scan.
fn brute_force(positions: &[Vector], radius: Real) -> Vec<Vec<u32>> {
    let r2 = radius * radius;
    (0..positions.len())
        .map(|i| {
            (0..positions.len())
                .filter(|&j| (positions[j] - positions[i]).norm_squared() < r2)
                .map(|j| j as u32)
                .collect()
        })
        .collect()
}

/// Builds the list with `search` and compares it, sorted, to `expected`.
fn check<S: CandidateSearch>(
    search: &mut S,
    positions: &[Vector],
    radius: Real,
    expected: &[Vec<u32>],
    label: &str,
) {
    search.rebuild(positions);
    let mut list = NeighborList::default();
    list.build(search, positions, radius);
    assert_eq!(list.len(), positions.len(), "{label}");
    for (i, want) in expected.iter().enumerate() {
        let mut found = list.of(i).to_vec();
        found.sort_unstable();
        assert_eq!(&found, want, "{label}: particle {i}");
    }
}

/// Runs all variants on one case. The grid covers `[min, max]`, which may
/// leave particles outside it. Each search is rebuilt twice, the second
/// time on a prefix, to exercise buffer reuse across particle counts.
fn check_all(positions: &[Vector], radius: Real, min: Vector, max: Vector, case: &str) {
    let prefix = &positions[..positions.len() / 2];
    let (expected, expected_prefix) = (brute_force(positions, radius), brute_force(prefix, radius));
    let mut grid = UniformGrid::new(min, max, radius).expect("small grid");
    let mut hash_r = SpatialHash::new(radius, HashCell::Radius);
    let mut hash_2r = SpatialHash::new(radius, HashCell::TwiceRadius);
    let mut tree = KdTree::new(radius);
    for (points, want) in [(positions, &expected), (prefix, &expected_prefix)] {
        let n = points.len();
        check(
            &mut grid,
            points,
            radius,
            want,
            &format!("{case} n={n} grid"),
        );
        check(
            &mut hash_r,
            points,
            radius,
            want,
            &format!("{case} n={n} hash r"),
        );
        check(
            &mut hash_2r,
            points,
            radius,
            want,
            &format!("{case} n={n} hash 2r"),
        );
        check(
            &mut tree,
            points,
            radius,
            want,
            &format!("{case} n={n} kd-tree"),
        );
    }
}

/// A random point in `[min, max]`, with z = 0 when `flat`.
fn point(seed: &mut u64, min: Vector, max: Vector, flat: bool) -> Vector {
    let mut p = min;
    for a in 0..3 {
        p[a] += (max[a] - min[a]) * uniform(seed);
    }
    if flat {
        p.z = 0.0;
    }
    p
}

/// A radius giving about `neighbours` neighbours at `n` points per unit
/// volume (or area when `flat`).
fn radius_for(n: usize, neighbours: Real, flat: bool) -> Real {
    if flat {
        (neighbours / (std::f64::consts::PI * n as Real)).sqrt()
    } else {
        (neighbours / (4.0 / 3.0 * std::f64::consts::PI * n as Real)).cbrt()
    }
}

#[test]
fn uniform_points_match_brute_force() {
    for flat in [false, true] {
        for (n, seed) in [(50, 1), (700, 2), (3000, 3)] {
            let mut seed = seed;
            let (min, max) = (Vector::zeros(), Vector::repeat(1.0));
            let positions: Vec<Vector> = (0..n).map(|_| point(&mut seed, min, max, flat)).collect();
            let radius = radius_for(n, 30.0, flat);
            check_all(
                &positions,
                radius,
                min,
                max,
                &format!("uniform flat={flat}"),
            );
        }
    }
}

/// A dense clump of thousands of points (hundreds of neighbours each) in a
/// sparse box 27 000 times its volume; the second radius links the
/// sparse points and makes the whole clump one neighbourhood.
#[test]
fn varying_density_matches_brute_force() {
    for flat in [false, true] {
        for (clump, sparse, radius, seed) in [
            (1000, 300, 0.05, 11),
            (3000, 500, 0.04, 12),
            (800, 400, 1.2, 13),
        ] {
            let mut seed = seed;
            let (min, max) = (Vector::zeros(), Vector::repeat(6.0));
            let centre = Vector::new(2.0, 3.0, 4.0);
            let mut positions: Vec<Vector> = (0..clump)
                .map(|_| point(&mut seed, centre, centre + Vector::repeat(0.2), flat))
                .collect();
            positions.extend((0..sparse).map(|_| point(&mut seed, min, max, flat)));
            check_all(
                &positions,
                radius,
                min,
                max,
                &format!("clump flat={flat} r={radius}"),
            );
        }
    }
}

/// Points up to a box size outside the grid's box on every side, and far
/// away (1e4 boxes): the grid clamps them into its border cells, the
/// hash and the tree do not care.
#[test]
fn points_outside_the_grid_match_brute_force() {
    for flat in [false, true] {
        for (n, seed) in [(400, 21), (2500, 22)] {
            let mut seed = seed;
            let (min, max) = (Vector::new(0.0, 0.0, 0.0), Vector::new(1.0, 0.5, 0.7));
            let mut positions: Vec<Vector> = (0..n)
                .map(|_| {
                    point(
                        &mut seed,
                        min - Vector::repeat(1.0),
                        max + Vector::repeat(1.0),
                        flat,
                    )
                })
                .collect();
            positions.push(Vector::new(-1e4, 2e4, 0.0));
            positions.push(Vector::new(-1e4, 2e4, 0.0) + Vector::new(0.01, 0.0, 0.0));
            let radius = 0.1;
            check_all(
                &positions,
                radius,
                min,
                max,
                &format!("outside flat={flat}"),
            );
        }
    }
}

/// Groups of identical points (more than a kd-tree leaf holds) among
/// random ones, including one at the origin and on cell boundaries.
#[test]
fn coincident_points_match_brute_force() {
    for flat in [false, true] {
        for (n, copies, seed) in [(200, 5, 31), (1500, 40, 32)] {
            let mut seed = seed;
            let (min, max) = (Vector::zeros(), Vector::repeat(1.0));
            let radius = 0.1;
            let mut positions: Vec<Vector> =
                (0..n).map(|_| point(&mut seed, min, max, flat)).collect();
            let z = if flat { 0.0 } else { 0.3 };
            for site in [
                Vector::zeros(),
                Vector::new(0.5, 0.5, z),
                Vector::new(0.2, 0.3, z),
            ] {
                positions.extend(std::iter::repeat_n(site, copies));
            }
            check_all(
                &positions,
                radius,
                min,
                max,
                &format!("coincident flat={flat}"),
            );
        }
    }
}

/// A 2D lattice with spacing exactly r / 2: many neighbours lie exactly at
/// distance r (excluded) or just inside it, and on cell boundaries.
#[test]
fn lattice_on_cell_boundaries_matches_brute_force() {
    let radius = 0.1;
    let positions: Vec<Vector> = (0..40)
        .flat_map(|i| (0..40).map(move |j| Vector::new(i as Real * 0.05, j as Real * 0.05, 0.0)))
        .collect();
    check_all(
        &positions,
        radius,
        Vector::zeros(),
        Vector::new(2.0, 2.0, 0.0),
        "lattice",
    );
}
