//! The scene's parsing and validation: defaults, round trips, and every
//! bad value rejected naming its field.

use super::*;

const SMALL: &str = r#"
    name = "small"
    [domain]
    min = [0.0, 0.0, 0.0]
    max = [1.0, 1.0, 1.0]
    [time]
    dt = 0.01
    [[systems]]
    kind = "fluid"
    spacing = 0.1
    stiffness = 1000.0
    [[systems.blocks]]
    region = { min = [0.0, 0.0, 0.0], max = [0.5, 0.5, 0.5] }
"#;

fn small() -> Scene {
    Scene::from_toml_str(SMALL).expect("valid scene")
}

fn rejected_field(scene: &Scene) -> String {
    match scene.validate(&BuildOptions::default()) {
        Err(SceneError::Invalid { field, .. }) => field,
        other => panic!("expected an invalid field, got {other:?}"),
    }
}

fn fluid(scene: &mut Scene) -> &mut FluidSpec {
    match &mut scene.systems[0] {
        SystemSpec::Fluid(f) => f,
        SystemSpec::RigidBody(_)
        | SystemSpec::Solid(_)
        | SystemSpec::ModalSolid(_)
        | SystemSpec::Shell(_) => {
            panic!("the first system is the fluid")
        }
    }
}

#[test]
fn toml_defaults_are_applied() {
    let scene = small();
    assert_eq!(scene.gravity, defaults::GRAVITY);
    assert_eq!(scene.time.max_substeps, defaults::MAX_SUBSTEPS);
    let mut s = scene.clone();
    let f = fluid(&mut s);
    assert_eq!(f.support_radius(), 0.2);
    assert_eq!(f.gamma, defaults::GAMMA);
    assert_eq!(scene.particle_count(), 125.0);
    assert_eq!(f.lattice(3).count(), 125);
    assert_eq!(f.lattice(2).count(), 25);
    assert!(f.lattice(2).all(|(x, _)| x[2] == 0.0));
}

/// Parse errors say where and what, never repeat the input at length,
/// and say what to change for a file nested too deep.
#[test]
fn parse_errors_are_short_and_located() {
    let long_key = format!("{} = 1\n", "k".repeat(1 << 20));
    let err = Scene::from_toml_str(&format!("{SMALL}{long_key}")).expect_err("unknown key");
    let message = err.to_string();
    assert!(message.len() < 600, "{} bytes", message.len());
    // toml places an unknown field at the table that holds it: the
    // `[[systems]]` header on line 8.
    assert!(message.contains("at line 8, column 5"), "{message}");

    let deep = format!("a = {}1{}", "[".repeat(100_000), "]".repeat(100_000));
    let message = Scene::from_toml_str(&deep)
        .expect_err("too deep")
        .to_string();
    assert!(message.contains("nested too deeply"), "{message}");
    assert!(message.len() < 600, "{} bytes", message.len());

    // A value holding the parser's own quote characters ends its quoted
    // span early; the error still repeats no more than a short prefix
    // of it (found by the `scene_toml` fuzz target; reproducer in
    // fuzz/regressions/scene_toml).
    let ticks = format!("ri{}gid_body", "`".repeat(80));
    let text = SMALL.replacen("kind = \"fluid\"", &format!("kind = \"{ticks}\""), 1);
    assert_ne!(text, SMALL, "the small scene names its fluid's kind");
    let message = Scene::from_toml_str(&text)
        .expect_err("unknown kind")
        .to_string();
    assert!(message.contains("unknown variant"), "{message}");
    assert!(!message.contains(&"`".repeat(40)), "{message}");
}

#[test]
fn toml_round_trips() {
    let scene = small();
    let again = Scene::from_toml_str(&scene.to_toml_string()).expect("round trip");
    assert_eq!(scene, again);
}

