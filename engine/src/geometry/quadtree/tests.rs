use super::*;

/// The unit square `[0, 1]^2` with a given conformal factor.
struct Square<F: Fn(Point2) -> Real>(F);

impl<F: Fn(Point2) -> Real> ChartDomain for Square<F> {
    fn distance(&self, u: Point2) -> Real {
        // Exact outside, a bound inside: the larger of the axes' signed
        // distances.
        let dx = (u[0] - 0.5).abs() - 0.5;
        let dy = (u[1] - 0.5).abs() - 0.5;
        let outside = (dx.max(0.0).powi(2) + dy.max(0.0).powi(2)).sqrt();
        if outside > 0.0 { outside } else { dx.max(dy) }
    }

    fn lambda(&self, u: Point2) -> Real {
        (self.0)(u)
    }
}

/// The disc of radius `r` about the origin, lambda = 1.
struct Disc(Real);

impl ChartDomain for Disc {
    fn distance(&self, u: Point2) -> Real {
        (u[0] * u[0] + u[1] * u[1]).sqrt() - self.0
    }

    fn lambda(&self, _: Point2) -> Real {
        1.0
    }
}

fn build(
    domain: &impl ChartDomain,
    lo: Point2,
    hi: Point2,
    params: &QuadtreeParams,
) -> Result<Quadtree, QuadtreeError> {
    Quadtree::build(domain, lo, hi, params, &Cancel::new())
}

/// No leaf has an edge or corner neighbour more than one level apart.
fn assert_balanced(tree: &Quadtree) {
    for &leaf in tree.leaves() {
        let (lo, side) = tree.bounds(leaf);
        let centre = [lo[0] + 0.5 * side, lo[1] + 0.5 * side];
        for (di, dj) in NEIGHBOURS {
            let probe = [
                centre[0] + di as Real * 0.75 * side,
                centre[1] + dj as Real * 0.75 * side,
            ];
            if let Some(other) = tree.leaf_of(probe) {
                let other = tree.leaves()[other];
                assert!(
                    other.level.abs_diff(leaf.level) <= 1,
                    "{leaf:?} beside {other:?}"
                );
            }
        }
    }
}

/// A uniform factor gives a uniform tree whose cells are the resolution
/// on the surface; its quadrature integrates the square's area and a
/// polynomial of the degree the rule is exact for.
#[test]
fn a_uniform_factor_gives_cells_of_the_resolution() {
    let square = Square(|_| 2.0);
    // lambda l <= 0.5 with lambda = 2: cells of 1/4.
    let tree = build(&square, [0.0, 0.0], [1.0, 1.0], &QuadtreeParams::new(0.5)).expect("builds");
    assert_eq!(tree.leaves().len(), 16);
    assert!(tree.leaves().iter().all(|c| c.level == 2));
    assert_eq!(tree.node(0), [0.125, 0.125]);
    assert!((tree.half_width(0) - 0.375).abs() < 1e-15);
    let area: Real = tree.gauss_points().iter().map(|g| g.weight).sum();
    assert!((area - 1.0).abs() < 1e-14, "{area}");
    // 4 x 4 Gauss points integrate x^6 y^2 exactly: 1/7 * 1/3.
    let moment: Real = tree
        .gauss_points()
        .iter()
        .map(|g| g.weight * g.at[0].powi(6) * g.at[1].powi(2))
        .sum();
    assert!((moment - 1.0 / 21.0).abs() < 1e-14, "{moment}");
    assert_eq!(tree.gauss_points().len(), 16 * 4 * 16);
}

/// A factor that grows across the chart grades the tree: every leaf is
/// at most the resolution on the surface, the tree is balanced, and each
/// leaf is no finer than the rule needs (its parent was too large).
#[test]
fn a_graded_factor_grades_the_tree_and_it_stays_balanced() {
    let lambda = |u: Point2| 1.0 + 15.0 * u[0] * u[0];
    let square = Square(lambda);
    let params = QuadtreeParams::new(0.1);
    let tree = build(&square, [0.0, 0.0], [1.0, 1.0], &params).expect("builds");
    let levels: Vec<u32> = tree.leaves().iter().map(|c| c.level).collect();
    let (min, max) = (levels.iter().min(), levels.iter().max());
    assert!(max > min, "graded: levels {min:?} to {max:?}");
    for &leaf in tree.leaves() {
        let size = tree.surface_size(&square, leaf);
        assert!(size <= params.resolution, "{leaf:?}: {size}");
    }
    assert_balanced(&tree);
    // Leaves on the left (lambda near 1) are coarser than on the right.
    let left = tree.leaves()[tree.leaf_of([0.05, 0.5]).expect("inside")];
    let right = tree.leaves()[tree.leaf_of([0.95, 0.5]).expect("inside")];
    assert!(left.level < right.level, "{left:?} against {right:?}");
}

