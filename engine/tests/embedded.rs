//! Surfaces embedded in an MLS solid (tutorial Section 7.2):
//!
//! - both methods carry an affine deformation `x -> A x + b` of a
//!   jittered particle lattice to the vertices of meshes inside it
//!   exactly, normals included (`A^-T n`, normalised);
//! - under a nonlinear deformation each gives what its formula, evaluated
//!   directly over all particles, gives;
//! - a rigid motion keeps the mesh's area and volume;
//! - a smooth bend `u = (0, c (x - x0)^2, 0)`: both errors stay within the
//!   Taylor bound `c h^2` (positions) and `2 c h` (normal angle); run with
//!   `--nocapture` for the figures;
//! - bad input gives errors that say what to change, never panics.

use meshless_engine::approx::{
    GradientKind, LagrangianGradients, Mls, MlsParams, Order, ShapeFunctions,
};
use meshless_engine::geometry::TriMesh;
use meshless_engine::math::{Real, Vector};
use meshless_engine::neighbors::{CandidateSearch, NeighborList, UniformGrid};
use meshless_engine::solid::embedded::{
    DeformedSurface, EmbedError, EmbeddedSurface, EmbeddingMethod,
};
use nalgebra::{Matrix3, Rotation3};

const METHODS: [EmbeddingMethod; 2] = [EmbeddingMethod::ShapeFunctions, EmbeddingMethod::Gradients];

/// Particle spacing of the test solid.
const SPACING: Real = 0.1;
/// Support radius: two spacings, some 30 particles per vertex.
const H: Real = 2.0 * SPACING;

/// Deterministic numbers in [0, 1) (SplitMix64).
fn uniform(seed: &mut u64) -> Real {
    *seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *seed;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    (z ^ (z >> 31)) as Real / u64::MAX as Real
}

/// 9^3 particles filling [0, 0.8]^3 at [`SPACING`], each jittered by up to
/// a fifth of a spacing per axis so that no symmetry helps the fits.
fn particles() -> Vec<Vector> {
    let mut seed = 11;
    let mut points = Vec::new();
    for i in 0..9 {
        for j in 0..9 {
            for k in 0..9 {
                let jitter = Vector::from_fn(|_, _| 0.2 * (2.0 * uniform(&mut seed) - 1.0));
                points.push((Vector::new(i as Real, j as Real, k as Real) + jitter) * SPACING);
            }
        }
    }
    points
}

/// The centre of the particle block.
fn centre() -> Vector {
    Vector::repeat(0.4)
}