/// Each kind of bad value is rejected with the path of its field.
#[test]
fn bad_values_name_their_field() {
    let mut s = small();
    fluid(&mut s).spacing = -1.0;
    assert_eq!(rejected_field(&s), "systems[0].spacing");

    let mut s = small();
    s.name = "n".repeat(MAX_NAME_CHARS + 1);
    assert_eq!(rejected_field(&s), "name");
    s.name = "\u{e9}".repeat(MAX_NAME_CHARS);
    assert!(
        s.validate(&BuildOptions::default()).is_ok(),
        "the limit counts characters"
    );

    let mut s = small();
    fluid(&mut s).support_radius = Some(Real::NAN);
    assert_eq!(rejected_field(&s), "systems[0].support_radius");

    let mut s = small();
    fluid(&mut s).support_radius = Some(0.0);
    assert_eq!(rejected_field(&s), "systems[0].support_radius");

    // Checked whichever solver reads them: the small tank is WCSPH, which
    // reads neither tolerance.
    let mut s = small();
    fluid(&mut s).divergence_tolerance = Real::NAN;
    assert_eq!(rejected_field(&s), "systems[0].divergence_tolerance");
    let mut s = small();
    fluid(&mut s).max_solver_iterations = 0;
    assert_eq!(rejected_field(&s), "systems[0].max_solver_iterations");

    let mut s = small();
    s.domain.max[1] = s.domain.min[1];
    assert_eq!(rejected_field(&s), "domain");

    let mut s = small();
    s.gravity[2] = Real::INFINITY;
    assert_eq!(rejected_field(&s), "gravity.z");

    let mut s = small();
    s.time.dt = 0.0;
    assert_eq!(rejected_field(&s), "time.dt");

    let mut s = small();
    fluid(&mut s).blocks[0].region.max = [2.0, 0.5, 0.5];
    assert_eq!(rejected_field(&s), "systems[0].blocks[0].region");

    let mut s = small();
    let block = fluid(&mut s).blocks[0].clone();
    fluid(&mut s).blocks.push(block);
    assert_eq!(rejected_field(&s), "systems[0].blocks[1].region");

    let mut s = small();
    fluid(&mut s).particles.push(ParticleSpec {
        position: [0.5, 1.5, 0.5],
        velocity: [0.0; 3],
    });
    assert_eq!(rejected_field(&s), "systems[0].particles[0].position");

    let mut s = small();
    fluid(&mut s).particles.push(ParticleSpec {
        position: [0.5, 0.5, 0.5],
        velocity: [0.0, Real::NAN, 0.0],
    });
    assert_eq!(rejected_field(&s), "systems[0].particles[0].velocity.y");

    // Particles piled into one spot are refused before any neighbour
    // search (50,000 at one point once took the server past 3 GB); a
    // lattice of them at the spacing is fine.
    let mut s = small();
    let spacing = fluid(&mut s).spacing;
    let pile = ParticleSpec {
        position: [0.55, 0.55, 0.55],
        velocity: [0.0; 3],
    };
    fluid(&mut s).particles = vec![pile; 50_000];
    match s.validate(&BuildOptions::default()) {
        Err(SceneError::Invalid { field, message }) => {
            assert_eq!(field, "systems[0].particles[0].position");
            assert!(message.contains("particles[8]"), "{message}");
        }
        other => panic!("a pile of particles was accepted: {other:?}"),
    }
    let mut s = small();
    fluid(&mut s).particles = (0..4)
        .flat_map(|i| (0..4).map(move |j| (i, j)))
        .map(|(i, j)| ParticleSpec {
            position: [0.6 + spacing * i as Real, 0.6 + spacing * j as Real, 0.6],
            velocity: [0.0; 3],
        })
        .collect();
    assert!(s.validate(&BuildOptions::default()).is_ok());

    // Three support radii (0.6 m) fit in the 1 m box; 0.5 m does not.
    let mut s = small();
    s.periodic = [false, true, false];
    assert!(s.validate(&BuildOptions::default()).is_ok());
    s.domain.max[1] = 0.5;
    fluid(&mut s).blocks[0].region.max[1] = 0.5;
    assert_eq!(rejected_field(&s), "periodic.y");

    let mut s = small();
    s.systems.clear();
    assert_eq!(rejected_field(&s), "systems");

    let mut s = small();
    s.domain.max = [1e6, 1e6, 1e6];
    assert_eq!(rejected_field(&s), "domain");
}

