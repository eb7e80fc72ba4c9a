//! Surfaces embedded in solids, through scenes: frames carry them
//! deformed with the particles.

use meshless_engine::math::{Real, Vector};
use meshless_engine::{BuildOptions, Scene, SceneError};
use nalgebra::Rotation3;

fn scene(dim: usize, gravity: Real, shape: &str, method: &str) -> Result<Scene, SceneError> {
    let scene = Scene::from_toml_str(&format!(
        r#"
        dimension = {dim}
        gravity = [0.0, {gravity}, 0.0]
        [domain]
        min = [-2.0, -2.0, -2.0]
        max = [2.0, 2.0, 2.0]
        [time]
        dt = 1e-3
        [[systems]]
        kind = "solid"
        shape = {shape}
        position = [0.0, 0.0, 0.0]
        spacing = 0.05
        young = 1e5
        surface = {{ method = "{method}", subdivisions = 3 }}
        "#
    ))?;
    scene.validate(&BuildOptions::default())?;
    Ok(scene)
}

const BOX: &str = r#"{ type = "box", half_extents = [0.3, 0.2, 0.15] }"#;
const BALL: &str = r#"{ type = "sphere", radius = 0.25 }"#;

#[test]
fn a_turned_solid_turns_its_surface_and_a_falling_one_carries_it() {
    for method in ["shape_functions", "gradients"] {
        for shape in [BOX, BALL] {
            let mut world = scene(3, 0.0, shape, method)
                .expect("valid")
                .build(&BuildOptions::default())
                .expect("world");
            let rest = world.frame().solid_surfaces[0].mesh.clone();
            let turn = Rotation3::from_euler_angles(0.4, -0.7, 1.1);
            let solid = world.solid_mut(0).expect("solid");
            let n = solid.len();
            let turned = solid.rest_positions().iter().map(|x| turn * x).collect();
            solid
                .set_state(turned, vec![Vector::zeros(); n])
                .expect("state");
            let surface = &world.frame().solid_surfaces[0];
            let worst = surface
                .mesh
                .vertices
                .iter()
                .zip(&rest.vertices)
                .map(|(v, r)| (v - turn * r).norm())
                .fold(0.0, Real::max);
            assert!(
                worst < 1e-10,
                "{method}: vertices off the turned rest by {worst:e}"
            );
            let area = (surface.mesh.area() / rest.area() - 1.0).abs();
            assert!(area < 1e-10, "{method}: area changed by {area:e}");
            assert!(
                surface
                    .normals
                    .iter()
                    .all(|n| (n.norm() - 1.0).abs() < 1e-12)
            );
        }
        let mut world = scene(3, -9.81, BOX, method)
            .expect("valid")
            .build(&BuildOptions::default())
            .expect("world");
        for _ in 0..50 {
            world.step().expect("stable");
        }
        let frame = world.frame();
        let surface = &frame.solid_surfaces[0];
        let mean = |v: &[Vector]| v.iter().map(|x| x.y).sum::<Real>() / v.len() as Real;
        let (_, solid) = world.solids().next().expect("solid");
        let fall = 0.5 * 9.81 * 0.05_f64.powi(2);
        let drop = -mean(&surface.mesh.vertices);
        // Symplectic Euler falls g dt^2 N (N + 1) / 2: 2 % more at N = 50.
        assert!(
            (drop / fall - 1.0).abs() < 0.05,
            "{method}: surface fell {drop}, expected {fall}"
        );
        assert!((mean(&solid.positions) - mean(&surface.mesh.vertices)).abs() < 1e-3);
    }
}

#[test]
fn surfaces_that_cannot_be_embedded_are_refused() {
    let field = |e: SceneError| match e {
        SceneError::Invalid { field, message } => format!("{field}: {message}"),
        other => other.to_string(),
    };
    let flat = scene(2, 0.0, BOX, "shape_functions").expect_err("2D");
    assert!(field(flat).starts_with("systems[0].surface: "), "2D");
    let capsule = scene(
        3,
        0.0,
        r#"{ type = "capsule", half_length = 0.2, radius = 0.1 }"#,
        "gradients",
    )
    .expect_err("capsule");
    let message = field(capsule);
    assert!(
        message.contains("systems[0].surface") && message.contains("capsule"),
        "{message}"
    );
    let fine = Scene::from_toml_str(
        &scene(3, 0.0, BOX, "gradients")
            .expect("valid")
            .to_toml_string()
            .replace("subdivisions = 3", "subdivisions = 9"),
    )
    .expect("parses")
    .validate(&BuildOptions::default())
    .expect_err("too fine");
    assert!(field(fine).contains("surface.subdivisions"));
}
