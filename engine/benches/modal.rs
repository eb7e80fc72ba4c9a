//! Guo–Qin's modal EFG solids against their Table 1.
//!
//! **Beam** (Table 1's first row: 1,008 nodes, 64 modes, 5,634 surface
//! points, 13 ms per frame on a 2006 dual Xeon): a 27 x 5 x 5 cm bar
//! (E = 1e6 Pa, nu = 0.3, rho = 1000 kg/m^3) cut at 1 cm, its nodes on a
//! 28 x 6 x 6 grid, clamped at x = 0, its surface the box's faces split
//! into 12,288 triangles (6,146 vertices). Then the same beam with a
//! 98,306-vertex surface.
//!
//! **Ball**: a free ball of radius 10 cm (same material) cut at a
//! sixth of its radius, 1,285 nodes, 96 modes (six of them rigid), a
//! 98,306-vertex surface.
//!
//! Each is built as a world builds a modal solid ([`ModalSolid::build`])
//! and timed as a world steps it. For each: the precompute stages
//! (octree, quadrature, shape functions, assembly, modes, rotation
//! modes, skin embedding), then the median time per frame over 1,000
//! frames of h = 1/60 s under gravity: the step (loads rotated into the
//! warped frames, the implicit modal step, each node's rotation and
//! displacement) and the skin (its displaced vertices and their
//! normals), with modal warping on and off, and on with seven surface
//! points grabbed (21 constraint rows, Eq. 33). Prints tables; asserts
//! nothing.
//!
//!     cargo bench -p meshless-engine --bench modal

use meshless_engine::Cancel;
use meshless_engine::efg::{
    EfgParams, FixedSurface, Grab, Material, ModalParams, ModalSolid, SkinBuffers, SkinInput,
};
use meshless_engine::geometry::{MeshSdf, TriMesh};
use meshless_engine::math::{Real, Vector};
use meshless_engine::modal::{Damping, Stabilization};
use std::time::{Duration, Instant};

#[path = "common/smoke.rs"]
mod smoke;

const MATERIAL: Material = Material {
    density: 1000.0,
    young: 1e6,
    poisson: 0.3,
};

/// One model to time.
struct Model {
    name: &'static str,
    sdf: MeshSdf,
    fixed: FixedSurface,
    surface: TriMesh,
    cell: Real,
    modes: usize,
}

fn beam(surface_subdivisions: u32) -> Model {
    let (cell, cells) = smoke::pick((0.01, [27.0, 5.0, 5.0]), (0.025, [8.0, 2.0, 2.0]));
    let max = Vector::new(cells[0], cells[1], cells[2]) * cell;
    let box_mesh = TriMesh::cuboid(Vector::zeros(), max);
    let surface = box_mesh.subdivided(surface_subdivisions);
    let fixed = FixedSurface::of_mesh_in_box(
        &box_mesh.subdivided(3),
        &Vector::repeat(-1e-9),
        &Vector::new(1e-9, max.y + 1e-9, max.z + 1e-9),
    );
    Model {
        name: "beam",
        sdf: MeshSdf::new(&box_mesh).expect("closed box"),
        fixed,
        surface,
        cell,
        modes: smoke::pick(64, 12),
    }
}

fn ball() -> Model {
    let radius = 0.1;
    // A cube's faces split 7 times (98,306 vertices) pushed onto the
    // sphere; the solid is the inside of that same mesh, so every skin
    // vertex lies on the discretised surface.
    let mut surface =
        TriMesh::cuboid(Vector::repeat(-1.0), Vector::repeat(1.0)).subdivided(smoke::pick(7, 3));
    for v in &mut surface.vertices {
        *v = v.normalize() * radius;
    }
    Model {
        name: "ball",
        sdf: MeshSdf::new(&surface).expect("closed"),
        fixed: FixedSurface::default(),
        surface,
        cell: smoke::pick(radius / 6.0, radius / 2.0),
        modes: smoke::pick(96, 12),
    }
}

fn ms(d: Duration) -> String {
    format!("{:.3}", d.as_secs_f64() * 1e3)
}

