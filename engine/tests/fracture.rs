//! Fracturing solids in a world (tutorial Section 7.3): the shipped
//! brittle cantilever snaps at its root and falls; below its strength it
//! steps exactly as the elastic one; a snapshot taken while a crack runs
//! continues bit for bit; a step that fails later in the world puts the
//! cracks back; the `fragment` field labels the pieces.

use meshless_engine::{BuildOptions, FieldKind, Scene, StepError, World};
use nalgebra::Vector3;

fn shipped(name: &str) -> Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(name);
    Scene::from_toml_file(&path).expect("the shipped scene parses")
}

fn build(scene: &Scene) -> World {
    scene
        .build(&BuildOptions::default())
        .expect("a valid scene")
}

fn fragments(world: &World) -> Vec<f32> {
    let frame = world.frame();
    frame
        .fields
        .iter()
        .find(|f| f.kind == FieldKind::Fragment)
        .expect("the scene asks for fragments")
        .values
        .clone()
}

/// The masses of a fracturing solid's pieces, largest first.
fn piece_masses(solid: &meshless_engine::solid::ElasticSolid) -> Vec<f64> {
    let fracture = solid.fracture().expect("it fractures");
    let mut parts = vec![0.0; fracture.fragment_count() as usize];
    for (&k, m) in fracture.fragments().iter().zip(solid.masses()) {
        parts[k as usize] += m;
    }
    parts.sort_by(|a, b| b.total_cmp(a));
    parts
}

/// Steps `world` until its solid is in two pieces of over 45 % of its
/// mass each, at most `max_steps`; the step it took.
fn steps_until_halves(world: &mut World, max_steps: usize) -> Option<usize> {
    (1..=max_steps).find(|_| {
        world.step().expect("the bar steps");
        let (_, solid) = world.solids().next().expect("one solid");
        let parts = piece_masses(solid);
        let mass: f64 = parts.iter().sum();
        parts.len() >= 2 && parts[1] > 0.45 * mass
    })
}

fn run_until_broken(world: &mut World, max_steps: usize) -> usize {
    for step in 1..=max_steps {
        world.step().expect("the beam steps");
        let (_, solid) = world.solids().next().expect("one solid");
        if solid.fracture().expect("it fractures").fragment_count() >= 2 {
            return step;
        }
    }
    panic!("the beam did not break in {max_steps} steps");
}

#[test]
fn the_brittle_beam_snaps_at_its_root_and_falls() {
    let scene = shipped("brittle_beam.toml");
    let mut world = build(&scene);
    let broke = run_until_broken(&mut world, 150);
    let (_, solid) = world.solids().next().expect("one solid");
    let fracture = solid.fracture().expect("it fractures");
    // The first crack starts at the root, where the bending stress peaks.
    let first = &fracture.cracks()[0];
    let start = first.front().iter().map(|f| f.at.x).sum::<f64>() / first.front().len() as f64;
    assert!(start < 0.15, "the first crack started at x = {start}");
    // The labels the frame carries are the solid's.
    let labels = fragments(&world);
    let distinct: std::collections::BTreeSet<u32> = labels.iter().map(|&k| k as u32).collect();
    assert!(distinct.len() >= 2, "{distinct:?}");
    // The piece away from the clamp falls: 0.2 s later its tip is far
    // below the sag an intact beam swings through (about 2 cm).
    for _ in 0..100 {
        world.step().expect("the pieces step");
    }
    let (_, solid) = world.solids().next().expect("one solid");
    let tip = solid
        .positions
        .iter()
        .zip(solid.rest_positions())
        .filter(|(_, r)| r.x > 0.95)
        .map(|(x, _)| x.y)
        .fold(f64::INFINITY, f64::min);
    assert!(
        tip < -0.1,
        "the tip is at y = {tip} {broke} steps after the break"
    );
    // The frame carries each crack's two faces; across the crack that
    // broke the beam they have come apart with the pieces.
    let frame = world.frame();
    let [faces] = &frame.crack_surfaces[..] else {
        panic!("one fracturing solid, so one set of crack faces");
    };
    let cracks = solid.fracture().expect("it fractures").cracks();
    let vertices: usize = cracks.iter().map(|c| c.vertices().len()).sum();
    assert_eq!(faces.mesh.vertices.len(), 2 * vertices);
    assert_eq!(faces.normals.len(), faces.mesh.vertices.len());
    let n = cracks[0].vertices().len();
    let gap = (0..n)
        .map(|k| (faces.mesh.vertices[k] - faces.mesh.vertices[n + k]).norm())
        .fold(0.0, f64::max);
    assert!(
        gap > 0.05,
        "the root crack's faces are {gap} m apart at most"
    );
}