/// The stiffness is the WCSPH solver's knob: required there, not for
/// DFSPH, whose own knobs are range-checked instead.
#[test]
fn each_solver_checks_its_own_knobs() {
    let mut s = small();
    fluid(&mut s).stiffness = 0.0;
    assert_eq!(rejected_field(&s), "systems[0].stiffness");
    fluid(&mut s).solver = SolverKind::Dfsph;
    s.validate(&BuildOptions::default())
        .expect("DFSPH needs no stiffness");
    fluid(&mut s).density_tolerance = 0.0;
    assert_eq!(rejected_field(&s), "systems[0].density_tolerance");
    fluid(&mut s).density_tolerance = 0.001;
    fluid(&mut s).max_solver_iterations = 0;
    assert_eq!(rejected_field(&s), "systems[0].max_solver_iterations");
}

#[test]
fn particle_limit_is_enforced_before_allocation() {
    let mut s = small();
    fluid(&mut s).spacing = 0.001;
    fluid(&mut s).support_radius = Some(0.004);
    let err = s
        .validate(&BuildOptions {
            max_particles: 1000,
            ..BuildOptions::default()
        })
        .expect_err("limit");
    assert!(
        matches!(err, SceneError::TooManyParticles { limit: 1000, .. }),
        "{err}"
    );
}

/// A 1 m elastic cube at `spacing`, centred in a 4 m domain, with
/// `extra` lines added to its system (e.g. a surface).
fn unit_box_solid(spacing: f64, extra: &str) -> Scene {
    Scene::from_toml_str(&format!(
        r#"
        gravity = [0.0, 0.0, 0.0]
        [domain]
        min = [-2.0, -2.0, -2.0]
        max = [2.0, 2.0, 2.0]
        [time]
        dt = 0.001
        [[systems]]
        kind = "solid"
        shape = {{ type = "box", half_extents = [0.5, 0.5, 0.5] }}
        position = [0.0, 0.0, 0.0]
        spacing = {spacing}
        young = 1e6
        density = 1000.0
        {extra}
        "#
    ))
    .expect("parses")
}

/// A solid too fine to sample is a resource limit like the fluid's
/// particle limit (the host answers both RESOURCE_EXHAUSTED), naming the
/// spacing.
#[test]
fn a_solid_too_fine_to_sample_is_a_resource_limit() {
    match unit_box_solid(1e-4, "").validate(&BuildOptions::default()) {
        Err(SceneError::TooFine { field, points, .. }) => {
            assert_eq!(field, "systems[0].spacing");
            assert!(points >= 1_000_000_000_000, "{points}");
        }
        other => panic!("expected TooFine, got {other:?}"),
    }
}

/// A solid over the host's particle limit is refused before its
/// particles are sampled or its embedded surface is built (either could
/// take gigabytes and seconds inside the admission check, found by the
/// `scene_spec` fuzz target): far over the limit by its volume's
/// expected count, just over it by the count sampled.
#[test]
fn a_solid_over_the_particle_limit_is_refused_before_sampling() {
    let limit = |max_particles| BuildOptions {
        max_particles,
        ..BuildOptions::default()
    };
    // 1 m^3 at 0.01 m: 10^6 expected, refused at a limit of 1,000 by the
    // estimate (the sampled count of the lattice would differ from it).
    match unit_box_solid(0.01, "surface = { subdivisions = 7 }").validate(&limit(1_000)) {
        Err(SceneError::TooManyParticles { count, limit }) => {
            assert_eq!((count, limit), (1_000_000, 1_000));
        }
        other => panic!("expected TooManyParticles, got {other:?}"),
    }
    // 1 m^3 at 0.1 m: about 1,000 sampled; a limit just below the sampled
    // count (within the estimate's factor of two) is met by the count.
    let sampled = unit_box_solid(0.1, "")
        .check(&limit(1_000_000))
        .expect("fits a large limit")
        .footprint()
        .particles;
    let just_below = (sampled as u64).saturating_sub(1);
    match unit_box_solid(0.1, "").validate(&limit(just_below)) {
        Err(SceneError::TooManyParticles { count, limit }) => {
            assert_eq!((count as f64, limit), (sampled, just_below));
        }
        other => panic!("expected TooManyParticles, got {other:?}"),
    }
}

