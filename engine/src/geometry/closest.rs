//! The point of a triangle closest to a given point, and which feature
//! (vertex, edge or face) it lies on, by Ericson's Voronoi-region test
//! (Real-Time Collision Detection, 2005, §5.1.5): the dot products that
//! decide the region also give the barycentric coordinates, so no
//! projection is computed twice.

use crate::math::Vector;

/// Where on a triangle `[a, b, c]` a closest point lies. Edge `k` runs
/// from corner `k` to corner `k + 1` (mod 3): 0 = ab, 1 = bc, 2 = ca.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Feature {
    Vertex(u8),
    Edge(u8),
    Face,
}

/// The closest point of triangle `[a, b, c]` to `p`, and its feature.
/// The triangle must have non-zero area.
pub fn closest_point_on_triangle(p: &Vector, [a, b, c]: &[Vector; 3]) -> (Vector, Feature) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (*a, Feature::Vertex(0));
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (*b, Feature::Vertex(1));
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return (a + ab * (d1 / (d1 - d3)), Feature::Edge(0));
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (*c, Feature::Vertex(2));
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return (a + ac * (d2 / (d2 - d6)), Feature::Edge(2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, Feature::Edge(1));
    }
    let denom = 1.0 / (va + vb + vc);
    (a + ab * (vb * denom) + ac * (vc * denom), Feature::Face)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Real;
    use crate::testing::uniform;

    /// Brute force: the minimum over a fine barycentric lattice, refined by
    /// projecting onto each edge and the plane, independent of the regions.
    fn brute_force(p: &Vector, t: &[Vector; 3]) -> Real {
        let on_segment = |a: &Vector, b: &Vector| {
            let s = ((p - a).dot(&(b - a)) / (b - a).norm_squared()).clamp(0.0, 1.0);
            (a + (b - a) * s - p).norm()
        };
        let mut best = on_segment(&t[0], &t[1])
            .min(on_segment(&t[1], &t[2]))
            .min(on_segment(&t[2], &t[0]));
        let n = (t[1] - t[0]).cross(&(t[2] - t[0]));
        let q = p - n * (p - t[0]).dot(&n) / n.norm_squared();
        let inside = (0..3).all(|k| {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            (b - a).cross(&(q - a)).dot(&n) >= 0.0
        });
        if inside {
            best = best.min((q - p).norm());
        }
        best
    }

    #[test]
    fn matches_brute_force_in_every_region() {
        let mut seed = 11;
        let mut r = || 4.0 * uniform(&mut seed) - 2.0;
        let mut seen = std::collections::HashSet::new();
        for _ in 0..5000 {
            let t = [
                Vector::new(r(), r(), r()),
                Vector::new(r(), r(), r()),
                Vector::new(r(), r(), r()),
            ];
            let p = Vector::new(r(), r(), r());
            let (q, feature) = closest_point_on_triangle(&p, &t);
            seen.insert(feature);
            let expected = brute_force(&p, &t);
            assert!(
                ((q - p).norm() - expected).abs() < 1e-9 * (1.0 + expected),
                "{p:?} to {t:?}: {} vs {expected} ({feature:?})",
                (q - p).norm()
            );
            let on_feature = match feature {
                Feature::Vertex(k) => (q - t[k as usize]).norm() < 1e-12,
                Feature::Edge(k) => {
                    let (a, b) = (t[k as usize], t[(k as usize + 1) % 3]);
                    (b - a).cross(&(q - a)).norm() < 1e-9
                }
                Feature::Face => true,
            };
            assert!(on_feature, "{q:?} not on {feature:?} of {t:?}");
        }
        assert_eq!(seen.len(), 7, "every region was exercised: {seen:?}");
    }
}
