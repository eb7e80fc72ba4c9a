//! Guo–Qin's modal EFG solids against their Table 1.
//!
//! **Beam** (Table 1's first row: 1,008 nodes, 64 modes, 5,634 surface
//! points, 13 ms per frame on a 2006 dual Xeon): a 27 x 5 x 5 cm bar
//! (E = 1e6 Pa, nu = 0.3, rho = 1000 kg/m^3) cut at 1 cm, its nodes on a
//! 28 x 6 x 6 grid, clamped at x = 0, its surface the box's faces split
//! into 12,288 triangles (6,146 vertices). Then the same beam with a
//! 98,306-vertex surface.
//!
//! **Ball**: a free ball of radius 10 cm (same material), 823
//! nodes, 96 modes (six of them rigid), a 98,306-vertex surface.
//!
//! For each: the precompute stages (octree, quadrature, shape functions,
//! assembly, modes, rotation modes, surface embedding), then the median
//! time per frame over 200 frames of h = 1/60 s under gravity — the modal
//! step (loads rotated into the warped frames), the nodal displacements
//! and the deformed surface with its normals — with modal warping on and
//! off. Prints tables; asserts nothing.
//!
//!     cargo bench -p meshless-engine --bench modal

use meshless_engine::Cancel;
use meshless_engine::efg::{EfgParams, EfgSolid, FixedSurface, Material, ShapeTable};
use meshless_engine::geometry::{MeshSdf, TriMesh, vertex_normals};
use meshless_engine::math::{Real, Vector};
use meshless_engine::modal::{Damping, ModalBasis, ModalSystem};
use nalgebra::{DMatrix, DVector};
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
    // A cube's faces split 7 times (98,306 vertices) pushed onto the sphere.
    let mut surface =
        TriMesh::cuboid(Vector::repeat(-1.0), Vector::repeat(1.0)).subdivided(smoke::pick(7, 3));
    for v in &mut surface.vertices {
        *v = v.normalize() * radius;
    }
    Model {
        name: "ball",
        sdf: MeshSdf::new(&TriMesh::icosphere(Vector::zeros(), radius, 4)).expect("closed"),
        fixed: FixedSurface::default(),
        surface,
        cell: smoke::pick(radius / 5.0, radius / 2.0),
        modes: smoke::pick(96, 12),
    }
}

fn ms(d: Duration) -> String {
    format!("{:.3}", d.as_secs_f64() * 1e3)
}

fn run(model: &Model) {
    let cancel = Cancel::new();
    let mut params = EfgParams::new(model.cell);
    params.penalty = 1e4;
    let start = Instant::now();
    let solid = EfgSolid::build(&model.sdf, &model.fixed, MATERIAL, params, &cancel)
        .expect("discretisation");
    let mut stages: Vec<(&str, Duration)> = solid.timings().to_vec();
    let clock = Instant::now();
    let modes = solid.modes(model.modes, 1e-10, &cancel).expect("modes");
    stages.push(("modes", clock.elapsed()));
    let clock = Instant::now();
    let w = solid.rotation_modes(&modes).expect("rotation modes");
    stages.push(("rotation modes", clock.elapsed()));
    let clock = Instant::now();
    let rest = &model.surface.vertices;
    let table = ShapeTable::build(solid.octree(), params.basis, rest).expect("surface covered");
    stages.push(("surface embedding", clock.elapsed()));
    let total = start.elapsed();
    let nodes = solid.nodes().len();
    println!(
        "\n{}: {nodes} nodes, {} quadrature points, {} modes ({} rigid), {} surface points \
         ({:.1} nodes per point)",
        model.name,
        solid.quadrature_points(),
        modes.eigenvalues.len(),
        modes.zero_modes,
        rest.len(),
        table.entries() as Real / rest.len() as Real
    );
    println!("| precompute stage | ms |\n|---|---:|");
    for (stage, t) in &stages {
        println!("| {stage} | {} |", ms(*t));
    }
    println!("| **total** | **{}** |", ms(total));

    let n = 3 * nodes;
    let psi = DMatrix::from_column_slice(n, modes.eigenvalues.len(), &modes.vectors);
    let basis =
        ModalBasis::new(&DVector::from_column_slice(&modes.eigenvalues), &psi, &w).expect("basis");
    let masses = solid.node_masses();
    let gravity: Vec<Vector> = masses
        .iter()
        .map(|m| Vector::new(0.0, 0.0, -9.81) * *m)
        .collect();
    let frames = smoke::pick(200, 3);
    println!(
        "| warping | modal step | nodes | surface | normals | **frame** (ms, median of {frames}) |\n\
         |---|---:|---:|---:|---:|---:|"
    );
    for warping in [true, false] {
        let mut system = ModalSystem::new(
            basis.clone(),
            Damping::new(0.5, 1e-3).expect("damping"),
            warping,
        );
        let mut u = vec![Vector::zeros(); nodes];
        let mut at_surface = Vec::new();
        let mut positions = vec![Vector::zeros(); rest.len()];
        let mut times: Vec<[Duration; 4]> = Vec::with_capacity(frames);
        for _ in 0..frames {
            let t0 = Instant::now();
            system.step(1.0 / 60.0, &gravity).expect("step");
            let t1 = Instant::now();
            system.displacements_into(&mut u).expect("displacements");
            let t2 = Instant::now();
            table.interpolate(&u, &mut at_surface);
            for ((p, x), d) in positions.iter_mut().zip(rest).zip(&at_surface) {
                *p = x + d;
            }
            let t3 = Instant::now();
            let surface_normals = vertex_normals(&model.surface.triangles, &positions);
            std::hint::black_box(&surface_normals);
            let t4 = Instant::now();
            times.push([t1 - t0, t2 - t1, t3 - t2, t4 - t3]);
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
            "| {} | {} | {} | {} | {} | **{}** |",
            if warping { "on" } else { "off" },
            ms(median(Some(0))),
            ms(median(Some(1))),
            ms(median(Some(2))),
            ms(median(Some(3))),
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
