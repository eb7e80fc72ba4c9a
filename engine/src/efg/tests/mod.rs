use super::*;
use crate::cancel::Cancel;
use crate::geometry::{ImplicitSurface, MeshSdf, TriMesh};
use crate::math::{Real, Vector};

// The longer suites, each its own file; the beams and tables they share live here.
mod admission;
mod extremes;
mod nonlinear;
mod paths;
mod warping;

fn steel_like() -> Material {
    Material {
        density: 1000.0,
        young: 1e6,
        poisson: 0.3,
    }
}

/// The cuboid `[0, l] x [0, h] x [0, h]` with its faces cut into small
/// triangles (for the penalty's surface integral), and the part of it in
/// the plane `x = 0`.
fn beam(l: Real, h: Real) -> (MeshSdf, FixedSurface) {
    let mesh = TriMesh::cuboid(Vector::zeros(), Vector::new(l, h, h)).subdivided(4);
    let fixed = FixedSurface::of_mesh_in_box(
        &mesh,
        &Vector::repeat(-1e-9),
        &Vector::new(1e-9, h + 1e-9, h + 1e-9),
    );
    (MeshSdf::new(&mesh).expect("closed"), fixed)
}

#[test]
fn the_quadrature_measures_the_volume_of_a_ball() {
    let ball = MeshSdf::new(&TriMesh::icosphere(Vector::zeros(), 1.0, 4)).expect("closed");
    let mesh_volume = ball.mesh().signed_volume();
    let mut errors = Vec::new();
    for refinement in [1, 2] {
        for cell in [0.25, 0.125] {
            let mut params = EfgParams::new(cell);
            params.boundary_refinement = refinement;
            let solid = EfgSolid::build(
                &ball,
                &FixedSurface::default(),
                steel_like(),
                params,
                &Cancel::new(),
            )
            .expect("solid");
            let error = solid.volume() / mesh_volume - 1.0;
            println!(
                "ball volume, cell {cell}, boundary refinement {refinement}: {} points, {:+.3e}",
                solid.quadrature_points(),
                error
            );
            errors.push(error.abs());
        }
    }
    // Points dropped outside the surface leave the cut cells' volume
    // right to parts in 1e3; refined boundary octants, in 1e4.
    assert!(errors[..2].iter().all(|e| *e < 3e-3), "{errors:?}");
    assert!(errors[2..].iter().all(|e| *e < 1e-3), "{errors:?}");
}

/// The patch test: nodal coefficients of a linear field reproduce it at
/// every quadrature point, and K applied to them leaves no force on the
/// nodes whose supports see only the uniform interior (where the
/// quadrature is symmetric about the node, so it integrates the odd
/// `grad phi_I` exactly).
#[test]
fn the_patch_test_passes_on_the_octree_of_a_ball() {
    let ball = MeshSdf::new(&TriMesh::icosphere(Vector::zeros(), 1.0, 3)).expect("closed");
    let cell = 0.125;
    let solid = EfgSolid::build(
        &ball,
        &FixedSurface::default(),
        steel_like(),
        EfgParams::new(cell),
        &Cancel::new(),
    )
    .expect("solid");
    let a = nalgebra::Matrix3::new(0.3, -0.1, 0.2, 0.05, -0.4, 0.1, 0.2, 0.15, 0.25) * 1e-3;
    let c = Vector::new(1e-3, -2e-3, 5e-4);
    let field = |x: &Vector| a * x + c;
    let nodal: Vec<Vector> = solid.nodes().iter().map(|n| field(&n.position)).collect();
    let mut at_points = Vec::new();
    solid.volume.table.interpolate(&nodal, &mut at_points);
    let scale = nodal.iter().map(|u| u.norm()).fold(0.0, Real::max);
    let rule = Quadrature::build(solid.octree(), &ball, 2, 2, 1, &Cancel::new()).expect("built");
    assert_eq!(rule.len(), solid.quadrature_points());
    for (q, x) in rule.points.iter().enumerate() {
        let err = (at_points[q] - field(x)).norm();
        assert!(err <= 1e-10 * scale, "point {q}: {err:e}");
    }
    let flat: Vec<Real> = nodal.iter().flat_map(|u| [u[0], u[1], u[2]]).collect();
    let force = solid.pattern().product(solid.stiffness(), &flat);
    let (lambda, mu) = lame(solid.material().young, solid.material().poisson);
    // The scale of one node's force: stress times a support's face.
    let stress = (lambda + 2.0 * mu) * a.norm();
    let deep = 4.5 * cell;
    let mut checked = 0;
    for (i, node) in solid.nodes().iter().enumerate() {
        if ball.signed_distance(&node.position) > -deep {
            continue;
        }
        checked += 1;
        let f = Vector::new(force[3 * i], force[3 * i + 1], force[3 * i + 2]).norm();
        assert!(f <= 1e-10 * stress * cell * cell, "node {i}: {f:e}");
    }
    assert!(checked > 50, "only {checked} deep nodes");
}

