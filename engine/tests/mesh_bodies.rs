//! Rigid bodies whose shape is a triangle mesh file, against the primitive
//! shapes they approximate: the shipped mesh files are the solids they
//! claim to be; a mesh ball in a resting tank disturbs it no more than the
//! analytic ball does and keeps the fluid out; a mesh block floats as deep
//! as the primitive box (Archimedes); bad mesh specs are rejected naming
//! their field. 3D, as meshes are.

use meshless_engine::geometry::{Shape, TriMesh};
use meshless_engine::math::{Real, Vector};
use meshless_engine::rigid::RigidBody;
use meshless_engine::{BuildOptions, Scene, SceneError, World};
use std::path::{Path, PathBuf};

mod common;
use common::{body, max_speed, particles_inside};

const G: Real = 9.81;

fn repo(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(relative)
}

fn icosphere_path() -> String {
    repo("scenes/meshes/icosphere.obj").display().to_string()
}

fn box_path() -> String {
    repo("scenes/meshes/box.ply").display().to_string()
}

/// A 3D DFSPH tank `[0, side] x [0, side] x [0, side]` at `spacing`, filled
/// to `depth`, with the body systems `bodies`.
fn tank_text(side: Real, spacing: Real, depth: Real, bodies: &str) -> String {
    format!(
        r#"
dimension = 3
[domain]
min = [0.0, 0.0, 0.0]
max = [{side}, {side}, {side}]
[time]
dt = 0.01
[[systems]]
kind = "fluid"
solver = "dfsph"
spacing = {spacing}
# XSPH keeps the particle order these resting tanks settle into, as the
# shipped floating_box scene does.
xsph = 0.1
[[systems.blocks]]
region = {{ min = [0.0, 0.0, 0.0], max = [{side}, {depth}, {side}] }}
{bodies}
"#
    )
}

fn build(text: &str) -> World {
    Scene::from_toml_str(text)
        .expect("scene parses")
        .build(&BuildOptions::default())
        .expect("scene is valid")
}

/// The checked-in OBJ is the unit icosphere of two subdivisions that
/// `TriMesh::icosphere` builds (to the 9 digits written), and the PLY is
/// the closed box 0.2 x 0.1 x 0.1 m (volume 0.002 m^3) with a corner at
/// the origin.
#[test]
fn the_shipped_mesh_files_are_the_solids_they_claim() {
    let obj = TriMesh::from_path(Path::new(&icosphere_path())).expect("reads");
    let reference = TriMesh::icosphere(Vector::zeros(), 1.0, 2);
    assert_eq!(obj.triangles, reference.triangles);
    for (a, b) in obj.vertices.iter().zip(&reference.vertices) {
        assert!((a - b).norm() < 1e-8);
    }
    let ply = TriMesh::from_path(Path::new(&box_path())).expect("reads");
    assert!(ply.is_closed());
    assert!((ply.signed_volume() - 0.002).abs() < 1e-9);
}

/// A body's mesh is placed by its centroid and turned from the file's
/// axes: the box file (corner at the origin) given `position` p and
/// `orientation` q puts each file vertex x at `p + q (x - c)`, c the box
/// centre (0.1, 0.05, 0.05); frames report q, not the principal frame; the
/// dynamic body's mass is density times the box volume.
#[test]
fn a_mesh_body_is_placed_by_its_centroid_in_the_files_axes() {
    let turn = [0.1, -0.4, 0.3];
    let bodies = format!(
        r#"
[[systems]]
kind = "rigid_body"
shape = {{ type = "mesh", path = "{}" }}
position = [0.3, 0.45, 0.25]
orientation = [{}, {}, {}]
motion = "dynamic"
density = 500.0
"#,
        box_path(),
        turn[0],
        turn[1],
        turn[2]
    );
    let world = build(&tank_text(0.6, 0.04, 0.2, &bodies));
    let b = body(&world);
    let q = meshless_engine::rigid::Rotation::from_scaled_axis(Vector::from(turn));
    let p = Vector::new(0.3, 0.45, 0.25);
    let centre = Vector::new(0.1, 0.05, 0.05);
    let file = TriMesh::from_path(Path::new(&box_path())).expect("reads");
    for x in &file.vertices {
        let world_x = p + q * (x - centre);
        let d = b.excluded_distance(&world_x);
        assert!(
            d.abs() < 1e-9,
            "file vertex {x:?} lands {d} m off the surface"
        );
    }
    let pose = world.frame().bodies[0];
    let reported = nalgebra::Quaternion::new(
        pose.orientation[3],
        pose.orientation[0],
        pose.orientation[1],
        pose.orientation[2],
    );
    assert!((reported - q.into_inner()).norm() < 1e-9 || (reported + q.into_inner()).norm() < 1e-9);
    let meshless_engine::rigid::Motion::Dynamic { mass, .. } = b.motion else {
        panic!("dynamic");
    };
    assert!((mass - 500.0 * 0.002).abs() < 1e-9, "mass {mass}");
    assert!(matches!(b.shape, Shape::Mesh(_)));
}

