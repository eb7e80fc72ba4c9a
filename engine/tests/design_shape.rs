//! Shape deformation (tutorial Section 8.1) through the engine API:
//! handles met, rigid handle motions give rigid fields, warm starts, the
//! embedded surface following, and coupling inside the shape only.

use meshless_engine::design::{
    Constraint, ConstraintKind, ConstraintSet, Context, DesignBody, DesignParams, Edit, Handle,
    Quadrature, Selection, Target, solve_shape,
};
use meshless_engine::geometry::{Shape, TriMesh};
use meshless_engine::math::{Real, Vector};
use nalgebra::{Matrix3, Rotation3};
use std::ops::ControlFlow;

fn quiet() -> impl FnMut(&meshless_engine::design::Progress) -> ControlFlow<()> {
    |_| ControlFlow::Continue(())
}

fn column_body(particles: u32, quadrature: Quadrature) -> DesignBody {
    let shape = Shape::Box {
        half_extents: Vector::new(0.5, 0.5, 1.0),
    };
    let params = DesignParams {
        particles,
        quadrature,
        ..DesignParams::default()
    };
    DesignBody::new(
        &shape,
        Vector::zeros(),
        Rotation3::identity(),
        3,
        &params,
        None,
    )
    .expect("a box is a valid design shape")
}

fn handle(name: &str, min: [Real; 3], max: [Real; 3], translation: [Real; 3]) -> Edit {
    Edit::Add(Constraint {
        name: name.into(),
        kind: ConstraintKind::Handle(Handle {
            points: Selection::Region { min, max },
            target: Target::Transform {
                translation,
                rotation: [0.0; 3],
                centre: [0.0; 3],
            },
            time: None,
        }),
    })
}

fn context() -> Context {
    Context {
        dim: 3,
        solids: vec![],
    }
}

#[test]
fn figure_13_volume() {
    for particles in [128u32] {
        for quadrature in [Quadrature::Cells] {
            let body = column_body(particles, quadrature);
            let mut set = ConstraintSet::new();
            let edits = [
                handle("bottom", [-1.0, -1.0, -2.0], [1.0, 1.0, -0.8], [0.0; 3]),
                handle("top", [-1.0, -1.0, 0.8], [1.0, 1.0, 2.0], [0.0, 0.0, 1.0]),
            ];
            set.apply(&edits, &context()).expect("valid handles");
            let mesh = TriMesh::cuboid(Vector::new(-0.5, -0.5, -1.0), Vector::new(0.5, 0.5, 1.0))
                .subdivided(3);
            let surface = body.surface(&mesh).expect("embeds");
            let rest_volume = mesh.signed_volume();
            for volume_weight in [300.0, 1000.0] {
                println!("{quadrature:?}");
                let mut params = DesignParams::default();
                params.weights.volume = volume_weight;
                let t = std::time::Instant::now();
                let s = solve_shape(&body, &set, &params, None, &mut quiet()).expect("solves");
                let positions: Vec<Vector> = body
                    .rest()
                    .iter()
                    .zip(&s.displacements)
                    .map(|(x, u)| x + u)
                    .collect();
                let mut out = Default::default();
                surface.update(&positions, &[], &mut out).expect("updates");
                let deformed = out.to_mesh(surface.triangles());
                let change = deformed.signed_volume() / rest_volume - 1.0;
                println!(
                    "volume weight {volume_weight}: {} particles, volume change {:+.1} %, {:?} in {:?}",
                    body.len(),
                    100.0 * change,
                    s.info,
                    t.elapsed()
                );
                let discrete: Real = (0..body.len())
                    .map(|i| {
                        body.volumes()[i]
                            * (Matrix3::identity()
                                + body.field().displacement_gradient(i, &s.displacements))
                            .determinant()
                    })
                    .sum::<Real>()
                    / body.volumes().iter().sum::<Real>()
                    - 1.0;
                println!("  discrete volume change {:+.2} %", 100.0 * discrete);
            }
        }
    }
}
