use super::*;
use crate::geometry::{Ball, MeshSdf, TriMesh};

fn params(cell: Real, interior_levels: u32) -> OctreeParams {
    OctreeParams {
        cell,
        interior_levels,
        alpha: 3.0,
    }
}

fn beam() -> MeshSdf {
    MeshSdf::new(&TriMesh::cuboid(
        Vector::zeros(),
        Vector::new(27.0, 5.0, 5.0),
    ))
    .expect("closed box")
}

#[test]
fn a_box_on_the_cell_grid_has_its_nodes_on_its_faces() {
    // Guo–Qin Table 1's beam: 28 x 6 x 6 = 1,008 nodes.
    let tree = Octree::build(&beam(), &params(1.0, 0), &Cancel::new()).expect("octree");
    assert_eq!(tree.nodes().len(), 1008);
    let [interior, _, ib, eb] = tree.census();
    // The nodes of the outer layer lie on the faces, in octants half in
    // the solid (IB, their centres on the surface).
    assert_eq!(interior, 26 * 4 * 4);
    assert_eq!((ib, eb), (1008 - interior, 0));
    for node in tree.nodes() {
        assert_eq!(node.half_width, 1.5);
        assert_eq!(node.position.map(|v| v.fract()), Vector::zeros());
    }
}

#[test]
fn a_ball_has_boundary_octants_and_projected_nodes() {
    let ball = Ball {
        centre: Vector::new(0.1, -0.2, 0.3),
        radius: 1.0,
    };
    let tree = Octree::build(&ball, &params(0.125, 2), &Cancel::new()).expect("octree");
    let [interior, _, ib, eb] = tree.census();
    assert!(interior > 0 && ib > 0 && eb > 0, "{:?}", tree.census());
    for node in tree.nodes() {
        assert!(ball.signed_distance(&node.position) <= 1e-12);
        let leaf = tree.leaves()[node.octant as usize];
        if leaf.kind == OctantKind::ExteriorBoundary {
            assert!(ball.signed_distance(&node.position).abs() < 1e-12);
        }
    }
    // The interior is coarser than the surface: fewer nodes than uniform.
    let uniform = Octree::build(&ball, &params(0.125, 0), &Cancel::new()).expect("octree");
    assert!(tree.nodes().len() < uniform.nodes().len());
}

#[test]
fn leaves_sharing_a_face_or_an_edge_differ_by_at_most_one_level() {
    let ball = Ball {
        centre: Vector::zeros(),
        radius: 1.0,
    };
    let tree = Octree::build(&ball, &params(0.0625, 4), &Cancel::new()).expect("octree");
    let levels: std::collections::BTreeSet<u32> = tree.leaves().iter().map(|l| l.level).collect();
    assert!(levels.len() >= 3, "the tree is graded: {levels:?}");
    for leaf in tree.leaves() {
        if leaf.kind == OctantKind::Exterior {
            continue;
        }
        // Probe just past each face and edge midpoint.
        for offset in FACE_AND_EDGE_OFFSETS {
            let probe = leaf.centre()
                + Vector::new(offset[0] as Real, offset[1] as Real, offset[2] as Real)
                    * (0.5 * leaf.size + 1e-9);
            let Some(j) = tree.leaf_at(&probe) else {
                continue;
            };
            let neighbour = tree.leaves()[j as usize];
            if neighbour.kind != OctantKind::Exterior {
                assert!(
                    leaf.level.abs_diff(neighbour.level) <= 1,
                    "levels {} and {}",
                    leaf.level,
                    neighbour.level
                );
            }
        }
    }
}

#[test]
fn the_candidate_lists_hold_every_covering_support() {
    let ball = Ball {
        centre: Vector::zeros(),
        radius: 1.0,
    };
    let tree = Octree::build(&ball, &params(0.125, 2), &Cancel::new()).expect("octree");
    let mut seed = 7;
    let mut checked = 0;
    while checked < 400 {
        let p = Vector::from_fn(|_, _| 2.0 * crate::testing::uniform(&mut seed) - 1.0);
        if !ball.contains(&p) {
            continue;
        }
        checked += 1;
        let leaf = tree.leaf_at(&p).expect("inside the root");
        let listed = tree.candidates(leaf);
        let mut covering = 0;
        for (n, node) in tree.nodes().iter().enumerate() {
            let inside = (p - node.position).amax() < node.half_width;
            if inside {
                covering += 1;
                assert!(listed.contains(&(n as u32)), "node {n} missing at {p:?}");
            }
        }
        assert!(covering >= 4, "{covering} supports at {p:?}");
    }
}

