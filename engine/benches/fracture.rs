//! What fracture costs an MLS solid (tutorial Section 7.3), on a 2D plate
//! of about 2.5k, 10k and 40k particles whose halves are pulled apart
//! (mode I). Two tables:
//!
//! - no crack running: the plate far below its strength, stepped with
//!   fracture off and on in turn: the step with the fracture update
//!   against the step alone, and the update's scan for particles past
//!   the threshold (the one pass over every particle);
//! - one crack running: the plate allowed one crack, which starts at the
//!   most loaded particle and runs across; over the steps while it runs,
//!   the elastic step, the whole update, its refit of the pairs near the
//!   moved front (terms, shape functions, fragments), the particles
//!   refitted and the time per refitted particle. A cache whose cost
//!   follows the particles a crack touches shows as a refit time and a
//!   time per refit that do not grow with the plate. (A solid holding its
//!   most cracks scans nothing.)
//! - resampling (tutorial Eq. 71): the same running crack with
//!   `resample` on: a step start that splits (a rebuild of the solid's
//!   neighbourhoods), one that finds nothing to split (a pass over the
//!   pairs' terms), the particles a split adds, the elastic step and its
//!   sub-steps before the first split and after.
//!
//! - each piece's closed surface: a 3D block cut in two by a notch
//!   through its middle, the surface a frame carries (every piece's own,
//!   cut from the block's reference surface on a grid of `surface_cell`
//!   spacings, the default half and a quarter; the volume the surfaces
//!   hold against the block's says what the finer cell buys):
//!   its triangles, the milliseconds the first frame after a change of the
//!   cracks takes to build it, and those of a frame that finds it kept.
//!
//! Prints the tables; asserts nothing.
//!
//!     cargo bench -p meshless-engine --bench fracture

use meshless_engine::approx::mls::Order;
use meshless_engine::geometry::{MeshSdf, Shape, TriMesh};
use meshless_engine::math::{Real, Vector};
use meshless_engine::solid::fracture::{Discontinuity, Notch, Resampling};
use meshless_engine::solid::{
    ElasticSolid, FractureParams, Integrator, Material, Obstacles, SolidParams,
};
use std::time::Instant;

#[path = "common/smoke.rs"]
mod smoke;

const SPACING: Real = 0.01;
const DT: Real = 2e-4;

/// The benchmark's material (E = 1 MPa, explicit, a support of two
/// spacings) in `dim` dimensions, fracturing with `fracture` (or not).
fn params(dim: usize, fracture: Option<FractureParams>) -> SolidParams {
    let young = 1e6;
    SolidParams {
        dim,
        spacing: SPACING,
        density: 1000.0,
        young,
        material: Material::from_young_poisson(young, 0.3, 0.0),
        order: Order::Linear,
        support: 2.0 * SPACING,
        hourglass: 0.1,
        damping: 0.0,
        friction: 0.0,
        integrator: Integrator::Explicit { cfl: 0.5 },
        plasticity: None,
        fracture,
    }
}

/// The plate, fracturing with `fracture` (or not).
fn plate(side: usize, fracture: Option<FractureParams>) -> ElasticSolid {
    let params = params(2, fracture);
    let half = 0.5 * side as Real * SPACING;
    let rest = Shape::Box {
        half_extents: Vector::new(half, half, 0.0),
    }
    .sample_volume(SPACING, 2)
    .expect("plate");
    let velocities = rest
        .iter()
        .map(|x| Vector::new(0.0, 0.5 * x.y.signum(), 0.0))
        .collect();
    let n = rest.len();
    ElasticSolid::new(
        params,
        rest,
        velocities,
        vec![false; n],
        Obstacles::default(),
    )
    .expect("plate")
}

/// Milliseconds of `f`.
fn timed<T>(f: impl FnOnce() -> T) -> (T, Real) {
    let start = Instant::now();
    let out = f();
    (out, start.elapsed().as_secs_f64() * 1e3)
}