/// Tip deflection of a cantilever (L/H = 10, square section, clamped by
/// the penalty on its end face) under its own weight, against beam
/// theory: Euler–Bernoulli `q L^4 / (8 E I)` plus Timoshenko's shear term
/// `q L^2 / (2 kappa G A)` with Cowper's `kappa = 10 (1 + nu) / (12 + 11 nu)`.
#[test]
fn a_cantilever_sags_under_gravity_as_beam_theory_says() {
    let (l, h) = (10.0, 1.0);
    let (sdf, fixed) = beam(l, h);
    let material = Material {
        density: 1000.0,
        young: 1e9,
        poisson: 0.3,
    };
    let g = 9.81;
    let q = material.density * g * h * h;
    let inertia = h.powi(4) / 12.0;
    let euler_bernoulli = q * l.powi(4) / (8.0 * material.young * inertia);
    let nu = material.poisson;
    let kappa = 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu);
    let shear = material.young / (2.0 * (1.0 + nu));
    let timoshenko = euler_bernoulli + q * l * l / (2.0 * kappa * shear * h * h);
    let mut errors = Vec::new();
    for cell in [0.5, 0.25, 1.0 / 6.0] {
        let solid = EfgSolid::build(&sdf, &fixed, material, EfgParams::new(cell), &Cancel::new())
            .expect("solid");
        let load = solid.body_load(&Vector::new(0.0, 0.0, -g));
        let u = solid
            .static_displacement(&load)
            .expect("held by the penalty");
        let nodal: Vec<Vector> = u.chunks(3).map(|c| Vector::new(c[0], c[1], c[2])).collect();
        let table = solid
            .shape_table(&[
                Vector::new(l, 0.5 * h, 0.5 * h),
                Vector::new(0.0, 0.5 * h, 0.5 * h),
            ])
            .expect("covered");
        let mut at = Vec::new();
        table.interpolate(&nodal, &mut at);
        let deflection = -at[0][2];
        let error = deflection / timoshenko - 1.0;
        println!(
            "cell {cell:.3}: {} nodes, tip {deflection:.5e} (EB {euler_bernoulli:.5e}, \
             Timoshenko {timoshenko:.5e}), error {:.2} %, root {:.1e}",
            solid.nodes().len(),
            100.0 * error,
            at[1].norm() / deflection
        );
        // The clamp holds: the root's centre barely moves.
        assert!(at[1].norm() < 1e-3 * deflection, "{:e}", at[1].norm());
        errors.push(error.abs());
    }
    assert!(errors[2] < errors[0], "{errors:?}");
    assert!(errors[2] < 0.03, "{errors:?}");
}

/// `(beta_n L)` of a clamped-free Euler–Bernoulli beam: the roots of
/// `cos x cosh x = -1` (Timoshenko & Young; Blevins, Table 8-1).
const CLAMPED_FREE: [Real; 4] = [1.875_104_07, 4.694_091_13, 7.854_757_44, 10.995_540_73];

/// `(beta_n L)` of a free-free beam: the positive roots of
/// `cos x cosh x = 1` (Blevins, Table 8-1).
const FREE_FREE: [Real; 2] = [4.730_040_74, 7.853_204_62];