/// The check samples a solid and embeds its surface, and the build takes
/// both over instead of making them again (an embedded surface is the
/// dearest part of admitting a solid): the world's solid rests at the
/// particles the check sampled, and its surface is the one it embedded.
#[test]
fn the_build_takes_over_the_solid_the_check_made() {
    let checked = unit_box_solid(0.1, "surface = { subdivisions = 1 }")
        .check(&BuildOptions::default())
        .expect("valid");
    let Some(Prepared::Solid(sampled)) = checked.systems.first().cloned() else {
        panic!("the check keeps the solid it sampled");
    };
    let surface = sampled.surface.expect("the check embedded the surface");
    let world = checked.build();
    let frame = world.frame();
    let positions = &frame.field(FieldKind::Position).expect("positions").values;
    assert_eq!(positions.len(), 3 * sampled.particles.len());
    for (k, (x, _)) in sampled.particles.iter().enumerate() {
        for a in 0..3 {
            assert_eq!(positions[3 * k + a], x[a] as f32, "particle {k}");
        }
    }
    assert_eq!(
        frame.solid_surfaces[0].mesh.vertices.len(),
        surface.vertex_count()
    );
}

fn with_body(body: &str) -> Scene {
    Scene::from_toml_str(&format!(
        "{SMALL}\n[[systems]]\nkind = \"rigid_body\"\n{body}"
    ))
    .expect("parses")
}

/// A valid body builds; each bad body spec is rejected naming its
/// field, with the scene path of the body (systems[1]).
#[test]
fn bad_bodies_name_their_field() {
    let ball = "shape = { type = \"sphere\", radius = 0.1 }\nposition = [0.7, 0.7, 0.7]";
    let s = with_body(&format!("{ball}\nmotion = \"dynamic\"\ndensity = 500.0"));
    let world = s.build(&BuildOptions::default()).expect("valid body");
    assert_eq!(world.frame().bodies.len(), 1);
    assert_eq!(
        Scene::from_toml_str(&s.to_toml_string()).expect("round trip"),
        s
    );
    // A moving body would cross the periodic faces its samples do not
    // wrap around (static ones clear of the faces may stay).
    let mut periodic = s.clone();
    periodic.periodic = [true, false, false];
    assert_eq!(rejected_field(&periodic), "systems[1].motion");

    let cases = [
        (
            "shape = { type = \"sphere\", radius = 0.0 }\nposition = [0.5, 0.5, 0.5]",
            "systems[1].shape.radius",
        ),
        (
            "shape = { type = \"box\", half_extents = [0.1, -0.1, 0.1] }\nposition = [0.5, 0.5, 0.5]",
            "systems[1].shape.half_extents.y",
        ),
        (
            "shape = { type = \"capsule\", half_length = -1.0, radius = 0.1 }\nposition = [0.5, 0.5, 0.5]",
            "systems[1].shape.half_length",
        ),
        (
            "shape = { type = \"plane\", normal = [0.0, 0.0, 0.0] }\nposition = [0.5, 0.1, 0.5]",
            "systems[1].shape.normal",
        ),
        (
            "shape = { type = \"plane\", normal = [0.0, 1.0, 0.0] }\nposition = [0.5, 2.0, 0.5]",
            "systems[1]",
        ),
        (
            "shape = { type = \"sphere\", radius = 0.1 }\nposition = [1.5, 0.5, 0.5]",
            "systems[1].position",
        ),
        (
            "shape = { type = \"sphere\", radius = 10.0 }\nposition = [0.5, 0.5, 0.5]",
            "systems[1].shape",
        ),
        (
            &format!("{ball}\nmotion = \"dynamic\""),
            "systems[1].density",
        ),
        (
            &format!("{ball}\nmotion = \"dynamic\"\ndensity = -1.0"),
            "systems[1].density",
        ),
        (&format!("{ball}\ndensity = 500.0"), "systems[1].density"),
        (
            &format!("{ball}\nvelocity = [1.0, 0.0, 0.0]"),
            "systems[1].motion",
        ),
        (
            &format!("{ball}\nmotion = \"dynamic\"\ndensity = 500.0\nhollow = true"),
            "systems[1].hollow",
        ),
        (
            &format!(
                "{ball}\nmotion = \"kinematic\"\noscillation = {{ amplitude = [0.1, 0.0, 0.0], frequency = 0.0 }}"
            ),
            "systems[1].oscillation.frequency",
        ),
        (&format!("{ball}\nslip = \"no\""), "systems[1].viscosity"),
        (
            &format!("{ball}\norientation = [0.0, 0.0, nan]"),
            "systems[1].orientation.z",
        ),
        (
            "shape = { type = \"plane\", normal = [0.0, 1.0, 0.0] }\nposition = [0.5, 0.1, 0.5]\nmotion = \"dynamic\"\ndensity = 1.0",
            "systems[1].motion",
        ),
    ];
    for (body, field) in cases {
        assert_eq!(rejected_field(&with_body(body)), field, "{body}");
    }

    let mut planar = with_body(&format!("{ball}\norientation = [0.3, 0.0, 0.0]"));
    planar.dimension = 2;
    assert_eq!(rejected_field(&planar), "systems[1].orientation");

    // A body without a fluid.
    let mut lonely = with_body(ball);
    lonely.systems.remove(0);
    assert_eq!(rejected_field(&lonely), "systems[0]");
    // An unknown shape key is a parse error naming it.
    let err = Scene::from_toml_str(&format!(
        "{SMALL}\n[[systems]]\nkind = \"rigid_body\"\nshape = {{ type = \"sphere\", radius = 0.1, radios = 1.0 }}\nposition = [0.5, 0.5, 0.5]"
    ))
    .expect_err("unknown key");
    assert!(err.to_string().contains("radios"), "{err}");
}