fn main() {
    let sides = smoke::pick(vec![50, 100, 200], vec![20]);
    let steps = smoke::pick(40, 2);
    let threads = rayon::current_num_threads();
    println!(
        "no crack running: the plate pulled apart far below its strength, fracture off and on in turn; ms per step, median over {steps} steps ({threads} threads)"
    );
    println!(
        "| particles | step, no fracture | step and update, fracture on | overhead | scan (every particle) |"
    );
    println!("|---|---|---|---|---|");
    for &side in &sides {
        let mut off = plate(side, None);
        let mut on = plate(side, Some(FractureParams::brittle(1e9)));
        let gravity = Vector::zeros();
        let (mut plain, mut fracturing, mut scan) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..steps {
            let ((), t) = timed(|| {
                off.step(DT, &gravity, 100);
            });
            plain.push(t);
            let (update, t) = timed(|| {
                on.step(DT, &gravity, 100);
                on.fracture_step().expect("bounded")
            });
            assert_eq!(update.started, 0, "a crack started far below the strength");
            fracturing.push(t);
            scan.push(update.scan.as_secs_f64() * 1e3);
        }
        let (plain, fracturing) = (median(&mut plain), median(&mut fracturing));
        println!(
            "| {:>9} | {plain:>17.2} | {fracturing:>28.2} | {:>+7.1} % | {:>21.3} |",
            on.len(),
            100.0 * (fracturing / plain - 1.0),
            median(&mut scan),
        );
    }

    println!();
    println!(
        "one crack running across the plate pulled apart: ms per step, median over {steps} steps with refits ({threads} threads)"
    );
    println!(
        "| criterion    | particles | elastic step | whole update | refit (near the crack) | refitted / update | µs per refit |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (name, discontinuity) in [
        ("transparency", Discontinuity::Transparency { kappa: 1.0 }),
        ("visibility", Discontinuity::Visibility),
    ] {
        let mut fracture = FractureParams::brittle(2e4);
        fracture.discontinuity = discontinuity;
        fracture.max_cracks = 1;
        for &side in &sides {
            let mut solid = plate(side, Some(fracture));
            let gravity = Vector::zeros();
            let (mut elastic, mut whole, mut refit, mut refitted) =
                (Vec::new(), Vec::new(), Vec::new(), Vec::new());
            let mut taken = 0;
            while whole.len() < steps && taken < 2000 {
                taken += 1;
                let ((), t) = timed(|| {
                    solid.step(DT, &gravity, 100);
                });
                let (update, t_update) = timed(|| solid.fracture_step().expect("bounded"));
                let running = solid.fracture().is_some_and(|f| !f.cracks().is_empty());
                if running && update.refitted > 0 && update.started == 0 {
                    elastic.push(t);
                    whole.push(t_update);
                    refit.push(update.refit.as_secs_f64() * 1e3);
                    refitted.push(Real::from(update.refitted));
                }
            }
            let mut per_refit: Vec<Real> = refit
                .iter()
                .zip(&refitted)
                .map(|(t, n)| t * 1e3 / n)
                .collect();
            println!(
                "| {name:<12} | {:>9} | {:>12.2} | {:>12.3} | {:>22.3} | {:>17.0} | {:>12.1} |",
                solid.len(),
                median(&mut elastic),
                median(&mut whole),
                median(&mut refit),
                median(&mut refitted),
                median(&mut per_refit),
            );
        }
    }
    resampling(&sides, steps);
    pieces(smoke::pick(vec![10, 20], vec![6]), smoke::pick(5, 1));
}

/// The fourth table: the closed surface of a block in two pieces.
fn pieces(sides: Vec<usize>, repeats: usize) {
    println!();
    println!(
        "each piece's closed surface, a 3D block (2n x n x n particles) cut through its middle: ms, median over {repeats} frames"
    );
    println!(
        "| particles | surface_cell | triangles | volume held | after a crack change (built) | frame between changes (kept) |"
    );
    println!("|---|---|---|---|---|---|");
    for side in sides {
        for cell in [FractureParams::DEFAULT_SURFACE_CELL, 0.25] {
            piece_row(side, cell, repeats);
        }
    }
}