/// A ball of radius 0.06 m fixed in a 0.4 m cube filled to 0.28 m
/// (spacing 0.02 m, about 2,200 particles), once as the icosphere mesh and
/// once as the analytic sphere: over 0.6 s no particle enters either, and
/// the fluid around the mesh ball settles from the lattice as it does
/// around the analytic one (measured: 0.137 and 0.136 m/s at 0.6 s), below
/// a tenth of `sqrt(g H)` = 1.7 m/s; this coarse 3D lattice settles more
/// slowly than the 2D tank of `rigid_bodies.rs`.
#[test]
fn a_mesh_ball_leaves_a_resting_tank_as_the_analytic_ball_does() {
    let ball = |shape: String| {
        format!(
            "[[systems]]\nkind = \"rigid_body\"\nshape = {shape}\nposition = [0.2, 0.12, 0.2]\n"
        )
    };
    let mesh = ball(format!(
        "{{ type = \"mesh\", path = \"{}\", scale = 0.06 }}",
        icosphere_path()
    ));
    let sphere = ball("{ type = \"sphere\", radius = 0.06 }".into());
    let mut worlds = [mesh, sphere].map(|b| build(&tank_text(0.4, 0.02, 0.28, &b)));
    let mut speeds = Vec::new();
    for step in 1..=60 {
        for world in &mut worlds {
            world.step().expect("stable");
            assert_eq!(
                particles_inside(world),
                0,
                "a particle entered at step {step}"
            );
        }
        if step % 20 == 0 {
            speeds.push((max_speed(&worlds[0]), max_speed(&worlds[1])));
        }
    }
    let projections: Vec<usize> = worlds
        .iter()
        .map(|w| {
            w.fluid()
                .expect("fluid")
                .bodies()
                .expect("bodies")
                .projections()
        })
        .collect();
    println!(
        "max speed every 0.2 s (mesh ball, analytic ball): {speeds:.4?}; constraint \
         projections {projections:?}"
    );
    let (mesh_speed, sphere_speed) = speeds[speeds.len() - 1];
    assert!(
        mesh_speed < 0.1 * (G * 0.28 as Real).sqrt(),
        "the fluid still moves at {mesh_speed} m/s around the mesh ball"
    );
    assert!(
        mesh_speed < 1.2 * sphere_speed.max(0.01),
        "{mesh_speed} m/s around the mesh ball, {sphere_speed} m/s around the sphere"
    );
}

/// The fraction of a body's volume below `level`, by midpoint quadrature
/// on a 60^3 grid over its bounding cube.
fn submerged_fraction(b: &RigidBody, level: Real) -> Real {
    let reach = b.shape.bounding_radius(3);
    let n = 60;
    let (mut inside, mut below) = (0usize, 0usize);
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let at = |m: usize| -reach + 2.0 * reach * (m as Real + 0.5) / n as Real;
                let p = b.state.position + Vector::new(at(i), at(j), at(k));
                if b.excluded_distance(&p) < 0.0 {
                    inside += 1;
                    below += usize::from(p.y < level);
                }
            }
        }
    }
    below as Real / inside as Real
}

/// The free surface: the highest particle farther than `clear` from the
/// body (horizontally), averaged over lattice columns, plus half a spacing.
fn water_level(world: &World, clear: Real) -> Real {
    let fluid = world.fluid().expect("fluid");
    let (dx, c) = (fluid.params.spacing, body(world).state.position);
    let mut columns = std::collections::BTreeMap::new();
    for x in &fluid.positions {
        if (x.x - c.x).hypot(x.z - c.z) > clear {
            let key = ((x.x / dx) as i64, (x.z / dx) as i64);
            let top = columns.entry(key).or_insert(0.0 as Real);
            *top = top.max(x.y);
        }
    }
    columns.values().sum::<Real>() / columns.len() as Real + 0.5 * dx
}

/// Mean submerged fraction of the body over the second half of 1.2 s.
fn float(shape: &str) -> Real {
    let bodies = format!(
        "[[systems]]\nkind = \"rigid_body\"\nshape = {shape}\nposition = [0.24, 0.205, 0.24]\n\
         motion = \"dynamic\"\ndensity = 500.0\n"
    );
    let mut world = build(&tank_text(0.48, 0.02, 0.18, &bodies));
    let (mut sum, mut count) = (0.0, 0);
    for step in 1..=120 {
        world.step().expect("stable");
        if step > 60 {
            sum += submerged_fraction(body(&world), water_level(&world, 0.14));
            count += 1;
        }
    }
    sum / count as Real
}