#[test]
fn below_its_strength_the_beam_steps_as_the_elastic_one() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/brittle_beam.toml");
    let text = std::fs::read_to_string(path).expect("readable");
    let line = text
        .lines()
        .find(|l| l.starts_with("fracture"))
        .expect("the scene fractures");
    let strong =
        Scene::from_toml_str(&text.replace(line, "fracture = { stress = 1.0e9 }")).expect("parses");
    let plain = Scene::from_toml_str(&text.replace(line, "")).expect("parses");
    let (mut a, mut b) = (build(&strong), build(&plain));
    for _ in 0..30 {
        a.step().expect("steps");
        b.step().expect("steps");
    }
    let (_, sa) = a.solids().next().expect("one solid");
    let (_, sb) = b.solids().next().expect("one solid");
    assert!(sa.fracture().is_some() && sb.fracture().is_none());
    assert!(sa.fracture().expect("it fractures").cracks().is_empty());
    assert!(sa.positions == sb.positions, "positions differ");
    assert!(sa.velocities == sb.velocities, "velocities differ");
}

#[test]
fn a_snapshot_taken_while_a_crack_runs_continues_bit_for_bit() {
    let scene = shipped("brittle_beam.toml");
    let mut world = build(&scene);
    // Step until a crack exists but the beam holds.
    loop {
        world.step().expect("steps");
        let (_, solid) = world.solids().next().expect("one solid");
        if !solid.fracture().expect("it fractures").cracks().is_empty() {
            break;
        }
        assert!(world.frame().step < 150, "no crack started");
    }
    let state = world.state();
    let restored = build(&scene).restored(&state).expect("the state fits");
    let mut restored = restored;
    for _ in 0..40 {
        world.step().expect("steps");
        restored.step().expect("steps");
    }
    let (_, a) = world.solids().next().expect("one solid");
    let (_, b) = restored.solids().next().expect("one solid");
    assert!(a.positions == b.positions, "positions differ");
    assert!(a.velocities == b.velocities, "velocities differ");
    assert!(a.fracture() == b.fracture(), "cracks differ");
    assert_eq!(fragments(&world), fragments(&restored));
}

#[test]
fn a_snapshot_whose_cracks_do_not_fit_is_refused() {
    let scene = shipped("brittle_beam.toml");
    let mut world = build(&scene);
    while world
        .solids()
        .next()
        .and_then(|(_, s)| s.fracture())
        .is_some_and(|f| f.cracks().is_empty())
    {
        world.step().expect("steps");
    }
    let good = world.state();
    let refused = |change: &dyn Fn(&mut meshless_engine::solid::FractureSnapshot)| {
        let mut state = good.clone();
        let meshless_engine::SystemState::Solid { solid, .. } = &mut state.systems[0] else {
            panic!("the beam is the only system");
        };
        change(solid.fracture.as_mut().expect("it fractures"));
        match build(&scene).restored(&state) {
            Ok(_) => panic!("a state that does not fit was restored"),
            Err(error) => error.to_string(),
        }
    };
    let error = refused(&|f| {
        f.extra.pop();
    });
    assert!(error.contains("crack terms"), "{error}");
    let error = refused(&|f| f.extra[0] = -1.0);
    assert!(error.contains("crack term"), "{error}");
    let error = refused(&|f| {
        let first = f.cracks[0].clone();
        f.cracks = vec![first; 65];
    });
    assert!(error.contains("cracks"), "{error}");
    let error = refused(&|f| f.fragments[3] = 1_000_000);
    assert!(error.contains("fragment label"), "{error}");
    // A scene without fracture refuses a state with cracks.
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/brittle_beam.toml"),
    )
    .expect("readable");
    let line = text
        .lines()
        .find(|l| l.starts_with("fracture"))
        .expect("fractures");
    let elastic = Scene::from_toml_str(&text.replace(line, "")).expect("parses");
    let Err(error) = build(&elastic).restored(&good).map(|_| ()) else {
        panic!("an elastic solid took a state with cracks");
    };
    let error = error.to_string();
    assert!(error.contains("fracture"), "{error}");
}