/// The angular frequency of the bending wave of wavenumber `k` in a
/// Timoshenko beam: the lower root of its dispersion relation
/// `E I k^4 - rho A w^2 - rho I w^2 k^2 (1 + E / (kappa G)) + rho^2 I w^4 / (kappa G) = 0`
/// (Timoshenko 1921; exact for a simply supported beam, an approximation
/// at a cantilever's wavenumbers).
fn timoshenko_frequency(k: Real, material: &Material, area: Real, inertia: Real) -> Real {
    let (e, rho, nu) = (material.young, material.density, material.poisson);
    let kappa = 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu);
    let kg = kappa * e / (2.0 * (1.0 + nu));
    // a s^2 + b s + c = 0 in s = w^2.
    let a = rho * rho * inertia / kg;
    let b = -(rho * area + rho * inertia * k * k * (1.0 + e / kg));
    let c = e * inertia * k.powi(4);
    let s = (-b - (b * b - 4.0 * a * c).sqrt()) / (2.0 * a);
    s.sqrt()
}

/// The fraction of a mode's nodal coefficients along axis `axis`.
fn fraction_along(vector: &[Real], axis: usize) -> Real {
    let total: Real = vector.iter().map(|v| v * v).sum();
    let along: Real = vector.iter().skip(axis).step_by(3).map(|v| v * v).sum();
    along / total
}

/// A clamped 10 x 2 x 1 beam (L/H = 10 in the bending plane x-z): its
/// first four modes of bending in z against beam theory, at three octree
/// resolutions.
#[test]
fn a_cantilevers_bending_frequencies_converge_to_beam_theory() {
    let (l, b, h) = (10.0, 2.0, 1.0);
    let mesh = TriMesh::cuboid(Vector::zeros(), Vector::new(l, b, h)).subdivided(4);
    let fixed = FixedSurface::of_mesh_in_box(
        &mesh,
        &Vector::repeat(-1e-9),
        &Vector::new(1e-9, b + 1e-9, h + 1e-9),
    );
    let sdf = MeshSdf::new(&mesh).expect("closed");
    let material = Material {
        density: 1000.0,
        young: 1e9,
        poisson: 0.3,
    };
    let (area, inertia) = (b * h, b * h.powi(3) / 12.0);
    let euler = |beta_l: Real| {
        (beta_l / l).powi(2) * (material.young * inertia / (material.density * area)).sqrt()
    };
    let mut errors = Vec::new();
    for cell in [0.5, 1.0 / 3.0, 0.25] {
        let solid = EfgSolid::build(&sdf, &fixed, material, EfgParams::new(cell), &Cancel::new())
            .expect("solid");
        let modes = solid.modes(16, 1e-10, &Cancel::new()).expect("modes");
        assert_eq!(modes.zero_modes, 0, "the clamp holds every rigid motion");
        let n = 3 * solid.nodes().len();
        let bending: Vec<Real> = (0..16)
            .filter(|&j| fraction_along(&modes.vectors[j * n..(j + 1) * n], 2) > 0.8)
            .map(|j| modes.eigenvalues[j].sqrt())
            .take(4)
            .collect();
        assert_eq!(bending.len(), 4, "four z-bending modes among the lowest 16");
        let mut row = Vec::new();
        for (mode, &omega) in bending.iter().enumerate() {
            let reference = timoshenko_frequency(CLAMPED_FREE[mode] / l, &material, area, inertia);
            println!(
                "cell {cell:.3} ({} nodes) mode {}: {omega:.4} rad/s, Euler–Bernoulli {:.4} \
                 ({:+.2} %), Timoshenko {reference:.4} ({:+.2} %)",
                solid.nodes().len(),
                mode + 1,
                euler(CLAMPED_FREE[mode]),
                100.0 * (omega / euler(CLAMPED_FREE[mode]) - 1.0),
                100.0 * (omega / reference - 1.0)
            );
            row.push((omega / reference - 1.0).abs());
        }
        errors.push(row);
    }
    for mode in 0..4 {
        assert!(
            errors[2][mode] < errors[0][mode],
            "mode {}: {errors:?}",
            mode + 1
        );
    }
    // The clamped 3D solid is a little stiffer than a beam in its first
    // mode (the clamp also holds the section's Poisson contraction).
    assert!(errors[2][0] < 0.025, "{errors:?}");
    assert!(errors[2][1..].iter().all(|e| *e < 0.01), "{errors:?}");
}

