//! Golden runs: the shipped dam break, jelly drop, floating box, beams
//! (elastic and modal), the small modal beam of the fixtures and the
//! tutorial's Figure 13 stretch, on one
//! thread, give the same bits as when their golden files were written.
//!
//! Refactors that only move code must not change a single floating-point
//! operation; this is the test that says so. Each frame (or the solve's
//! result) is reduced to a 64-bit FNV-1a hash of the bit patterns of
//! every number it carries, one line per frame, and compared line by line
//! with `tests/golden/NAME.txt`. A change that alters the physics on
//! purpose regenerates the files with `MESHLESS_BLESS_GOLDEN=1 cargo test
//! -p meshless-tests --test golden` and says why in its commit.

use meshless_engine::scene::{IntegratorKind, SystemSpec};
use meshless_engine::solid::LinearSolver;
use meshless_engine::{BuildOptions, Frame, Scene};
use meshless_tests::fixture;
use meshless_validation::design::{Stretch, stretch_params};
use std::path::PathBuf;

/// FNV-1a over 64-bit words.
#[derive(Debug)]
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
    fn word(&mut self, w: u64) {
        for byte in w.to_le_bytes() {
            self.0 ^= u64::from(byte);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    fn real(&mut self, x: f64) {
        self.word(x.to_bits());
    }
    fn reals(&mut self, xs: impl IntoIterator<Item = f64>) {
        for x in xs {
            self.real(x);
        }
    }
}

/// Every number a frame carries: clock, solver report, fields, bodies,
/// surfaces.
fn frame_hash(frame: &Frame) -> u64 {
    let mut h = Fnv::new();
    h.word(frame.step);
    h.real(frame.time);
    h.word(u64::from(frame.substeps));
    h.real(frame.substep_dt);
    h.word(u64::from(frame.solver_iterations));
    h.real(frame.density_error);
    h.word(frame.particle_count as u64);
    for field in &frame.fields {
        h.word(field.components as u64);
        for v in &field.values {
            h.word(u64::from(v.to_bits()));
        }
    }
    for body in &frame.bodies {
        h.word(body.system as u64);
        h.reals(body.position);
        h.reals(body.orientation);
        h.reals(body.velocity);
        h.reals(body.angular_velocity);
    }
    for solid in &frame.solids {
        h.word(solid.system as u64);
        h.word(solid.first as u64);
        h.word(solid.count as u64);
    }
    for surface in &frame.solid_surfaces {
        h.word(surface.system as u64);
        h.reals(surface.mesh.vertices.iter().flat_map(|v| [v.x, v.y, v.z]));
        h.reals(surface.normals.iter().flat_map(|n| [n.x, n.y, n.z]));
    }
    if let Some(surface) = &frame.surface {
        h.reals(surface.vertices.iter().flat_map(|v| [v.x, v.y, v.z]));
    }
    h.0
}

/// Runs `work` on a pool of one thread, so the result cannot depend on
/// how rayon splits the loops.
fn on_one_thread<T: Send>(work: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool")
        .install(work)
}

/// A shipped scene, as its file says.
fn shipped(file: &str) -> Scene {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(file);
    let text = std::fs::read_to_string(&path).expect("the shipped scene is readable");
    Scene::from_toml_str(&text).expect("the shipped scene parses")
}

/// The shipped cantilever stepped implicitly with `solver`.
fn implicit_beam(solver: LinearSolver) -> Scene {
    let mut scene = shipped("elastic_beam.toml");
    let SystemSpec::Solid(solid) = &mut scene.systems[0] else {
        panic!("the beam's first system is the solid")
    };
    solid.integrator = IntegratorKind::Implicit;
    solid.implicit.linear_solver = solver;
    scene.time.dt = 0.01;
    scene
}

/// `steps` steps of `scene`, one line per step: step and hash.
fn run_scene(scene: &Scene, steps: usize) -> Vec<String> {
    on_one_thread(|| {
        let mut world = scene
            .build(&BuildOptions::default())
            .expect("the shipped scene builds");
        let mut lines = vec![format!("0 {:016x}", frame_hash(&world.frame()))];
        for _ in 0..steps {
            world.step().expect("a stable step");
            let frame = world.frame();
            lines.push(format!("{} {:016x}", frame.step, frame_hash(&frame)));
        }
        lines
    })
}

/// Compares `lines` with `tests/golden/NAME.txt`, or writes the file when
/// `MESHLESS_BLESS_GOLDEN` is set.
fn check(name: &str, lines: &[String]) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("golden")
        .join(format!("{name}.txt"));
    let text = lines.join("\n") + "\n";
    if std::env::var_os("MESHLESS_BLESS_GOLDEN").is_some() {
        std::fs::write(&path, text).expect("the golden file is writable");
        return;
    }
    let golden = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: {e}; bless it first", path.display()));
    for (k, (want, got)) in golden.lines().zip(text.lines()).enumerate() {
        assert_eq!(
            got,
            want,
            "{name}: line {k} (step, hash) differs from {}: the run no longer gives the same bits",
            path.display()
        );
    }
    assert_eq!(
        golden.lines().count(),
        text.lines().count(),
        "{name}: number of lines"
    );
}