fn run(model: &Model) {
    let mut efg = EfgParams::new(model.cell);
    efg.penalty = 1e4;
    let params = ModalParams {
        dynamics: meshless_engine::efg::Dynamics::Modal,
        efg,
        modes: model.modes,
        tolerance: 1e-10,
        warping: true,
        damping: Damping::new(0.5, 1e-3).expect("damping"),
        stabilization: Stabilization::new(20.0, 20.0).expect("stabilisation"),
    };
    let skin = SkinInput {
        vertices: model.surface.vertices.clone(),
        triangles: model.surface.triangles.clone(),
        normals: model.surface.vertex_normals(),
    };
    let start = Instant::now();
    let mut solid = ModalSolid::build(
        &model.sdf,
        &model.fixed,
        MATERIAL,
        &params,
        Some(skin),
        &Cancel::new(),
    )
    .expect("a modal solid");
    let total = start.elapsed();
    println!(
        "\n{}: {} nodes, {} quadrature points, {} modes ({} rigid), {} surface points",
        model.name,
        solid.len(),
        solid.efg().quadrature_points(),
        solid.eigenvalues().len(),
        solid.zero_modes(),
        model.surface.vertices.len(),
    );
    println!("| precompute stage | ms |\n|---|---:|");
    for (stage, t) in solid.timings() {
        println!("| {stage} | {} |", ms(*t));
    }
    println!("| **total** | **{}** |", ms(total));

    let gravity = Vector::new(0.0, 0.0, -9.81);
    // A thousand frames (a few seconds at most) after a hundred untimed
    // ones: a median over a window this long rides out a busy neighbour
    // on a shared machine, and the first frames after the precompute
    // run on cold caches.
    let (warm_up, frames) = smoke::pick((100, 1000), (1, 3));
    println!(
        "| warping | step | skin | **frame** (ms, median of {frames}) |\n|---|---:|---:|---:|"
    );
    let mut skin = SkinBuffers::default();
    // Seven surface points each held 5 mm above rest: 21 constraint rows,
    // past the paper's k <= 20.
    let vertices = &model.surface.vertices;
    let grabs: Vec<Grab> = (0..7)
        .map(|k| {
            let point = vertices[k * vertices.len() / 7];
            Grab {
                point,
                position: Some(point + Vector::new(0.0, 0.0, 0.005)),
                rotation: None,
            }
        })
        .collect();
    for (label, warping, grabbed) in [
        ("on", true, false),
        ("off", false, false),
        ("on, 21 grab rows", true, true),
    ] {
        solid.set_warping(warping);
        solid
            .set_grabs(if grabbed { &grabs } else { &[] })
            .expect("grabs on the surface");
        for _ in 0..warm_up {
            solid.step(1.0 / 60.0, &gravity).expect("step");
            solid.skin_into(&mut skin);
        }
        let mut times: Vec<[Duration; 2]> = Vec::with_capacity(frames);
        for _ in 0..frames {
            let t0 = Instant::now();
            solid.step(1.0 / 60.0, &gravity).expect("step");
            let t1 = Instant::now();
            solid.skin_into(&mut skin);
            std::hint::black_box(&skin);
            times.push([t1 - t0, t1.elapsed()]);
        }
        let median = |k: Option<usize>| {
            let mut v: Vec<Duration> = times
                .iter()
                .map(|t| k.map_or_else(|| t.iter().sum(), |k| t[k]))
                .collect();
            v.sort();
            v[v.len() / 2]
        };
        println!(
            "| {label} | {} | {} | **{}** |",
            ms(median(Some(0))),
            ms(median(Some(1))),
            ms(median(None))
        );
    }
}

fn main() {
    println!(
        "modal EFG solids, {} threads (Guo–Qin Table 1: beam 1,008 nodes, 64 modes, \
         5,634 surface points, 13 ms per frame)",
        rayon::current_num_threads()
    );
    run(&beam(smoke::pick(5, 2)));
    run(&Model {
        name: "beam, fine surface",
        ..beam(smoke::pick(7, 3))
    });
    run(&ball());
}