/// A surface is optional, defaults its cell to half the spacing, and
/// names its field when out of range, in 2D or too fine for the domain.
#[test]
fn surfaces_are_validated() {
    let text = SMALL.replace("[time]", "[output]\nsurface = {}\n[time]");
    let s = Scene::from_toml_str(&text).expect("surface with defaults");
    let surface = s.output.surface.clone().expect("a surface");
    assert_eq!((surface.cell(0.1), surface.iso), (0.05, 0.5));
    s.validate(&BuildOptions::default()).expect("valid");
    assert_eq!(
        Scene::from_toml_str(&s.to_toml_string()).expect("round trip"),
        s
    );
    assert_eq!(small().output.surface, None);

    let with = |cell: Option<Real>, iso: Real| {
        let mut s = s.clone();
        s.output.surface = Some(SurfaceSpec { cell, iso });
        s
    };
    assert_eq!(rejected_field(&with(Some(0.0), 0.5)), "output.surface.cell");
    assert_eq!(
        rejected_field(&with(Some(Real::NAN), 0.5)),
        "output.surface.cell"
    );
    assert_eq!(rejected_field(&with(None, 1.0)), "output.surface.iso");
    assert_eq!(rejected_field(&with(None, 0.0)), "output.surface.iso");
    let err = with(Some(1e-4), 0.5)
        .validate(&BuildOptions::default())
        .expect_err("10^12 nodes");
    assert!(err.to_string().starts_with("output.surface.cell:"), "{err}");
    assert!(err.to_string().contains("limit"), "{err}");

    let mut flat = s.clone();
    flat.dimension = 2;
    let err = flat.validate(&BuildOptions::default()).expect_err("2D");
    assert!(err.to_string().contains("3D only"), "{err}");
}

#[test]
fn unknown_systems_and_keys_are_parse_errors() {
    let text = SMALL.replace("kind = \"fluid\"", "kind = \"plasma\"");
    let err = Scene::from_toml_str(&text).expect_err("unknown system");
    assert!(err.to_string().contains("plasma"), "{err}");

    let text = SMALL.replace("stiffness = 1000.0", "stiffness = 1000.0\nstifness = 1.0");
    let err = Scene::from_toml_str(&text).expect_err("unknown key");
    assert!(err.to_string().contains("stifness"), "{err}");
}