/// Three closed meshes inside the block, each at least a spacing inside
/// the outer particles: an icosphere (642 vertices, neighbours sharing most
/// particles), a box, and a square pyramid, whose odd vertex count leaves
/// one vertex without a partner in Alternative 2's couples.
fn meshes() -> [(&'static str, TriMesh); 3] {
    let pyramid = TriMesh {
        vertices: vec![
            Vector::new(0.15, 0.15, 0.1),
            Vector::new(0.65, 0.15, 0.1),
            Vector::new(0.65, 0.6, 0.1),
            Vector::new(0.15, 0.6, 0.1),
            Vector::new(0.4, 0.35, 0.7),
        ],
        triangles: vec![
            [0, 2, 1],
            [0, 3, 2],
            [0, 1, 4],
            [1, 2, 4],
            [2, 3, 4],
            [3, 0, 4],
        ],
    };
    assert!(pyramid.is_closed() && pyramid.signed_volume() > 0.0);
    [
        ("icosphere", TriMesh::icosphere(centre(), 0.28, 3)),
        (
            "box",
            TriMesh::cuboid(Vector::new(0.1, 0.15, 0.1), Vector::new(0.7, 0.6, 0.65)),
        ),
        ("pyramid", pyramid),
    ]
}

/// Area-weighted vertex normals, normalised, computed here independently
/// of the module.
fn normals(mesh: &TriMesh) -> Vec<Vector> {
    let mut n = vec![Vector::zeros(); mesh.vertices.len()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let [a, b, c] = mesh.corners(t);
        for &i in tri {
            n[i as usize] += (b - a).cross(&(c - a));
        }
    }
    n.iter().map(|v| v.normalize()).collect()
}

/// Per-particle displacement gradients as the solver computes them: the
/// direct linear MLS estimate (Eq. 37-38) over the particles within `H`.
fn gradients(rest: &[Vector], current: &[Vector]) -> Vec<Matrix3<Real>> {
    let mls = Mls::new(3, MlsParams::new(Order::Linear, H)).expect("parameters");
    let mut grid = UniformGrid::new(Vector::repeat(-0.2), Vector::repeat(1.0), H).expect("grid");
    grid.rebuild(rest);
    let mut list = NeighborList::default();
    list.build(&grid, rest, H);
    let weights =
        LagrangianGradients::build(&mls, GradientKind::Direct, rest, &list).expect("weights");
    let u: Vec<Vector> = current.iter().zip(rest).map(|(x, r)| x - r).collect();
    let mut g = vec![Matrix3::zeros(); rest.len()];
    weights.vector_gradients(&u, &mut g);
    g
}

/// Embeds `mesh` with `method`, moves the particles by `map` and returns
/// the deformed surface.
fn deform(
    mesh: &TriMesh,
    method: EmbeddingMethod,
    map: impl Fn(&Vector) -> Vector,
) -> (EmbeddedSurface, DeformedSurface) {
    let rest = particles();
    let surface =
        EmbeddedSurface::new(mesh, &rest, 3, H, Order::Linear, method).expect("embedding");
    let current: Vec<Vector> = rest.iter().map(&map).collect();
    let grad_u = gradients(&rest, &current);
    let mut out = DeformedSurface::new();
    surface.update(&current, &grad_u, &mut out).expect("update");
    (surface, out)
}

/// Largest angle (radians) between corresponding unit vectors.
fn max_angle(a: &[Vector], b: &[Vector]) -> Real {
    a.iter()
        .zip(b)
        .map(|(a, b)| a.cross(b).norm().atan2(a.dot(b)))
        .fold(0.0, Real::max)
}

#[test]
fn affine_deformations_are_reproduced_exactly() {
    // Stretch, shear and rotation together: A^-T n and A n differ in
    // direction, so the normal rule matters.
    let a = Matrix3::new(1.3, 0.4, -0.2, 0.1, 0.8, 0.3, -0.25, 0.15, 1.1);
    let b = Vector::new(0.5, -0.3, 2.0);
    let inverse_transpose = a.try_inverse().expect("invertible").transpose();
    for (name, mesh) in meshes() {
        let n0 = normals(&mesh);
        for method in METHODS {
            let (surface, out) = deform(&mesh, method, |x| a * x + b);
            assert_eq!(surface.reduced_vertices(), 0, "{name} {method:?}");
            assert_eq!(out.vertices.len(), mesh.vertices.len());
            for (v, x) in mesh.vertices.iter().enumerate() {
                let error = (out.vertices[v] - (a * x + b)).norm();
                assert!(error < 1e-10, "{name} {method:?} vertex {v}: {error:e}");
                let expected = (inverse_transpose * n0[v]).normalize();
                let error = (out.normals[v] - expected).norm();
                assert!(error < 1e-10, "{name} {method:?} normal {v}: {error:e}");
            }
        }
    }
}

/// Under a nonlinear deformation both methods give what their formulas give
/// when evaluated directly at each vertex, over all particles: Alternative
/// 1 `x + sum_i phi_i u_i` and `cof(I + sum_i u_i grad phi_i^T) n`;
/// Alternative 2 Eq. 68 with poly6 weights and `cof(I + sum_j w~_j grad
/// u_j) n`. Alternative 2 stores its weights in single precision, hence its
/// looser tolerance.
#[test]
fn both_methods_match_their_formulas_evaluated_directly() {
    let rest = particles();
    let twist = |x: &Vector| {
        let d = x - centre();
        x + Vector::new(0.3 * d.y * d.z, -0.2 * d.x * d.x, 0.25 * d.x * d.y)
    };
    let current: Vec<Vector> = rest.iter().map(twist).collect();
    let u: Vec<Vector> = current.iter().zip(&rest).map(|(x, r)| x - r).collect();
    let grad_u = gradients(&rest, &current);
    let mls = Mls::new(3, MlsParams::new(Order::Linear, H)).expect("parameters");
    let mut shape = ShapeFunctions::new();
    let normal = |f: Matrix3<Real>, n: &Vector| {
        (f.determinant() * f.try_inverse().expect("invertible").transpose() * n).normalize()
    };
    for (name, mesh) in meshes() {
        let n0 = normals(&mesh);
        for method in METHODS {
            let (_, out) = deform(&mesh, method, twist);
            for (v, x) in mesh.vertices.iter().enumerate() {
                let (position, f, tolerance) = match method {
                    EmbeddingMethod::ShapeFunctions => {
                        mls.shape_functions(x, &rest, &mut shape).expect("support");
                        let mut f = Matrix3::identity();
                        let mut position = *x;
                        for ((phi, g), u) in shape.values().iter().zip(shape.gradients()).zip(&u) {
                            position += *phi * u;
                            f += u * g.transpose();
                        }
                        (position, f, 1e-12)
                    }
                    EmbeddingMethod::Gradients => {
                        let mut total = 0.0;
                        let (mut shift, mut g) = (Vector::zeros(), Matrix3::zeros());
                        for ((r, u), gu) in rest.iter().zip(&u).zip(&grad_u) {
                            let q2 = (x - r).norm_squared() / (H * H);
                            if q2 < 1.0 {
                                let w = (1.0 - q2).powi(3);
                                total += w;
                                shift += w * (u + gu * (x - r));
                                g += w * gu;
                            }
                        }
                        (x + shift / total, Matrix3::identity() + g / total, 1e-6)
                    }
                };
                let error = (out.vertices[v] - position).norm();
                assert!(error < tolerance, "{name} {method:?} vertex {v}: {error:e}");
                let error = (out.normals[v] - normal(f, &n0[v])).norm();
                assert!(error < tolerance, "{name} {method:?} normal {v}: {error:e}");
            }
        }
    }
}

#[test]
fn rigid_motions_keep_area_and_volume() {
    let rotation = Rotation3::from_axis_angle(
        &nalgebra::Unit::new_normalize(Vector::new(1.0, -2.0, 0.5)),
        2.1,
    );
    let shift = Vector::new(-3.0, 0.7, 1.2);
    for (name, mesh) in meshes() {
        let (area, volume) = (mesh.area(), mesh.signed_volume());
        for method in METHODS {
            let (surface, out) = deform(&mesh, method, |x| rotation * x + shift);
            let moved = out.to_mesh(surface.triangles());
            assert!(
                (moved.area() - area).abs() < 1e-10 * area,
                "{name} {method:?}: area {} -> {}",
                area,
                moved.area()
            );
            assert!(
                (moved.signed_volume() - volume).abs() < 1e-10 * volume,
                "{name} {method:?}: volume {} -> {}",
                volume,
                moved.signed_volume()
            );
            // The mesh did move: the test is not passed by a no-op.
            assert!((moved.vertices[0] - mesh.vertices[0]).norm() > 1.0);
        }
    }
}

/// `u = (0, c (x - x0)^2, 0)`. A scheme that reproduces affine fields with
/// non-negative weights summing to one and reaching no farther than `h`
/// errs by at most the Taylor remainder `c h^2`; Alternative 1's weights
/// can be slightly negative near the block's faces and Alternative 2 uses
/// estimated gradients, so each gets the bound `c h^2` on positions, and
/// `2 c h`, the bound on the error of a gradient estimate of a field with
/// second derivative `2 c` over a support `h`, on the normals' angle.
#[test]
fn a_smooth_bend_stays_within_the_taylor_bound() {
    let c = 0.5;
    let x0 = centre().x;
    let bend = |x: &Vector| x + Vector::new(0.0, c * (x.x - x0).powi(2), 0.0);
    let (position_bound, angle_bound) = (c * H * H, 2.0 * c * H);
    for (name, mesh) in meshes() {
        let n0 = normals(&mesh);
        let exact: Vec<Vector> = mesh.vertices.iter().map(bend).collect();
        let exact_normals: Vec<Vector> = mesh
            .vertices
            .iter()
            .zip(&n0)
            .map(|(x, n)| {
                // F = I + 2c (x - x0) e_y e_x^T; normals map by F^-T.
                let mut f = Matrix3::identity();
                f[(1, 0)] = 2.0 * c * (x.x - x0);
                (f.try_inverse().expect("shear").transpose() * n).normalize()
            })
            .collect();
        for method in METHODS {
            let (_, out) = deform(&mesh, method, bend);
            let position_error = out
                .vertices
                .iter()
                .zip(&exact)
                .map(|(a, b)| (a - b).norm())
                .fold(0.0, Real::max);
            let angle_error = max_angle(&out.normals, &exact_normals);
            println!(
                "bend c = {c}, h = {H}, {name:<9} {method:<16}: max position error {position_error:.3e} \
                 ({:.3} c h^2), max normal angle {angle_error:.3e} rad ({:.3} c h)",
                position_error / (c * H * H),
                angle_error / (c * H),
                method = format!("{method:?}"),
            );
            assert!(
                position_error < position_bound,
                "{name} {method:?}: {position_error:e}"
            );
            assert!(
                angle_error < angle_bound,
                "{name} {method:?}: {angle_error:e}"
            );
        }
    }
}

#[test]
fn a_vertex_outside_the_support_is_named() {
    let mut mesh = TriMesh::icosphere(centre(), 0.28, 1);
    mesh.vertices[5] = Vector::new(2.0, 0.4, 0.4);
    for method in METHODS {
        let err = EmbeddedSurface::new(&mesh, &particles(), 3, H, Order::Linear, method)
            .expect_err("vertex 5 is far outside");
        assert!(
            matches!(err, EmbedError::NoSupport { vertex: 5, h, .. } if h == H),
            "{err:?}"
        );
        let message = err.to_string();
        assert!(
            message.contains("vertex 5") && message.contains("enlarge h"),
            "{message}"
        );
    }
}

#[test]
fn mismatched_lengths_are_errors() {
    let mesh = TriMesh::icosphere(centre(), 0.28, 1);
    let rest = particles();
    let n = rest.len();
    let mut out = DeformedSurface::new();
    for method in METHODS {
        let surface =
            EmbeddedSurface::new(&mesh, &rest, 3, H, Order::Linear, method).expect("embedding");
        let err = surface
            .update(&rest[1..], &vec![Matrix3::zeros(); n], &mut out)
            .expect_err("one position short");
        assert_eq!(
            err,
            EmbedError::LengthMismatch {
                what: "positions",
                got: n - 1,
                expected: n
            }
        );
        let result = surface.update(&rest, &[], &mut out);
        match method {
            // Alternative 1 does not read the gradients.
            EmbeddingMethod::ShapeFunctions => result.expect("gradients unused"),
            EmbeddingMethod::Gradients => assert_eq!(
                result.expect_err("no gradients"),
                EmbedError::LengthMismatch {
                    what: "grad_u",
                    got: 0,
                    expected: n
                }
            ),
        }
    }
}

#[test]
fn bad_parameters_are_errors() {
    let mesh = TriMesh::icosphere(centre(), 0.28, 1);
    let rest = particles();
    let method = EmbeddingMethod::ShapeFunctions;
    let embed = |mesh: &TriMesh, rest: &[Vector], dim, h| {
        EmbeddedSurface::new(mesh, rest, dim, h, Order::Linear, method)
    };
    assert_eq!(
        embed(&mesh, &rest, 2, H).expect_err("2D"),
        EmbedError::Dimension { dim: 2 }
    );
    for h in [0.0, -1.0, Real::NAN, Real::INFINITY] {
        let err = embed(&mesh, &rest, 3, h).expect_err("bad h");
        assert!(matches!(err, EmbedError::Parameter(_)), "h = {h}: {err:?}");
    }
    let mut broken = mesh.clone();
    broken.triangles[3][1] = 10_000;
    assert!(matches!(
        embed(&broken, &rest, 3, H).expect_err("bad index"),
        EmbedError::Mesh(_)
    ));
    let mut nan = rest.clone();
    nan[7].y = Real::NAN;
    assert_eq!(
        embed(&mesh, &nan, 3, H).expect_err("NaN particle"),
        EmbedError::NonFiniteParticle { particle: 7 }
    );
    let err = embed(&mesh, &[], 3, H).expect_err("no particles");
    assert!(
        matches!(
            err,
            EmbedError::NoSupport {
                vertex: 0,
                particles: 0,
                ..
            }
        ),
        "{err:?}"
    );
}

/// The result does not depend on the thread count, and a reused output
/// keeps its buffers.
#[test]
fn results_are_deterministic_and_buffers_reused() {
    let mesh = TriMesh::icosphere(centre(), 0.28, 4);
    let rest = particles();
    let current: Vec<Vector> = rest
        .iter()
        .map(|x| x + Vector::new(0.1 * x.y * x.y, 0.0, -0.05 * x.x))
        .collect();
    let grad_u = gradients(&rest, &current);
    for method in METHODS {
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool");
            pool.install(|| {
                let surface = EmbeddedSurface::new(&mesh, &rest, 3, H, Order::Linear, method)
                    .expect("embedding");
                let mut out = DeformedSurface::new();
                surface.update(&current, &grad_u, &mut out).expect("update");
                let pointers = (out.vertices.as_ptr(), out.normals.as_ptr());
                surface.update(&current, &grad_u, &mut out).expect("update");
                assert_eq!(pointers, (out.vertices.as_ptr(), out.normals.as_ptr()));
                out
            })
        };
        let (one, four) = (run(1), run(4));
        assert_eq!(one.vertices, four.vertices, "{method:?}");
        assert_eq!(one.normals, four.normals, "{method:?}");
    }
}

#[test]
fn methods_read_as_snake_case() {
    #[derive(serde::Deserialize)]
    struct Config {
        method: EmbeddingMethod,
    }
    for (text, method) in [
        ("shape_functions", EmbeddingMethod::ShapeFunctions),
        ("gradients", EmbeddingMethod::Gradients),
    ] {
        let config: Config = toml::from_str(&format!("method = \"{text}\"")).expect("toml");
        assert_eq!(config.method, method);
    }
}
