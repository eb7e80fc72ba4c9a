//! A modal solid's precompute under a host's limits: the estimate made
//! from the octree bounds what real builds hold, a refused estimate ends
//! the build before anything that grows with the octree is allocated,
//! and a cancel flag raised inside the long loops (quadrature, shape
//! functions, assembly) stops the build there.

use super::super::*;
use crate::cancel::Cancel;
use crate::geometry::octree::{Octree, OctreeParams};
use crate::geometry::{ImplicitSurface, MeshSdf, TriMesh};
use crate::math::{Real, Vector};
use crate::modal::{Damping, Stabilization};
use std::sync::Mutex;

fn material() -> Material {
    Material {
        density: 1000.0,
        young: 1e6,
        poisson: 0.3,
    }
}

fn params(efg: EfgParams, modes: usize) -> ModalParams {
    ModalParams {
        dynamics: Dynamics::Modal,
        efg,
        modes,
        tolerance: 1e-8,
        warping: true,
        damping: Damping::new(0.0, 0.0).expect("no damping"),
        stabilization: Stabilization::new(20.0, 20.0).expect("stabilisation"),
    }
}

/// A closed mesh as the implicit surface, its skin and, when `clamped`,
/// its surface in the plane `x = min.x` held.
fn model(mesh: TriMesh, clamped: bool) -> (MeshSdf, FixedSurface, SkinInput) {
    let sdf = MeshSdf::new(&mesh).expect("closed");
    let (min, max) = sdf.bounds();
    let fixed = if clamped {
        let slab = Vector::new(min.x + 1e-9, max.y + 1e-9, max.z + 1e-9);
        FixedSurface::of_mesh_in_box(&mesh, &(min - Vector::repeat(1e-9)), &slab)
    } else {
        FixedSurface::default()
    };
    let skin = SkinInput {
        normals: vec![Vector::zeros(); mesh.vertices.len()],
        vertices: mesh.vertices,
        triangles: mesh.triangles,
    };
    (sdf, fixed, skin)
}

/// Builds the solid and returns it with the estimate its build made.
fn built(
    (surface, fixed, skin): &(MeshSdf, FixedSurface, SkinInput),
    params: &ModalParams,
) -> (ModalSolid, Estimate) {
    let seen = Mutex::new(None);
    let solid = ModalSolid::build_admitted(
        surface,
        fixed,
        material(),
        params,
        Some(skin.clone()),
        &Cancel::new(),
        &|estimate| {
            *seen.lock().expect("not poisoned") = Some(*estimate);
            Ok(())
        },
    )
    .expect("the solid builds");
    let estimate = seen.lock().expect("not poisoned").expect("admit was asked");
    (solid, estimate)
}

/// The estimate is an upper bound on every count it makes and on the
/// bytes the built solid holds by its own count
/// ([`ModalSolid::bytes`]), and within a small factor of them, on a
/// clamped beam, a free ball with refined boundary cells, and a block
/// with coarser interior octants.
#[test]
fn the_estimate_bounds_what_real_builds_hold() {
    let beam = model(
        TriMesh::cuboid(Vector::zeros(), Vector::new(0.6, 0.1, 0.1)).subdivided(3),
        true,
    );
    let ball = model(TriMesh::icosphere(Vector::zeros(), 0.2, 3), false);
    let block = model(
        TriMesh::cuboid(Vector::zeros(), Vector::new(0.32, 0.32, 0.16)).subdivided(2),
        true,
    );
    let mut fine_ball = EfgParams::new(0.05);
    fine_ball.boundary_refinement = 2;
    let mut coarse_inside = EfgParams::new(0.02);
    coarse_inside.interior_levels = 1;
    for (name, model, params) in [
        ("beam", &beam, params(EfgParams::new(0.025), 12)),
        ("ball", &ball, params(fine_ball, 8)),
        ("block", &block, params(coarse_inside, 10)),
    ] {
        let (solid, estimate) = built(model, &params);
        let efg = solid.efg();
        let blocks = efg.stiffness().len() / 9;
        println!(
            "{name}: {} nodes, points {} <= {}, entries {} <= {}, blocks {blocks} <= {}, \
             bytes {} <= {}",
            solid.len(),
            efg.quadrature_points(),
            estimate.quadrature_points,
            efg.shape_entries(),
            estimate.shape_entries,
            estimate.blocks,
            solid.bytes(),
            estimate.bytes
        );
        assert_eq!(estimate.nodes, solid.len(), "{name}: the octree's nodes");
        assert!(
            estimate.quadrature_points >= efg.quadrature_points(),
            "{name}: quadrature points"
        );
        assert!(
            estimate.shape_entries >= efg.shape_entries(),
            "{name}: shape entries"
        );
        assert!(estimate.blocks >= blocks, "{name}: blocks of M and K");
        let held = solid.bytes() as Real;
        let bound = estimate.bytes as Real;
        assert!(
            bound >= held,
            "{name}: estimate {bound} below the held {held}"
        );
        // The bound counts the rows a table holds while it is packed
        // (twice the entries), and every Gauss point of a boundary octant
        // as if inside: the ball, four cells across its radius with
        // boundary cells cut twice finer, is mostly boundary (7.7 times).
        assert!(
            bound <= 10.0 * held,
            "{name}: estimate {bound} more than 10 times the held {held}"
        );
    }
}