#[test]
fn bad_parameters_and_too_fine_trees_are_refused() {
    let sdf = beam();
    let cancel = Cancel::new();
    for bad in [0.0, -1.0, Real::NAN] {
        assert!(matches!(
            Octree::build(&sdf, &params(bad, 0), &cancel),
            Err(OctreeError::InvalidParameter { field: "cell", .. })
        ));
    }
    let mut p = params(1.0, 0);
    p.alpha = 0.5;
    assert!(matches!(
        Octree::build(&sdf, &p, &cancel),
        Err(OctreeError::InvalidParameter { field: "alpha", .. })
    ));
    let err = Octree::build(&sdf, &params(1e-9, 0), &cancel).expect_err("too fine");
    assert!(matches!(err, OctreeError::TooFine { .. }), "{err}");
    assert!(err.to_string().contains("use a larger cell"));
    // A ball well inside one cell, off its centre, has no node.
    let speck = Ball {
        centre: Vector::repeat(0.1),
        radius: 0.1,
    };
    let err = Octree::build(&speck, &params(1.0, 0), &cancel).expect_err("no node");
    assert!(matches!(err, OctreeError::Empty { .. }), "{err}");
}

#[test]
fn a_cancelled_build_stops() {
    let cancel = Cancel::new();
    cancel.cancel();
    assert_eq!(
        Octree::build(&beam(), &params(0.25, 0), &cancel).expect_err("cancelled"),
        OctreeError::Cancelled
    );
}

/// A point of the solid on the face between an exterior octant (above it)
/// and a non-exterior one (below) is given the non-exterior one, whose
/// candidates cover it; it was given the exterior one, with none.
///
/// The ball's top pokes 2e-4 through a face plane of the grid (the origin
/// is its lowest point less half a cell, so its top lies `cell / 2 + 2 R`
/// above the origin: 15.5 cells and 2e-4), between the face's corners
/// (the cap is 0.02 wide, the corners 0.03 away): the octant above has
/// no corner or centre inside, so it is exterior.
#[test]
fn a_point_on_a_face_shared_with_an_exterior_octant_finds_its_supports() {
    let cell = 0.125;
    let ball = Ball {
        centre: Vector::new(0.013, -0.021, 0.007),
        radius: (15.5 * cell + 2e-4) / 2.0,
    };
    let tree = Octree::build(&ball, &params(cell, 2), &Cancel::new()).expect("octree");
    // On each exterior leaf's lower faces, the point nearest the centre:
    // where it lies in the ball, the ball crosses that face.
    let mut found = 0;
    for (e, leaf) in tree.leaves().iter().enumerate() {
        if leaf.kind != OctantKind::Exterior {
            continue;
        }
        for k in 0..3 {
            let mut p = ball
                .centre
                .sup(&leaf.min)
                .inf(&(leaf.min + Vector::repeat(leaf.size)));
            p[k] = leaf.min[k];
            let below = p - Vector::ith(k, 1e-9 * leaf.size);
            if ball.signed_distance(&p) > 0.0
                || tree
                    .leaf_at(&below)
                    .is_none_or(|b| tree.leaves()[b as usize].kind == OctantKind::Exterior)
            {
                continue;
            }
            found += 1;
            let at = tree.leaf_at(&p).expect("in the tree");
            assert_ne!(at as usize, e, "{p:?} on exterior leaf {e}'s face");
            assert_ne!(
                tree.leaves()[at as usize].kind,
                OctantKind::Exterior,
                "{p:?}"
            );
            assert!(!tree.candidates(at).is_empty(), "{p:?}");
        }
    }
    println!("{found} points of the ball on faces of exterior octants");
    assert!(found > 0, "the ball crosses a face of an exterior octant");
}