/// A 2D plate hanging from anchors along its top, solved statically, with
/// the notch `notch` (a TOML inline table).
fn hanging_plate(notch: &str) -> World {
    let text = format!(
        r#"
        dimension = 2
        gravity = [0.0, -9.81, 0.0]
        [domain]
        min = [-1.0, -1.0, 0.0]
        max = [1.0, 1.0, 0.0]
        [time]
        dt = 0.01
        [[systems]]
        kind = "solid"
        shape = {{ type = "box", half_extents = [0.2, 0.3, 0.05] }}
        position = [0.0, 0.0, 0.0]
        spacing = 0.02
        young = 1e6
        poisson = 0.0
        integrator = "implicit"
        implicit = {{ scheme = "static", linear_solver = "cholesky" }}
        anchors = [{{ min = [-0.3, 0.25, 0.0], max = [0.3, 0.4, 0.0] }}]
        fracture = {{ stress = 1e9, notches = [{notch}] }}
        "#
    );
    build(&Scene::from_toml_str(&text).expect("the scene parses"))
}

#[test]
fn a_static_solid_whose_cracks_free_a_piece_faults_naming_the_scheme() {
    // A notch across the whole width below the anchors: the lower part
    // hangs from nothing, and a static solve has no equilibrium for it.
    let mut cut =
        hanging_plate("{ center = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 0.0], radius = 0.5 }");
    let error = cut.step().expect_err("a free piece in statics");
    let StepError::FragmentFreeInStatics {
        system,
        particles,
        step,
    } = error
    else {
        panic!("faulted otherwise: {error}");
    };
    assert_eq!((system, step), (0, 1));
    assert_eq!(particles, 20 * 15, "the lower half of the 20 x 30 plate");
    assert!(error.to_string().contains("backward_euler"), "{error}");

    // A notch half across: every piece still hangs, and it steps.
    let mut notched =
        hanging_plate("{ center = [-0.2, 0.0, 0.0], normal = [0.0, 1.0, 0.0], radius = 0.2 }");
    for _ in 0..3 {
        notched.step().expect("the notched plate hangs");
    }
}

/// The shipped beam resampling by `resample` (a TOML inline table), its
/// frames carrying ids.
fn resampling_beam(resample: &str) -> Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/brittle_beam.toml");
    let text = std::fs::read_to_string(path).expect("the shipped scene");
    let text = text
        .replace(
            "advance = 0.5 }",
            &format!("advance = 0.5, resample = {resample} }}"),
        )
        .replace(
            r#"fields = ["velocity", "fragment"]"#,
            r#"fields = ["velocity", "fragment", "id"]"#,
        );
    assert!(text.contains("resample"), "the beam's fracture table moved");
    Scene::from_toml_str(&text).expect("the scene parses")
}

#[test]
fn a_resampling_beam_grows_its_frames_keeping_ids_and_continues_from_a_snapshot() {
    let scene = resampling_beam("{ q_min = 10 }");
    let mut world = build(&scene);
    let built = world.frame().particle_count;
    let first_ids = world.frame().ids.expect("ids asked for");
    let mut grew = None;
    for _ in 0..150 {
        let info = world.step().expect("the beam steps");
        let frame = world.frame();
        assert_eq!(frame.added, info.added);
        if info.added > 0 {
            grew = Some(frame);
            break;
        }
    }
    let frame = grew.expect("the crack's neighbours split within 150 steps");
    // The frame holds the new particles after the old, whose ids stay.
    let ids = frame.ids.expect("ids");
    assert_eq!(frame.particle_count, built + frame.added as usize);
    assert_eq!(ids[..built], first_ids[..]);
    assert!(
        ids[built..]
            .iter()
            .copied()
            .eq(built as u32..frame.particle_count as u32)
    );
    assert_eq!(frame.solids[0].count, frame.particle_count);
    // A snapshot of the grown world continues bit for bit.
    let state = world.state();
    let mut restored = build(&scene).restored(&state).expect("the state fits");
    for _ in 0..30 {
        world.step().expect("steps");
        restored.step().expect("steps");
    }
    let (_, a) = world.solids().next().expect("one solid");
    let (_, b) = restored.solids().next().expect("one solid");
    assert!(a.positions == b.positions, "positions differ");
    assert!(a.fracture() == b.fracture(), "cracks differ");
}

