//! Shape deformation (tutorial Section 8.1) through the engine API: warm
//! starts, the embedded surface following the field, coupling inside the
//! shape only, selections and bad input.

use meshless_engine::design::{
    Constraint, ConstraintKind, ConstraintSet, Context, DesignBody, DesignError, DesignParams,
    Edit, Handle, Progress, Selection, Target, solve_shape,
};
use meshless_engine::geometry::{MeshSolid, Shape, TriMesh};
use meshless_engine::math::{Real, Vector};
use meshless_engine::solid::embedded::DeformedSurface;
use meshless_validation::design::{Stretch, region_handle};
use nalgebra::Rotation3;
use std::ops::ControlFlow;

fn go(_: &Progress) -> ControlFlow<()> {
    ControlFlow::Continue(())
}

fn context() -> Context {
    Context {
        dim: 3,
        solids: vec![],
    }
}

/// Dragging: after a small move of the handle, the solve that starts
/// from the previous solution needs a fraction of the cold solve's
/// iterations and lands on the same optimum.
#[test]
fn a_warm_start_after_a_small_drag_is_cheap() {
    let stretch = Stretch {
        pull: 0.5,
        ..Stretch::default()
    };
    let params = DesignParams::default();
    let body = stretch.body(&params).expect("body");
    let first = solve_shape(&body, &stretch.constraints(), &params, None, &mut go).expect("solves");
    let dragged = Stretch {
        pull: 0.52,
        ..stretch
    };
    let cold = solve_shape(&body, &dragged.constraints(), &params, None, &mut go).expect("solves");
    let warm = solve_shape(
        &body,
        &dragged.constraints(),
        &params,
        Some(&first.displacements),
        &mut go,
    )
    .expect("solves");
    let gap = cold
        .displacements
        .iter()
        .zip(&warm.displacements)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, Real::max)
        / body.spacing();
    println!(
        "cold {} iterations, warm {} iterations, solutions {gap:.1e} spacings apart",
        cold.info.iterations, warm.info.iterations
    );
    assert!(
        warm.info.iterations * 2 <= cold.info.iterations,
        "warm {:?} against cold {:?}",
        warm.info,
        cold.info
    );
    // Both stop at the solver's tolerance, from different sides.
    assert!(gap < 0.1, "warm and cold optima differ by {gap} spacings");
}

/// The surface embedded with the field's own shape functions (Section
/// 7.2, Alternative 1) lands where the field maps its rest vertices.
#[test]
fn the_embedded_surface_follows_the_field() {
    let stretch = Stretch::default();
    let params = DesignParams::default();
    let body = stretch.body(&params).expect("body");
    let s = solve_shape(&body, &stretch.constraints(), &params, None, &mut go).expect("solves");
    let mesh = Stretch::mesh();
    let surface = body.surface(&mesh).expect("embeds");
    let positions: Vec<Vector> = body
        .rest()
        .iter()
        .zip(&s.displacements)
        .map(|(x, u)| x + u)
        .collect();
    let mut deformed = DeformedSurface::new();
    surface
        .update(&positions, &[], &mut deformed)
        .expect("updates");
    let field = body.embed(&mesh.vertices).expect("embeds the vertices");
    let worst = mesh
        .vertices
        .iter()
        .enumerate()
        .map(|(v, x)| (deformed.vertices[v] - (x + field.displacement(v, &s.displacements))).norm())
        .fold(0.0, Real::max);
    assert!(worst < 1e-9, "surface and field disagree by {worst} m");
    let top = deformed
        .vertices
        .iter()
        .map(|x| x.z)
        .fold(Real::MIN, Real::max);
    assert!(
        (top - 2.0).abs() < 0.05,
        "the top follows the handle to z = 2: {top}"
    );
}