/// With eta = 3 every Gauss point lies in at least three supports, and
/// `covering` finds exactly the supports holding a point (against a scan
/// of every node).
#[test]
fn every_point_lies_in_three_supports_and_the_lookup_finds_them_all() {
    let lambda = |u: Point2| 1.0 + 3.0 * u[0] * u[0];
    let square = Square(lambda);
    let tree = build(&square, [0.0, 0.0], [1.0, 1.0], &QuadtreeParams::new(0.2)).expect("builds");
    let levels: HashSet<u32> = tree.leaves().iter().map(|c| c.level).collect();
    assert!(levels.len() >= 2, "a graded tree: {levels:?}");
    let nodes = tree.nodes();
    let mut fewest = usize::MAX;
    for g in tree.gauss_points() {
        let found: Vec<u32> = tree.covering(g.at).collect();
        let scanned: Vec<u32> = (0..nodes.len() as u32)
            .filter(|&k| {
                let (x, h) = (nodes[k as usize], tree.half_width(k as usize));
                (g.at[0] - x[0]).abs() < h && (g.at[1] - x[1]).abs() < h
            })
            .collect();
        assert_eq!(found, scanned, "at {:?}", g.at);
        fewest = fewest.min(found.len());
    }
    assert!(fewest >= MIN_SUPPORTS, "{fewest}");
}

/// A curved domain keeps the cells its boundary crosses and drops the
/// Gauss points outside: the disc's area to the resolution, and nodes
/// at most a cell outside it.
#[test]
fn a_disc_is_covered_and_integrated_to_its_resolution() {
    let disc = Disc(1.0);
    for resolution in [0.1, 0.05] {
        let tree = build(
            &disc,
            [-1.0, -1.0],
            [1.0, 1.0],
            &QuadtreeParams::new(resolution),
        )
        .expect("builds");
        let area: Real = tree.gauss_points().iter().map(|g| g.weight).sum();
        let error = (area - std::f64::consts::PI).abs();
        // A band of cells along the boundary: at most its area.
        assert!(
            error < 2.0 * std::f64::consts::PI * resolution,
            "{resolution}: {error}"
        );
        for (k, node) in tree.nodes().iter().enumerate() {
            let side = tree.bounds(tree.leaves()[k]).1;
            assert!(disc.distance(*node) < side, "node {k} at {node:?}");
        }
        assert!(
            tree.gauss_points()
                .iter()
                .all(|g| disc.distance(g.at) <= 0.0)
        );
        assert_balanced(&tree);
    }
}

/// Narrow supports leave points under fewer than three, refused with
/// the point and what to change; bad parameters, boxes and domains are
/// refused, a too fine resolution before it fills memory, and a cancelled
/// build stops.
#[test]
fn bad_requests_are_refused_with_what_to_change() {
    let square = Square(|_| 1.0);
    let narrow = QuadtreeParams {
        eta: 1.2,
        ..QuadtreeParams::new(0.25)
    };
    let error = build(&square, [0.0, 0.0], [1.0, 1.0], &narrow).expect_err("refused");
    assert!(matches!(error, QuadtreeError::Uncovered { supports, .. } if supports < 3));
    assert!(error.to_string().contains("raise eta"), "{error}");

    for (params, what) in [
        (QuadtreeParams::new(-1.0), "resolution"),
        (QuadtreeParams::new(Real::NAN), "resolution"),
        (
            QuadtreeParams {
                eta: 0.5,
                ..QuadtreeParams::new(0.25)
            },
            "eta",
        ),
        (
            QuadtreeParams {
                gauss_order: 0,
                ..QuadtreeParams::new(0.25)
            },
            "gauss_order",
        ),
        (
            QuadtreeParams {
                subdivision: 0,
                ..QuadtreeParams::new(0.25)
            },
            "subdivision",
        ),
        (
            QuadtreeParams {
                max_depth: 99,
                ..QuadtreeParams::new(0.25)
            },
            "max_depth",
        ),
    ] {
        let error = build(&square, [0.0, 0.0], [1.0, 1.0], &params).expect_err("refused");
        assert!(error.to_string().contains(what), "{error}");
    }
    assert_eq!(
        build(&square, [0.0, 0.0], [0.0, 0.0], &QuadtreeParams::new(0.25)).expect_err("empty box"),
        QuadtreeError::BadBounds
    );
    assert_eq!(
        build(
            &Disc(-1.0),
            [-1.0, -1.0],
            [1.0, 1.0],
            &QuadtreeParams::new(0.25)
        )
        .expect_err("empty domain"),
        QuadtreeError::Empty
    );
    let fine = QuadtreeParams {
        max_depth: MAX_DEPTH,
        ..QuadtreeParams::new(1e-5)
    };
    assert!(matches!(
        build(&square, [0.0, 0.0], [1.0, 1.0], &fine).expect_err("too fine"),
        QuadtreeError::TooFine { .. }
    ));
    let cancel = Cancel::new();
    cancel.cancel();
    assert_eq!(
        Quadtree::build(
            &square,
            [0.0, 0.0],
            [1.0, 1.0],
            &QuadtreeParams::new(0.01),
            &cancel
        )
        .expect_err("cancelled"),
        QuadtreeError::Cancelled
    );
}