#[test]
fn a_beam_that_would_outgrow_its_limit_faults_with_the_reason_and_nothing_changed() {
    let built = build(&shipped("brittle_beam.toml")).frame().particle_count;
    let scene = resampling_beam(&format!("{{ max_particles = {} }}", built + 1));
    let mut world = build(&scene);
    let error = loop {
        let before = world.state();
        match world.step() {
            Ok(_) => assert!(world.frame().step < 150, "never outgrew its limit"),
            Err(error) => {
                assert_eq!(world.state(), before, "a refused step changed the world");
                break error;
            }
        }
    };
    let StepError::ParticleLimit { system, .. } = &error else {
        panic!("faulted otherwise: {error}");
    };
    assert_eq!(*system, 0);
    assert!(error.to_string().contains("max_particles"), "{error}");

    // A limit under the particles built is refused with the key named.
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/brittle_beam.toml"),
    )
    .expect("the shipped scene")
    .replace(
        "advance = 0.5 }",
        "advance = 0.5, resample = { max_particles = 10 } }",
    );
    let error = Scene::from_toml_str(&text)
        .expect("parses")
        .check(&BuildOptions::default())
        .expect_err("a limit under the built count");
    assert!(
        error.to_string().contains("resample.max_particles"),
        "{error}"
    );
}

/// Mass, linear momentum and angular momentum about z of a solid.
fn totals(solid: &meshless_engine::solid::ElasticSolid) -> (f64, f64, f64) {
    let mut mass = 0.0;
    let mut momentum = meshless_engine::math::Vector::zeros();
    let mut angular = 0.0;
    for ((x, v), m) in solid
        .positions
        .iter()
        .zip(&solid.velocities)
        .zip(solid.masses())
    {
        mass += m;
        momentum += v * *m;
        angular += m * (x.x * v.y - x.y * v.x);
    }
    (mass, momentum.norm(), angular)
}

/// The shipped ductile bar (tutorial Figure 8's ductile fracture): spun
/// about its centre, its middle flows, thins and tears, and the halves
/// fly apart; resampling keeps the particles beside the tear sampled;
/// mass, momentum and angular momentum hold through it all.
#[test]
fn the_spinning_ductile_bar_necks_and_tears_in_two_with_resampling_keeping_its_samples() {
    let mut world = build(&shipped("ductile_spin.toml"));
    let (_, solid) = world.solids().next().expect("one solid");
    let built = solid.len();
    let (mass, _, angular) = totals(solid);
    // The top and bottom particles of the reference columns at the
    // centre, halfway out and near the ends.
    let rest = solid.rest_positions().to_vec();
    let at = |x: f64, y: f64| {
        rest.iter()
            .position(|r| (r.x - x).abs() < 1e-9 && (r.y - y).abs() < 1e-9)
            .expect("a particle there")
    };
    let columns: Vec<(usize, usize)> = [0.005, 0.095, 0.195]
        .iter()
        .map(|&x| (at(x, 0.025), at(x, -0.025)))
        .collect();
    let mut necked = None;
    let mut halves = None;
    for step in 1..=100 {
        world.step().expect("the bar steps");
        let (_, solid) = world.solids().next().expect("one solid");
        let fracture = solid.fracture().expect("it fractures");
        if necked.is_none() && !fracture.cracks().is_empty() {
            necked = Some(
                columns
                    .iter()
                    .map(|&(a, b)| (solid.positions[a] - solid.positions[b]).norm())
                    .collect::<Vec<f64>>(),
            );
        }
        // What the next step's start will do meets Eq. 71 along the tear.
        if step % 10 == 0 && solid.radii().is_some() {
            let mut next = solid.clone();
            next.resample().expect("within its limit");
            let (q, count) = next.sampling();
            let short = (0..next.len())
                .filter(|&i| {
                    q[i] < (10.0f64).min(count[i]) - 1e-9
                        && next.support_radius(i) / 3f64.sqrt() >= 0.5 * 0.02
                })
                .count();
            // Only a particle a crack runs through (no room on its side)
            // may stay short while it could still split.
            assert!(
                short * 100 <= next.len(),
                "step {step}: {short} of {} short",
                next.len()
            );
        }
        let (m, p, l) = totals(solid);
        assert!((m - mass).abs() < 1e-12 * mass, "step {step}: mass {m}");
        assert!(p < 1e-10 * mass, "step {step}: momentum {p}");
        assert!(
            (l - angular).abs() < 1e-9 * angular,
            "step {step}: angular momentum {l} of {angular}"
        );
        let parts = piece_masses(solid);
        if parts.len() >= 2 && parts[1] > 0.45 * mass {
            halves = Some((step, solid.len()));
            break;
        }
    }
    // Necked first: at the first crack the middle is thinner than
    // halfway out, and that than near the ends, which barely thinned.
    let thickness = necked.expect("a crack started within 0.2 s");
    assert!(
        thickness[0] < thickness[1]
            && thickness[1] < thickness[2]
            && thickness[0] < 0.75 * thickness[2],
        "no neck: {thickness:?}"
    );
    assert!(thickness[2] > 0.049, "{thickness:?}");
    // Then in two halves, and grown where the tear split particles.
    let (step, count) = halves.expect("the bar tore in two within 0.2 s");
    assert!(count > built, "no particle split by step {step}");
}