/// Archimedes in 3D: a block 0.12 x 0.06 x 0.06 m of density 500 kg/m^3
/// (the box PLY scaled by 0.6), let go near its equilibrium in water
/// 0.18 m deep (spacing 0.02 m), floats with about half its volume
/// submerged, and as deep as the primitive box of the same size in the
/// same scene: the mesh changes the geometry's source, not the physics.
#[test]
fn a_mesh_block_floats_as_deep_as_the_primitive_box() {
    let mesh = float(&format!(
        "{{ type = \"mesh\", path = \"{}\", scale = 0.6 }}",
        box_path()
    ));
    let primitive = float("{ type = \"box\", half_extents = [0.06, 0.03, 0.03] }");
    println!(
        "submerged fraction over the second half: mesh block {mesh:.3}, primitive box \
         {primitive:.3} (Archimedes: 0.5)"
    );
    assert!((mesh - 0.5).abs() < 0.15, "mesh block submerged {mesh}");
    assert!(
        (mesh - primitive).abs() < 0.05,
        "mesh block {mesh} against primitive box {primitive}"
    );
}

/// The shipped scene reads from its file (mesh paths relative to it),
/// builds and runs 0.05 s: the block falls towards its pool, the ball
/// stays.
#[test]
fn the_shipped_mesh_scene_runs() {
    let scene = Scene::from_toml_file(&repo("scenes/mesh_body.toml")).expect("parses");
    let mut world = scene.build(&BuildOptions::default()).expect("valid");
    for _ in 0..5 {
        world.step().expect("stable");
    }
    let frame = world.frame();
    assert_eq!(frame.bodies.len(), 2);
    let (ball, block) = (frame.bodies[0], frame.bodies[1]);
    println!("after 0.05 s: ball {ball:?}; block {block:?}");
    assert_eq!(ball.position, [0.38, 0.06, 0.1]);
    assert!(block.velocity[1] < 0.0 && block.position[1] < 0.1);
}

fn rejected(text: &str) -> (String, String) {
    let scene = Scene::from_toml_str(text).expect("parses");
    match scene.build(&BuildOptions::default()) {
        Err(SceneError::Invalid { field, message }) => (field, message),
        Err(other) => panic!("expected an invalid field, got {other}"),
        Ok(_) => panic!("expected an invalid field, got a world"),
    }
}

fn mesh_body(shape: &str) -> String {
    format!("[[systems]]\nkind = \"rigid_body\"\nshape = {shape}\nposition = [0.2, 0.3, 0.2]\n")
}

/// A missing file, an open mesh, a 2D scene and a scale that is not
/// positive are each rejected, naming the field and what to change.
#[test]
fn bad_mesh_specs_name_their_field() {
    let missing = mesh_body("{ type = \"mesh\", path = \"no/such/mesh.obj\" }");
    let (field, message) = rejected(&tank_text(0.4, 0.04, 0.1, &missing));
    assert_eq!(field, "systems[1].shape.path");
    assert!(
        message.contains("no/such/mesh.obj") && message.contains("tried"),
        "{message}"
    );

    // The box without its top face: two triangles, four open edges.
    let open = Path::new(env!("CARGO_TARGET_TMPDIR")).join("open_box.obj");
    let mut text = String::new();
    let cube = TriMesh::cuboid(Vector::zeros(), Vector::repeat(0.1));
    for v in &cube.vertices {
        text += &format!("v {} {} {}\n", v.x, v.y, v.z);
    }
    for t in &cube.triangles[..10] {
        text += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    std::fs::write(&open, text).expect("writes");
    let body = mesh_body(&format!(
        "{{ type = \"mesh\", path = \"{}\" }}",
        open.display()
    ));
    let (field, message) = rejected(&tank_text(0.4, 0.04, 0.1, &body));
    assert_eq!(field, "systems[1].shape.path");
    assert!(message.contains("4 edges are open"), "{message}");

    let body = mesh_body(&format!(
        "{{ type = \"mesh\", path = \"{}\", scale = 0.0 }}",
        box_path()
    ));
    let (field, _) = rejected(&tank_text(0.4, 0.04, 0.1, &body));
    assert_eq!(field, "systems[1].shape.scale");
    let body = mesh_body(&format!(
        "{{ type = \"mesh\", path = \"{}\", scale = -2.0 }}",
        box_path()
    ));
    assert_eq!(
        rejected(&tank_text(0.4, 0.04, 0.1, &body)).0,
        "systems[1].shape.scale"
    );

    let body = mesh_body(&format!("{{ type = \"mesh\", path = \"{}\" }}", box_path()));
    let planar = tank_text(0.4, 0.04, 0.1, &body).replace("dimension = 3", "dimension = 2");
    let (field, message) = rejected(&planar);
    assert_eq!(field, "systems[1].shape");
    assert!(message.contains("3D only"), "{message}");
}