/// One row of the fourth table: a block `side` particles deep, its
/// pieces' surfaces cut on a grid of `cell` spacings.
fn piece_row(side: usize, cell: Real, repeats: usize) {
    let spacing = SPACING;
    let half = Vector::new(side as Real, 0.5 * side as Real, 0.5 * side as Real) * spacing;
    let fracture = FractureParams {
        surface_cell: cell,
        ..FractureParams::brittle(1e9)
    };
    let params = params(3, Some(fracture));
    let rest = Shape::Box { half_extents: half }
        .sample_volume(spacing, 3)
        .expect("block");
    let n = rest.len();
    let mut block = ElasticSolid::new(
        params,
        rest,
        vec![Vector::zeros(); n],
        vec![false; n],
        Obstacles::default(),
    )
    .expect("block");
    // Between the two middle planes of particles, off the grid's nodes.
    block
        .notch(&[Notch {
            center: Vector::new(0.3 * spacing, 0.0, 0.0),
            normal: Vector::x(),
            radius: 2.0 * half.norm(),
        }])
        .expect("a notch");
    let outline = MeshSdf::new(&TriMesh::cuboid(-half, half)).expect("a closed box");
    let (mut rebuilt, mut kept) = (Vec::new(), Vec::new());
    let (mut triangles, mut held) = (0, 0.0);
    for _ in 0..repeats {
        // A clone starts with no kept surface: its first frame builds it.
        let fresh = block.clone();
        let (surface, t) = timed(|| fresh.fragment_surface(&outline).expect("two pieces"));
        triangles = surface.0.triangles.len();
        held = surface.0.signed_volume() / (8.0 * half.x * half.y * half.z);
        rebuilt.push(t);
        let (_, t) = timed(|| fresh.fragment_surface(&outline).expect("two pieces"));
        kept.push(t);
    }
    println!(
        "| {n:>9} | {cell:>12} | {triangles:>9} | {:>10.1} % | {:>27.1} | {:>27.2} |",
        100.0 * held,
        median(&mut rebuilt),
        median(&mut kept)
    );
}

/// The third table: a running crack's resampling.
fn resampling(sides: &[usize], steps: usize) {
    println!();
    println!(
        "resampling beside one running crack (transparency, Q_min 10): ms, median over up to {steps} step starts of each kind"
    );
    println!(
        "| particles | start that splits | start with nothing to split | added per split | elastic step before -> after | sub-steps before -> after |"
    );
    println!("|---|---|---|---|---|---|");
    let mut fracture = FractureParams::brittle(2e4);
    fracture.max_cracks = 1;
    fracture.resample = Some(Resampling {
        max_particles: Some(u32::MAX),
        ..Resampling::new()
    });
    for &side in sides {
        let mut solid = plate(side, Some(fracture));
        let gravity = Vector::zeros();
        let (mut splits, mut checks, mut added) = (Vec::new(), Vec::new(), Vec::new());
        let (mut before, mut after) = (Vec::new(), Vec::new());
        let (mut sub_before, mut sub_after) = (Vec::new(), Vec::new());
        let mut taken = 0;
        while (splits.len() < steps || checks.len() < steps || after.len() < steps) && taken < 2000
        {
            taken += 1;
            let (done, t) = timed(|| solid.resample().expect("no limit"));
            let cracked = solid.fracture().is_some_and(|f| !f.cracks().is_empty());
            if done.added > 0 {
                splits.push(t);
                added.push(Real::from(done.added));
            } else if cracked {
                checks.push(t);
            }
            let (step, t) = timed(|| solid.step(DT, &gravity, 1000));
            if solid.radii().is_some() {
                after.push(t);
                sub_after.push(Real::from(step.substeps));
            } else {
                before.push(t);
                sub_before.push(Real::from(step.substeps));
            }
            solid.fracture_step().expect("bounded");
        }
        println!(
            "| {:>9} | {:>17.2} | {:>27.3} | {:>15.0} | {:>12.2} -> {:<12.2} | {:>9.0} -> {:<9.0} |",
            side * side,
            median(&mut splits),
            median(&mut checks),
            median(&mut added),
            median(&mut before),
            median(&mut after),
            median(&mut sub_before),
            median(&mut sub_after),
        );
    }
}

fn median(values: &mut [Real]) -> Real {
    if values.is_empty() {
        return Real::NAN;
    }
    values.sort_by(Real::total_cmp);
    values[values.len() / 2]
}