/// A velocity field gives each block particle the formula's value at its
/// position; a body force drives the fluid. Bad formulas are refused
/// naming the component, a field infinite at a particle naming the field,
/// and a wrongly typed value inside a system names its key.
#[test]
fn formula_fields_build_and_bad_ones_are_refused() {
    let mut s = small();
    s.gravity = [0.0; 3];
    fluid(&mut s).velocity_field = Some(["y".into(), "-x".into(), "0.5*z".into()]);
    let world = s.build(&BuildOptions::default()).expect("valid");
    let f = world.fluid().expect("fluid");
    for (x, v) in f.positions.iter().zip(&f.velocities) {
        assert_eq!(*v, crate::math::Vector::new(x.y, -x.x, 0.5 * x.z));
    }

    let mut pushed = small();
    pushed.gravity = [0.0; 3];
    fluid(&mut pushed).body_force = Some(["2".into(), "0".into(), "0".into()]);
    let mut world = pushed.build(&BuildOptions::default()).expect("valid");
    for _ in 0..5 {
        world.step().expect("stable");
    }
    let f = world.fluid().expect("fluid");
    let mean = f.velocities.iter().map(|v| v.x).sum::<f64>() / f.len() as f64;
    // 2 m/s^2 for 0.05 s: 0.1 m/s, give or take what the walls the block
    // starts against push.
    assert!((mean - 0.1).abs() < 0.02, "{mean}");

    // Scientific notation is a number, in TOML scenes as in formulas.
    let text = SMALL.replace(
        "[[systems]]",
        "[[systems]]\nvelocity_field = [\"1e-3*x\", \"2.5E+4*0\", \"-1e3*0 + 2e-1\"]",
    );
    let sci = Scene::from_toml_str(&text).expect("parses");
    let world = sci
        .build(&BuildOptions::default())
        .expect("scientific notation is valid");
    let f = world.fluid().expect("fluid");
    for (x, v) in f.positions.iter().zip(&f.velocities) {
        assert_eq!(*v, crate::math::Vector::new(1e-3 * x.x, 0.0, 2e-1));
    }

    let mut s = small();
    fluid(&mut s).velocity_field = Some(["x".into(), "q".into(), "0".into()]);
    assert_eq!(rejected_field(&s), "systems[0].velocity_field[1]");
    let mut s = small();
    fluid(&mut s).body_force = Some(["1/(x - 0.05)".into(), "0".into(), "0".into()]);
    assert_eq!(rejected_field(&s), "systems[0].body_force");

    // A formula is evaluated only once the particle count is bounded: a
    // block of 10^18 particles is refused by its count, at once.
    let mut huge = small();
    fluid(&mut huge).spacing = 1e-6;
    fluid(&mut huge).velocity_field = Some(["x".into(), "0".into(), "0".into()]);
    let refused = huge.validate(&BuildOptions::default());
    assert!(
        matches!(
            refused,
            Err(SceneError::TooManyParticles { .. } | SceneError::Invalid { .. })
        ) && !format!("{refused:?}").contains("velocity_field"),
        "{refused:?}"
    );

    let typed = SMALL.replace("spacing = 0.1", "spacing = \"0.1\"");
    let Err(SceneError::Parse(message)) = Scene::from_toml_str(&typed) else {
        panic!("a string spacing parsed");
    };
    assert!(message.contains("`spacing`"), "{message}");
}