/// A free 10 x 2 x 1 beam: six zero modes to round-off, then the first
/// bending mode in z against beam theory.
#[test]
fn a_free_beam_has_six_rigid_modes_then_bends() {
    let (l, b, h) = (10.0, 2.0, 1.0);
    let sdf =
        MeshSdf::new(&TriMesh::cuboid(Vector::zeros(), Vector::new(l, b, h))).expect("closed");
    let material = Material {
        density: 1000.0,
        young: 1e9,
        poisson: 0.3,
    };
    let solid = EfgSolid::build(
        &sdf,
        &FixedSurface::default(),
        material,
        EfgParams::new(0.25),
        &Cancel::new(),
    )
    .expect("solid");
    let modes = solid.modes(12, 1e-10, &Cancel::new()).expect("modes");
    assert_eq!(modes.zero_modes, 6, "{:?}", &modes.eigenvalues[..8]);
    let first_elastic = modes.eigenvalues[6];
    for lambda in &modes.eigenvalues[..6] {
        assert!(lambda.abs() < 1e-8 * first_elastic, "{lambda:e}");
    }
    let n = 3 * solid.nodes().len();
    let j = (6..12)
        .find(|&j| fraction_along(&modes.vectors[j * n..(j + 1) * n], 2) > 0.8)
        .expect("a z-bending mode");
    let omega = modes.eigenvalues[j].sqrt();
    let (area, inertia) = (b * h, b * h.powi(3) / 12.0);
    let reference = timoshenko_frequency(FREE_FREE[0] / l, &material, area, inertia);
    println!("free-free first z bending: {omega:.4} rad/s, Timoshenko {reference:.4}");
    assert!(
        (omega / reference - 1.0).abs() < 0.03,
        "{omega} against {reference}"
    );
}

/// The 10 x 1 x 1 m cantilever (E = 5e7 Pa, 24 modes) of the warping
/// tests, with the shape functions at 41 points of its centreline.
struct BentBeam {
    length: Real,
    basis: crate::modal::ModalBasis,
    masses: Vec<Real>,
    centreline: Vec<Vector>,
    table: ShapeTable,
    /// The discretisation (for the nonlinear EFG of the same beam).
    solid: EfgSolid,
}

impl BentBeam {
    fn new() -> Self {
        let (length, h) = (10.0, 1.0);
        let (sdf, fixed) = beam(length, h);
        let material = Material {
            density: 1000.0,
            young: 5e7,
            poisson: 0.3,
        };
        let solid = EfgSolid::build(&sdf, &fixed, material, EfgParams::new(0.5), &Cancel::new())
            .expect("solid");
        let (_, basis) = solid.modal_basis(24, 1e-10, &Cancel::new()).expect("basis");
        let centreline: Vec<Vector> = (0..=40)
            .map(|i| Vector::new(length * i as Real / 40.0, 0.5 * h, 0.5 * h))
            .collect();
        let table = solid.shape_table(&centreline).expect("covered");
        Self {
            length,
            basis,
            masses: solid.node_masses().to_vec(),
            centreline,
            table,
            solid,
        }
    }

    /// The centreline settled statically under `load` times its weight
    /// (heavy damping and long implicit steps), with or without warping.
    fn settle(&self, load: Real, warping: bool) -> Vec<Vector> {
        use crate::modal::{Damping, ModalSystem};
        let gravity: Vec<Vector> = self
            .masses
            .iter()
            .map(|m| Vector::new(0.0, 0.0, -9.81 * load) * *m)
            .collect();
        let damping = Damping::new(5.0, 0.0).expect("damping");
        let mut system = ModalSystem::new(self.basis.clone(), damping, warping);
        for _ in 0..400 {
            system.step(0.05, &gravity).expect("step");
        }
        let mut d = Vec::new();
        self.table.interpolate(system.displacements(), &mut d);
        self.centreline.iter().zip(&d).map(|(x, d)| x + d).collect()
    }