/// Two fingers 0.3 m apart with particles 0.25 m apart and a support of
/// 0.55 m: in straight lines they would couple across the slot. Coupled
/// inside the shape, pulling one finger leaves the other in place.
#[test]
fn fingers_close_in_space_do_not_couple() {
    let mesh = fingers();
    let solid = MeshSolid::new(&mesh).expect("a closed mesh");
    let (centre, axes) = (solid.centroid(), solid.axes());
    let params = DesignParams {
        spacing: 0.25,
        ..DesignParams::default()
    };
    let body = DesignBody::new(
        &Shape::Mesh(solid),
        centre,
        axes.to_rotation_matrix(),
        3,
        &params,
        None,
    )
    .expect("body");
    // No particle of the left finger (x < 1) sees one of the right (x >
    // 1.3) above the palm.
    for i in 0..body.len() {
        let x = body.rest()[i];
        if x.x < 1.0 && x.y > 1.1 {
            let (js, _, _) = body.field().row(i);
            for &j in js {
                let y = body.rest()[j as usize];
                assert!(
                    !(y.x > 1.3 && y.y > 1.1),
                    "particle {i} at {x:?} couples across the slot to {j} at {y:?}"
                );
            }
        }
    }
    let mut set = ConstraintSet::new();
    set.apply(
        &[
            Edit::Add(region_handle(
                "palm",
                [-1.0, -1.0, -1.0],
                [3.0, 0.6, 1.0],
                [0.0; 3],
                [0.0; 3],
                None,
            )),
            Edit::Add(region_handle(
                "right tip",
                [1.3, 2.6, -1.0],
                [3.0, 3.0, 1.0],
                [0.8, 0.0, 0.0],
                [0.0; 3],
                None,
            )),
        ],
        &context(),
    )
    .expect("valid");
    let s = solve_shape(&body, &set, &params, None, &mut go).expect("solves");
    let moved = |filter: &dyn Fn(&Vector) -> bool| {
        body.rest()
            .iter()
            .enumerate()
            .filter(|(_, x)| filter(x))
            .map(|(i, _)| body.field().displacement(i, &s.displacements).norm())
            .fold(0.0, Real::max)
    };
    let right = moved(&|x| x.x > 1.3 && x.y > 2.4);
    let left = moved(&|x| x.x < 1.0 && x.y > 2.4);
    println!("right tip moved {right:.3} m, left tip {left:.4} m");
    assert!(right > 0.5, "the pulled finger follows: {right}");
    assert!(
        left < 0.05 * right,
        "the other finger stays: {left} against {right}"
    );
}

/// An extruded U (two fingers on a palm) as a closed triangle mesh:
/// outline in the xy-plane, z from 0 to 0.5.
fn fingers() -> TriMesh {
    let outline: [[Real; 2]; 10] = [
        [0.0, 0.0],
        [1.0, 0.0],
        [1.3, 0.0],
        [2.3, 0.0],
        [2.3, 3.0],
        [1.3, 3.0],
        [1.3, 1.0],
        [1.0, 1.0],
        [1.0, 3.0],
        [0.0, 3.0],
    ];
    // The outline's triangles (counter-clockwise seen from +z).
    let caps: [[u32; 3]; 8] = [
        [0, 1, 7],
        [0, 7, 8],
        [0, 8, 9],
        [1, 2, 6],
        [1, 6, 7],
        [2, 3, 6],
        [3, 4, 6],
        [4, 5, 6],
    ];
    let n = outline.len() as u32;
    let mut vertices: Vec<Vector> = outline
        .iter()
        .map(|p| Vector::new(p[0], p[1], 0.0))
        .collect();
    vertices.extend(outline.iter().map(|p| Vector::new(p[0], p[1], 0.5)));
    let mut triangles = Vec::new();
    for [a, b, c] in caps {
        triangles.push([a, c, b]);
        triangles.push([a + n, b + n, c + n]);
    }
    for a in 0..n {
        let b = (a + 1) % n;
        triangles.push([a, b, b + n]);
        triangles.push([a, b + n, a + n]);
    }
    TriMesh {
        vertices,
        triangles,
    }
}

#[test]
fn bad_selections_and_problems_are_errors_naming_the_constraint() {
    let stretch = Stretch::default();
    let params = DesignParams::default();
    let body = stretch.body(&params).expect("body");
    let mut set = ConstraintSet::new();
    set.apply(
        &[Edit::Add(region_handle(
            "nowhere", [5.0; 3], [6.0; 3], [0.0; 3], [0.0; 3], None,
        ))],
        &context(),
    )
    .expect("a region is valid until the particles are known");
    let err = solve_shape(&body, &set, &params, None, &mut go).expect_err("selects nothing");
    assert!(
        matches!(&err, DesignError::Constraint(c) if c.name == "nowhere"),
        "{err}"
    );
    assert!(
        err.to_string().contains("holds no design particle"),
        "{err}"
    );

    let empty = ConstraintSet::new();
    let err = solve_shape(&body, &empty, &params, None, &mut go).expect_err("no handle");
    assert!(matches!(err, DesignError::Problem(_)), "{err}");

    let outside = Selection::Points(vec![[3.0, 0.0, 0.0]]);
    assert!(body.select(&outside).is_err());

    let mut bad = params;
    bad.weights.volume = Real::NAN;
    let err =
        solve_shape(&body, &stretch.constraints(), &bad, None, &mut go).expect_err("NaN weight");
    assert!(err.to_string().contains("volume"), "{err}");

    let short = vec![Vector::zeros(); 3];
    let err = solve_shape(
        &body,
        &stretch.constraints(),
        &params,
        Some(&short),
        &mut go,
    )
    .expect_err("wrong warm start");
    assert!(
        matches!(err, DesignError::Parameter { field: "warm", .. }),
        "{err}"
    );
}