/// The shipped notched bar, spun: a crack runs from the notch's tip
/// straight across the ligament (normal to the tension) and the bar
/// snaps into two halves; the same bar without its notch does not crack
/// in the same time.
#[test]
fn the_spinning_notched_bar_snaps_at_its_notch_and_the_plain_one_holds() {
    let scene = shipped("notched_spin.toml");
    let mut world = build(&scene);
    let step =
        steps_until_halves(&mut world, 100).expect("the notched bar snapped in two within 0.05 s");
    let (_, solid) = world.solids().next().expect("one solid");
    let fracture = solid.fracture().expect("it fractures");
    // The notch (crack 0) grew from its tip at (0, 0) across the whole
    // ligament, within 20 degrees of normal to the tension (the bar's
    // axis); every other crack started in the fracture zone beside it.
    let cracks = fracture.cracks();
    let lowest = cracks[0]
        .vertices()
        .iter()
        .min_by(|a, b| a.y.total_cmp(&b.y))
        .expect("vertices");
    assert!(lowest.y < -0.025, "the notch's crack stopped at {lowest:?}");
    let angle = (lowest.x / -lowest.y).atan().to_degrees();
    assert!(
        angle.abs() < 20.0,
        "the crack ran {angle} degrees off normal"
    );
    for crack in &cracks[1..] {
        assert!(
            crack.vertices().iter().all(|v| v.x.abs() < 0.1),
            "a crack started away from the notch"
        );
    }
    // Two halves: every particle left of the fracture zone in one
    // fragment, every one right of it in another.
    let labels = fracture.fragments();
    let rest = solid.rest_positions();
    let side = |left: bool| -> std::collections::BTreeSet<u32> {
        labels
            .iter()
            .zip(rest)
            .filter(|(_, x)| (x.x < 0.0) == left && x.x.abs() > 0.1)
            .map(|(&k, _)| k)
            .collect()
    };
    let (left, right) = (side(true), side(false));
    assert!(
        left.len() == 1 && right.len() == 1 && left != right,
        "{left:?} {right:?}"
    );
    // Without the notch, nothing cracks in twice that time.
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/notched_spin.toml"),
    )
    .expect("the shipped scene");
    let start = text.find(", notches = [").expect("the notch");
    let end = text[start..].find("] }").expect("its end") + start + 1;
    let plain = format!("{}{}", &text[..start], &text[end..]);
    let mut world = build(&Scene::from_toml_str(&plain).expect("the plain bar parses"));
    for _ in 0..2 * step {
        world.step().expect("the plain bar steps");
    }
    let (_, solid) = world.solids().next().expect("one solid");
    assert!(solid.fracture().expect("fractures").cracks().is_empty());
}