    /// A deformed centreline's length over the beam's, less one.
    fn stretch(&self, deformed: &[Vector]) -> Real {
        let length: Real = deformed.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        length / self.length - 1.0
    }
}

/// Modal warping against linear modes on a cantilever bent far by its own
/// weight (tip deflection about a quarter of its length): linear modes
/// only translate the sections, so the centreline stretches; warping
/// turns them with the local rotation, so it keeps its length.
#[test]
fn modal_warping_keeps_a_bent_cantilevers_length_where_linear_modes_stretch_it() {
    let beam = BentBeam::new();
    let (l, h) = (beam.length, 1.0);
    let mut result = Vec::new();
    for warping in [false, true] {
        let deformed = beam.settle(1.0, warping);
        let stretch = beam.stretch(&deformed);
        let tip = deformed[40];
        println!(
            "warping {warping}: tip ({:.3}, {:.3}), centreline length {:+.2} %",
            tip.x,
            tip.z,
            100.0 * stretch
        );
        result.push((stretch, tip));
    }
    let (linear, warped) = (result[0], result[1]);
    assert!(
        linear.1.z < 0.5 * h - 0.2 * l,
        "a large deflection: {:?}",
        linear.1
    );
    assert!(
        linear.0 > 0.02,
        "linear modes stretch the centreline: {:e}",
        linear.0
    );
    assert!(
        warped.0.abs() < 0.2 * linear.0,
        "warping keeps it: {:e}",
        warped.0
    );
    // Warping shortens the reach along the beam, as a bent rod does;
    // linear modes leave the tip at x = L.
    assert!((linear.1.x - l).abs() < 1e-6 * l, "{:?}", linear.1);
    assert!(warped.1.x < l - 0.02 * l, "{:?}", warped.1);
}

/// Where modal warping stops holding: the same cantilever under its
/// weight times 1 to 16, each settled statically. An inextensible rod
/// (the elastica) keeps its length at every load; Choi & Ko's warping
/// rotates each node's linear displacement by the local rotation of the
/// linear field, which shortens a beam bent hard by construction: the
/// shortfall grows with the tip's rotation, measured here and stated in
/// docs/validation.md. The exact path is the nonlinear EFG dynamics of
/// Guo–Qin Section 5.1 (`dynamics = "nonlinear"`, `nonlinear.rs`).
#[test]
fn modal_warping_shortens_a_beam_bent_hard() {
    let beam = BentBeam::new();
    let mut measured = Vec::new();
    println!("load  tip rotation [deg]  centreline length");
    for load in [1.0, 2.0, 4.0, 8.0, 16.0] {
        let deformed = beam.settle(load, true);
        let stretch = beam.stretch(&deformed);
        let end = deformed[40] - deformed[39];
        let rotation = (-end.z).atan2(end.x).to_degrees();
        println!("{load:4}  {rotation:18.1}  {:+.2} %", 100.0 * stretch);
        measured.push((rotation, stretch));
    }
    // The rotation grows with the load and the shortfall with it.
    assert!(measured.windows(2).all(|w| w[1].0 > w[0].0), "{measured:?}");
    assert!(measured.windows(2).all(|w| w[1].1 < w[0].1), "{measured:?}");
    let (small, hard) = (measured[0], measured[measured.len() - 1]);
    assert!(
        small.1.abs() < 0.01,
        "a moderate bend keeps its length: {small:?}"
    );
    assert!(
        hard.0 > 45.0 && hard.1 < -0.03,
        "bent hard, it shortens: {hard:?}"
    );
}