/// A 3D fracturing solid with a surface, built in two pieces by a notch
/// through it: its frames carry a surface closed and cut at the notch
/// (each piece's own), where the same solid in one piece carries its
/// embedded surface.
#[test]
fn a_solid_in_pieces_frames_a_closed_surface_cut_where_it_broke() {
    let cut = 0.02;
    let whole = unit_box_solid(
        0.1,
        "surface = { subdivisions = 2 }\nfracture = { stress = 1e9 }",
    )
    .build(&BuildOptions::default())
    .expect("builds");
    let embedded = whole.frame().solid_surfaces[0].mesh.vertices.len();
    let broken = unit_box_solid(
        0.1,
        &format!(
            "surface = {{ subdivisions = 2 }}\nfracture = {{ stress = 1e9, criterion = \"visibility\", \
             notches = [{{ center = [{cut}, 0.0, 0.0], normal = [1.0, 0.0, 0.0], radius = 1.0 }}] }}"
        ),
    )
    .build(&BuildOptions::default())
    .expect("builds");
    let frame = broken.frame();
    let mesh = &frame.solid_surfaces[0].mesh;
    assert_ne!(
        mesh.vertices.len(),
        embedded,
        "the pieces' surface, not the embedded one"
    );
    let edges: std::collections::HashSet<(u32, u32)> = mesh
        .triangles
        .iter()
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .collect();
    assert_eq!(
        edges.len(),
        3 * mesh.triangles.len(),
        "an edge used twice one way"
    );
    assert!(
        edges.iter().all(|(a, b)| edges.contains(&(*b, *a))),
        "the surface is open"
    );
    let x = |v: u32| mesh.vertices[v as usize].x;
    assert!(
        mesh.triangles.iter().all(|t| {
            let (lo, hi) = t
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                    (lo.min(x(v)), hi.max(x(v)))
                });
            hi <= cut + 1e-3 || lo >= cut - 1e-3
        }),
        "a triangle spans the cut"
    );
    for side in [-1.0, 1.0] {
        assert!(
            mesh.vertices.iter().any(|v| side * (v.x - cut) > 0.4),
            "no piece on side {side}"
        );
    }
}

/// A fracture table's toughness and notches: a notched cube builds with
/// its notch as a crack, and each bad value is refused naming its field.
#[test]
fn notches_and_toughness_build_or_are_refused_naming_the_field() {
    let notched = unit_box_solid(
        0.1,
        "fracture = { stress = 1e5, toughness = 1.5e5, notches = [{ center = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 0.0], radius = 0.3 }] }",
    );
    let world = notched.build(&BuildOptions::default()).expect("builds");
    let (_, solid) = world.solids().next().expect("a solid");
    let fracture = solid.fracture().expect("fractures");
    assert_eq!(fracture.cracks().len(), 1);
    // A disc of radius 0.3 with rim nodes at most a spacing apart.
    assert!(fracture.cracks()[0].front().len() >= 19);
    assert_eq!(
        fracture.fragment_count(),
        1,
        "a notch inside the body splits nothing"
    );
    // Branching in 3D (the cube is 3D).
    unit_box_solid(0.1, "fracture = { stress = 1e5, branching = 2.0 }")
        .build(&BuildOptions::default())
        .expect("3D branching builds");

    for (extra, field) in [
        // The critical distance 1e4^2 / (2 pi 1e5^2) is 1.6 mm, under the
        // 0.1 m spacing.
        (
            "fracture = { stress = 1e5, toughness = 1e4 }",
            "systems[0].fracture",
        ),
        (
            "fracture = { plastic_strain = 0.1, toughness = 1e4 }",
            "systems[0].fracture.toughness",
        ),
        (
            "fracture = { stress = 1e5, notches = [{ center = [0.0, 0.0, 0.0], normal = [0.0, 0.0, 0.0], radius = 0.3 }] }",
            "systems[0].fracture.notches[0]",
        ),
        (
            "fracture = { stress = 1e5, notches = [{ center = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 0.0], radius = -1.0 }] }",
            "systems[0].fracture.notches[0]",
        ),
        (
            "fracture = { stress = 1e5, max_cracks = 1, notches = [{ center = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 0.0], radius = 0.1 }, { center = [0.0, 0.2, 0.0], normal = [0.0, 1.0, 0.0], radius = 0.1 }] }",
            "systems[0].fracture.notches",
        ),
        // Branching below the threshold itself.
        (
            "fracture = { stress = 1e5, branching = 0.5 }",
            "systems[0].fracture",
        ),
        // A surface cell past a spacing.
        (
            "fracture = { stress = 1e5, surface_cell = 1.5 }",
            "systems[0].fracture",
        ),
        (
            // A rim of 2 pi 1e4 / 0.1 nodes: past what 1000 particles hold.
            "fracture = { stress = 1e5, notches = [{ center = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 0.0], radius = 1e4 }] }",
            "systems[0].fracture.notches",
        ),
    ] {
        assert_eq!(
            rejected_field(&unit_box_solid(0.1, extra)),
            field,
            "{extra}"
        );
    }
}