/// A host that refuses the estimate ends the build right after the
/// octree, with the estimate in the message and what to change.
#[test]
fn a_refused_estimate_ends_the_build_after_the_octree() {
    let (surface, fixed, skin) = model(
        TriMesh::cuboid(Vector::zeros(), Vector::new(0.6, 0.1, 0.1)),
        true,
    );
    let err = ModalSolid::build_admitted(
        &surface,
        &fixed,
        material(),
        &params(EfgParams::new(0.025), 12),
        Some(skin),
        &Cancel::new(),
        &|_| Err("the host has 1 MB left".into()),
    )
    .expect_err("refused");
    assert!(matches!(err, EfgError::Refused { .. }), "{err:?}");
    let message = err.to_string();
    for part in ["MB by its estimate", "the host has 1 MB left", "`cell`"] {
        assert!(message.contains(part), "{part:?} in {message}");
    }
}

/// Reads of the cancel flag that the octree of `surface` makes.
fn octree_reads(surface: &dyn ImplicitSurface, efg: &EfgParams) -> (usize, usize) {
    let counting = Cancel::raised_at_read(usize::MAX);
    let octree = Octree::build(
        surface,
        &OctreeParams {
            cell: efg.cell,
            interior_levels: efg.interior_levels,
            alpha: efg.alpha,
        },
        &counting,
    )
    .expect("octree");
    (counting.reads(), octree.leaves().len())
}

/// A flag raised a few points into the shape-function table, or a few
/// columns into the assembly, stops the build there: it returns
/// cancelled (before, the build read its flag only between stages, so a
/// flag first raised after the octree went unseen until the
/// eigensolver). The reads are counted, so the flag goes up at a chosen
/// point of a chosen loop without timing anything: the octree's, one per
/// octant of the quadrature, then one per point of the table.
#[test]
fn a_flag_raised_inside_the_shape_functions_or_the_assembly_stops_the_build() {
    let (surface, fixed, _) = model(
        TriMesh::cuboid(Vector::zeros(), Vector::new(0.6, 0.1, 0.1)).subdivided(3),
        true,
    );
    let efg = EfgParams::new(0.025);
    let (octree, leaves) = octree_reads(&surface, &efg);
    let reference =
        EfgSolid::build(&surface, &fixed, material(), efg, &Cancel::new()).expect("uncancelled");
    let points = reference.quadrature_points() + fixed.points.len();
    for (stage, read) in [
        ("the shape functions", octree + leaves + 10),
        ("the assembly", octree + leaves + points + 10),
    ] {
        let cancel = Cancel::raised_at_read(read);
        let err = EfgSolid::build(&surface, &fixed, material(), efg, &cancel)
            .expect_err("the raised flag stops the build");
        assert!(err.is_cancelled(), "{stage}: {err:?}");
    }
}

/// A flag raised from another thread while a modal solid's build is
/// under way (after its octree, while the host admits it) stops the
/// build in the next loop, the quadrature.
#[test]
fn a_flag_raised_from_another_thread_stops_a_modal_build() {
    let (surface, fixed, skin) = model(
        TriMesh::cuboid(Vector::zeros(), Vector::new(0.6, 0.1, 0.1)).subdivided(3),
        true,
    );
    let cancel = Cancel::new();
    let err = ModalSolid::build_admitted(
        &surface,
        &fixed,
        material(),
        &params(EfgParams::new(0.025), 12),
        Some(skin),
        &cancel,
        &|_| {
            let other = cancel.clone();
            std::thread::spawn(move || other.cancel())
                .join()
                .map_err(|_| "the raising thread panicked".to_owned())
        },
    )
    .expect_err("cancelled");
    assert!(matches!(err, EfgError::Cancelled), "{err:?}");
}