/// The shipped 3D dam break (6,750 particles, WCSPH): 0.2 s.
#[test]
fn dam_break_frames_are_bit_identical() {
    check("dam_break", &run_scene(&shipped("dam_break.toml"), 20));
}

/// The shipped jelly drop (explicit MLS solid with an embedded surface,
/// a static ball): 0.4 s, through the landing on the ball.
#[test]
fn jelly_drop_frames_are_bit_identical() {
    check("jelly_drop", &run_scene(&shipped("jelly_drop.toml"), 40));
}

/// The shipped floating box: DFSPH with a dynamic rigid body.
#[test]
fn floating_box_frames_are_bit_identical() {
    check(
        "floating_box",
        &run_scene(&shipped("floating_box.toml"), 10),
    );
}

/// The shipped 2D cantilever, explicit.
#[test]
fn elastic_beam_frames_are_bit_identical() {
    check(
        "elastic_beam",
        &run_scene(&shipped("elastic_beam.toml"), 20),
    );
}

/// The cantilever by backward Euler, Newton steps solved by conjugate
/// gradients and by sparse Cholesky.
#[test]
fn implicit_beam_frames_are_bit_identical() {
    check(
        "implicit_beam_cg",
        &run_scene(&implicit_beam(LinearSolver::ConjugateGradient), 10),
    );
    check(
        "implicit_beam_cholesky",
        &run_scene(&implicit_beam(LinearSolver::Cholesky), 10),
    );
}

/// The small modal beam (`tests/fixtures/small_modal.toml`: a modal EFG
/// cantilever of a few hundred nodes in 12 modes with warping, clamped,
/// falling under gravity): its build (octree, EFG assembly, eigensolve,
/// rotation modes, embedded skin) and 10 steps, each frame's node
/// positions and deformed skin.
#[test]
fn small_modal_frames_are_bit_identical() {
    let scene = Scene::from_toml_str(&fixture("small_modal")).expect("the fixture parses");
    check("small_modal", &run_scene(&scene, 10));
}

/// The shipped modal beam (Guo–Qin's Table 1 bar: 1,008 EFG nodes in 64
/// modes with warping, clamped, sagging under gravity): its build and 10
/// frames of 1/60 s.
#[test]
fn modal_beam_frames_are_bit_identical() {
    check("modal_beam", &run_scene(&shipped("modal_beam.toml"), 10));
}

/// Figure 13's stretch with the volume energy: the design's displacements,
/// solver report and measured volume changes.
#[test]
fn figure_13_stretch_is_bit_identical() {
    let result = on_one_thread(|| {
        Stretch::default()
            .solve(&stretch_params(true))
            .expect("the stretch solves")
    });
    let mut h = Fnv::new();
    h.reals(
        result
            .solution
            .displacements
            .iter()
            .flat_map(|u| [u.x, u.y, u.z]),
    );
    let lines = vec![
        format!("particles {}", result.particles),
        format!("iterations {}", result.solution.info.iterations),
        format!(
            "linear_iterations {}",
            result.solution.info.linear_iterations
        ),
        format!(
            "gradient_norm {:016x}",
            result.solution.info.gradient_norm.to_bits()
        ),
        format!("volume_change {:016x}", result.volume_change.to_bits()),
        format!(
            "discrete_volume_change {:016x}",
            result.discrete_volume_change.to_bits()
        ),
        format!("handle_error {:016x}", result.handle_error.to_bits()),
        format!("displacements {:016x}", h.0),
    ];
    check("stretch", &lines);
}