/// Extremes: a pull of ten heights, a near-zero and a huge handle weight,
/// a single design particle's worth of support. Each ends in a finite
/// answer or a clear error, never a panic or NaN.
#[test]
fn extremes_end_finite_or_in_clear_errors() {
    let params = DesignParams::default();
    let far = Stretch {
        pull: 20.0,
        ..Stretch::default()
    };
    let r = far.solve(&params).expect("a long pull still solves");
    assert!(
        r.solution
            .displacements
            .iter()
            .all(|u| u.iter().all(|c| c.is_finite()))
    );
    // Stretched tenfold, rigidity pulls back hard against the handles'
    // weight; they still hold the top within a few percent of the pull.
    let body = far.body(&params).expect("body");
    let miss = r.handle_error * body.spacing();
    assert!(
        miss < 0.05 * far.pull,
        "handles missed by {miss} m of a {} m pull",
        far.pull
    );

    for handle in [1e-6, 1e8] {
        let mut p = params;
        p.weights.handle = handle;
        let r = Stretch::default().solve(&p).expect("solves");
        assert!(
            r.solution
                .displacements
                .iter()
                .all(|u| u.iter().all(|c| c.is_finite())),
            "handle weight {handle}"
        );
    }

    let tiny = DesignParams {
        spacing: 10.0,
        ..params
    };
    let err = Stretch::default()
        .body(&tiny)
        .expect_err("no particle fits");
    assert!(err.to_string().contains("spacing"), "{err}");
    let err = DesignBody::new(
        &Shape::Sphere { radius: 1.0 },
        Vector::zeros(),
        Rotation3::identity(),
        3,
        &DesignParams {
            support: 0.5,
            ..params
        },
        None,
    )
    .expect_err("support too small");
    assert!(err.to_string().contains("support"), "{err}");
}

/// A first solve starts from the rigid motion that best takes the handles
/// to their targets. Handles that fix no rotation, one point or points on
/// a line, get only its translation, and still solve to their targets.
#[test]
fn handles_that_fix_no_rotation_start_from_a_translation() {
    let params = DesignParams::default();
    let stretch = Stretch::default();
    let body = stretch.body(&params).expect("body");
    let point = |name: &str, points: Vec<[Real; 3]>, targets: Vec<[Real; 3]>| Constraint {
        name: name.into(),
        kind: ConstraintKind::Handle(Handle {
            points: Selection::Points(points),
            target: Target::Positions(targets),
            time: None,
        }),
    };
    let cases = [
        vec![point("tip", vec![[0.0, 0.0, 0.8]], vec![[0.3, -0.2, 1.3]])],
        vec![point(
            "axis",
            vec![[0.0, 0.0, -0.8], [0.0, 0.0, 0.8]],
            vec![[0.2, 0.0, -0.7], [0.2, 0.0, 1.1]],
        )],
    ];
    for constraints in cases {
        let name = constraints[0].name.clone();
        let mut set = ConstraintSet::new();
        set.apply(
            &constraints.into_iter().map(Edit::Add).collect::<Vec<_>>(),
            &context(),
        )
        .expect("valid handles");
        let s = solve_shape(&body, &set, &params, None, &mut go).expect("solves");
        assert!(
            s.displacements
                .iter()
                .all(|u| u.iter().all(|c| c.is_finite())),
            "{name}: finite"
        );
        assert!(s.info.converged, "{name}: {:?}", s.info);
        // The handle energy is the weight times the squared misses in
        // spacings.
        let miss = (s.info.energies.handle / params.weights.handle).sqrt();
        assert!(miss < 0.05, "{name}: handles missed by {miss} spacings");
    }
}