/// The shipped 3D notched bar, spun: a crack runs from the notch across
/// the section and the bar snaps into two halves; frames carry the
/// embedded surface while it is whole and then one closed surface per
/// half, each holding about half the bar's volume, the two apart.
#[test]
fn the_3d_notched_bar_snaps_in_two_each_half_framed_by_its_own_closed_surface() {
    let mut world = build(&shipped("notched_spin_3d.toml"));
    let whole = world.frame().solid_surfaces[0].mesh.clone();
    assert!(whole.is_closed());
    let bar = whole.signed_volume();
    assert!((bar - 0.5 * 0.06 * 0.06).abs() < 1e-9, "bar volume {bar}");
    let step =
        steps_until_halves(&mut world, 60).expect("the notched bar snapped in two within 0.03 s");
    for _ in 0..30 {
        world.step().expect("the halves step");
    }
    let frame = world.frame();
    let surface = &frame.solid_surfaces[0].mesh;
    assert!(surface.is_closed(), "step {step}: an open surface");
    let pieces = surface_pieces(surface);
    assert_eq!(pieces.len(), 2, "step {step}: {} surfaces", pieces.len());
    // Every vertex moved with the material: none is left behind where the
    // bar was (a vertex with no particle of its piece in sight once stayed
    // put, a tongue of surface reaching back to the notch).
    let (_, solid) = world.solids().next().expect("one solid");
    assert_eq!(
        stray(surface, &solid.positions, 0.01),
        0,
        "vertices two spacings from every particle"
    );
    for (volume, _) in &pieces {
        assert!(
            (0.40 * bar..0.52 * bar).contains(volume),
            "a half holds {volume} of the bar's {bar} m^3"
        );
    }
    let apart = (pieces[0].1 - pieces[1].1).norm();
    assert!(apart > 0.2, "the halves' surfaces are {apart} m apart");
}

/// The vertices of `surface` farther than `distance` from every particle.
fn stray(
    surface: &meshless_engine::geometry::TriMesh,
    particles: &[Vector3<f64>],
    distance: f64,
) -> usize {
    surface
        .vertices
        .iter()
        .filter(|v| particles.iter().all(|x| (x - *v).norm() > distance))
        .count()
}

/// The shipped 3D ductile bar, spun: it necks and tears in two halves
/// with resampling beside the tear, steps on stably while they fly
/// apart, keeps its mass and momentum, and frames one closed surface per
/// piece, the halves holding most of the bar.
#[test]
fn the_3d_ductile_bar_tears_in_two_each_half_framed_by_its_own_closed_surface() {
    let mut world = build(&shipped("ductile_spin_3d.toml"));
    let (_, solid) = world.solids().next().expect("one solid");
    let (built, (mass, _, angular)) = (solid.len(), totals(solid));
    let bar = world.frame().solid_surfaces[0].mesh.signed_volume();
    // 0.2 s: the bar tears at about 0.12 s, and its halves fly on (with
    // gradients kept beside the cracks at 3D's condition bound of 1e3 it
    // blew up at 0.19 s).
    let mut torn = None;
    for step in 1..=100 {
        world.step().expect("the bar steps");
        let (_, solid) = world.solids().next().expect("one solid");
        let parts = piece_masses(solid);
        if torn.is_none() && parts.len() >= 2 && parts[1] > 0.4 * mass {
            torn = Some(step);
        }
        // Whole, split or torn, every frame carries the bar's surface.
        if step % 10 == 0 {
            assert_eq!(world.frame().solid_surfaces.len(), 1, "step {step}");
        }
    }
    let step = torn.expect("the bar tore in two within 0.2 s");
    let (_, solid) = world.solids().next().expect("one solid");
    assert!(solid.len() > built, "no particle split by step {step}");
    let (m, p, l) = totals(solid);
    assert!((m - mass).abs() < 1e-12 * mass, "mass {m} of {mass}");
    assert!(p < 1e-10 * mass, "momentum {p}");
    assert!(
        (l - angular).abs() < 1e-9 * angular,
        "angular momentum {l} of {angular}"
    );
    let frame = world.frame();
    let surface = &frame.solid_surfaces[0].mesh;
    assert!(surface.is_closed(), "an open surface");
    let pieces = surface_pieces(surface);
    assert!(pieces.len() >= 2, "{} surfaces", pieces.len());
    for (volume, _) in &pieces[..2] {
        assert!(
            (0.3 * bar..0.6 * bar).contains(volume),
            "a half holds {volume} of the bar's {bar} m^3"
        );
    }
    assert!((pieces[0].1 - pieces[1].1).norm() > 0.2, "the halves apart");
    // Every vertex moved with its piece: the neck's flow stretched the
    // material between particles, so a few lie past two spacings from
    // the nearest (two of 6,672 here, one past three), none past five.
    assert_eq!(stray(surface, &solid.positions, 0.05), 0);
}