/// Points a rounding outside the implicit surface (the true sphere
/// around its icosphere, on octants of a fifth of the radius) still
/// find the supports that reach them, and their shape functions sum to
/// one: a skin on the true sphere embeds. (On octants of r / 5.75 the
/// pole (r, 0, 0) falls in an exterior octant and is refused as
/// uncovered: a skin must lie within the boundary octants.)
#[test]
fn points_just_outside_the_implicit_surface_are_covered() {
    let r = 0.1;
    let sdf = MeshSdf::new(&TriMesh::icosphere(Vector::zeros(), r, 4)).expect("closed");
    let solid = EfgSolid::build(
        &sdf,
        &FixedSurface::default(),
        steel_like(),
        EfgParams::new(r / 5.0),
        &Cancel::new(),
    )
    .expect("a ball");
    let mut points = vec![Vector::new(r, 0.0, 0.0), Vector::new(0.0, -r, 0.0)];
    points.extend(crate::testing::fibonacci_sphere(200).iter().map(|p| p * r));
    let outside = points
        .iter()
        .filter(|p| sdf.signed_distance(p) > 0.0)
        .count();
    assert!(outside > 100, "most lie outside the icosphere: {outside}");
    let table = solid.shape_table(&points).expect("every point covered");
    // Partition of unity at each point.
    for i in 0..table.len() {
        let sum: Real = table.row(i).values.iter().sum();
        assert!((sum - 1.0).abs() < 1e-10, "point {i}: {sum}");
    }
}

/// Guo–Qin's Table 1 beam (27 x 5 x 5 cm on 1 cm cells, 1,008 nodes)
/// clamped through its x = 0 face cut into fine triangles. A square
/// section bends alike in y and z, so its modes come in pairs (the
/// first two 4e-6 apart: the octree is not quite symmetric);
/// with a Krylov basis of two vectors per mode faer's Krylov–Schur
/// returned duplicated vectors for 60 modes and never returned for 64.
/// Both counts now give distinct modes (the M-orthonormality check of
/// `lowest_modes` refuses duplicates), the first bending pair within
/// 1e-4 of each other.
#[test]
fn the_table_1_beam_gives_its_paired_modes() {
    let max = Vector::new(0.27, 0.05, 0.05);
    let mesh = TriMesh::cuboid(Vector::zeros(), max);
    let fixed = FixedSurface::of_mesh_in_box(
        &mesh.subdivided(4),
        &Vector::repeat(-1e-3),
        &Vector::new(1e-3, max.y + 1e-3, max.z + 1e-3),
    );
    let sdf = MeshSdf::new(&mesh).expect("closed");
    let solid = EfgSolid::build(
        &sdf,
        &fixed,
        steel_like(),
        EfgParams::new(0.01),
        &Cancel::new(),
    )
    .expect("the beam");
    assert_eq!(solid.nodes().len(), 1008);
    for count in [60, 64] {
        let modes = solid.modes(count, 1e-10, &Cancel::new()).expect("modes");
        let l = &modes.eigenvalues;
        assert_eq!(l.len(), count);
        assert!(
            (l[1] - l[0]).abs() <= 1e-4 * l[0],
            "{count} modes: the first bending pair {} and {}",
            l[0],
            l[1]
        );
    }
}

/// The bench's second model (`engine/benches/modal.rs`): a ball whose
/// solid is the inside of its own cube-sphere skin. Cut at a sixth of
/// its radius every skin vertex embeds; cut at r / 5.75 the vertex
/// (r, 0, 0) lies on the face between an exterior octant and the boundary
/// octant inside it, is given the boundary one (`Octree::leaf_at`), and is
/// reached there by the supports of one plane of nodes only (9, at
/// x = 0.0913): too flat a layout for the linear basis, so it is refused
/// as uncovered with its position and their count.
#[test]
fn a_ball_on_its_own_skin_embeds_at_a_sixth_of_its_radius() {
    let r = 0.1;
    let mut skin = TriMesh::cuboid(Vector::repeat(-1.0), Vector::repeat(1.0)).subdivided(3);
    for v in &mut skin.vertices {
        *v = v.normalize() * r;
    }
    let sdf = MeshSdf::new(&skin).expect("closed");
    let ball = |cell: Real| {
        EfgSolid::build(
            &sdf,
            &FixedSurface::default(),
            steel_like(),
            EfgParams::new(cell),
            &Cancel::new(),
        )
        .expect("a ball")
    };
    ball(r / 6.0)
        .shape_table(&skin.vertices)
        .expect("every skin vertex covered");
    let refused = ball(r / 5.75).shape_table(&[Vector::new(r, 0.0, 0.0)]);
    assert!(
        matches!(refused, Err(CoverError::Uncovered { supports: 9, .. })),
        "{refused:?}"
    );
}