/// The closed components of a surface (triangles joined by shared
/// vertices): each one's enclosed volume and centroid, largest first.
fn surface_pieces(surface: &meshless_engine::geometry::TriMesh) -> Vec<(f64, Vector3<f64>)> {
    let mut root: Vec<usize> = (0..surface.vertices.len()).collect();
    fn find(root: &mut [usize], mut v: usize) -> usize {
        while root[v] != v {
            root[v] = root[root[v]];
            v = root[v];
        }
        v
    }
    for t in &surface.triangles {
        for k in 0..3 {
            let (a, b) = (
                find(&mut root, t[k] as usize),
                find(&mut root, t[(k + 1) % 3] as usize),
            );
            root[a] = b;
        }
    }
    let mut pieces: std::collections::BTreeMap<usize, (f64, Vector3<f64>, usize)> =
        Default::default();
    for t in &surface.triangles {
        let r = find(&mut root, t[0] as usize);
        let [a, b, c] = t.map(|v| surface.vertices[v as usize]);
        let piece = pieces.entry(r).or_default();
        piece.0 += a.dot(&b.cross(&c)) / 6.0;
        piece.1 += a + b + c;
        piece.2 += 3;
    }
    let mut pieces: Vec<(f64, Vector3<f64>)> = pieces
        .into_values()
        .map(|(volume, sum, count)| (volume, sum / count as f64))
        .collect();
    pieces.sort_by(|a, b| b.0.total_cmp(&a.0));
    pieces
}

/// Why the shipped ductile bar needs no resampling for its flow: its
/// kernels are Lagrangian, so stretching alone leaves Eq. 71's count as
/// built; and with the reference re-based on the flow (the tutorial's
/// Eulerian view, `plasticity.rebase`), the neck's near-isochoric flow
/// squeezes the section as it stretches the bar, bringing neighbours
/// into the support across it as it pulls them out along it, so the
/// count along the neck does not fall either.
#[test]
fn the_spun_bar_s_flow_re_based_does_not_thin_eq_71_s_count_along_its_neck() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/ductile_spin.toml");
    let text = std::fs::read_to_string(path).expect("the shipped scene");
    let fracture = "fracture = { plastic_strain = 0.6, resample = { q_min = 10 } }";
    assert!(text.contains(fracture) && text.contains("max = 3.0 }"));
    let text = text
        .replace(fracture, "")
        .replace("max = 3.0 }", "max = 3.0, rebase = 0.1 }");
    let mut world = build(&Scene::from_toml_str(&text).expect("the re-based bar parses"));
    let (_, solid) = world.solids().next().expect("one solid");
    let built = solid.rest_positions().to_vec();
    let (count, _) = solid.sampling();
    // The middle columns, where the bar necks.
    let neck: Vec<usize> = (0..built.len())
        .filter(|&i| built[i].x.abs() < 0.03)
        .collect();
    for _ in 0..60 {
        world.step().expect("the bar steps");
    }
    let (_, solid) = world.solids().next().expect("one solid");
    let moved = solid
        .rest_positions()
        .iter()
        .zip(&built)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max);
    assert!(moved > 0.005, "the reference was re-based ({moved} m)");
    let (now, _) = solid.sampling();
    let (before, after): (f64, f64) = neck
        .iter()
        .fold((0.0, 0.0), |(b, a), &i| (b + count[i], a + now[i]));
    let lost = neck.iter().map(|&i| count[i] - now[i]).fold(0.0, f64::max);
    // In all the neck gains neighbours (264 to 288 here); a few particles
    // on its edges lose one as the section narrows.
    assert!(
        after > before && lost <= 1.0,
        "the neck's count {before} -> {after}; a particle lost {lost}"
    );
}
