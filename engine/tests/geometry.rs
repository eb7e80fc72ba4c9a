//! Meshes written to disk as OBJ and PLY (ASCII and binary, in the number
//! types tools emit) read back with their analytic area and volume, bad
//! files give the documented errors without panicking, and a mesh read
//! from a file feeds the signed distance and the samplers.

use meshless_engine::geometry::{self, MeshError, MeshSdf, TriMesh};
use meshless_engine::math::{Real, Vector};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// A scratch directory removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> TempDir {
        let dir =
            std::env::temp_dir().join(format!("meshless-geometry-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        TempDir(dir)
    }

    fn write(&self, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
        let path = self.0.join(name);
        std::fs::write(&path, bytes).expect("write fixture");
        path
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The cube [0, 2]^3 as six quads, with texture and normal indices and
/// every face written with negative (relative) indices: area 24, volume 8.
const QUAD_CUBE_OBJ: &str = "\
# cube, quads
o cube
v 0 0 0
v 2 0 0
v 0 2 0
v 2 2 0
v 0 0 2
v 2 0 2
v 0 2 2
v 2 2 2
vt 0 0
vn 0 0 1
s off
f -8/1/1 -4/1/1 -2/1/1 -6/1/1
f -7//1 -5//1 -1//1 -3//1
g bottom
f 1/1 2/1 6/1 5/1
f 3 7 8 4
f 1 3 4 2
f 5 6 8 7
";

fn obj_text(mesh: &TriMesh) -> String {
    let mut text = String::from("# written by the test\n");
    for v in &mesh.vertices {
        text += &format!("v {:.17e} {:.17e} {:.17e}\n", v.x, v.y, v.z);
    }
    for t in &mesh.triangles {
        text += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    text
}

#[derive(Clone, Copy, Debug)]
enum Encoding {
    Ascii,
    Binary,
}

/// How a PLY file stores its numbers.
#[derive(Clone, Copy, Debug)]
struct PlyKind {
    encoding: Encoding,
    double: bool,
    /// `uchar` list counts, else `int`.
    uchar_count: bool,
    /// `uint` indices, else `int`.
    uint_index: bool,
}

fn ply_bytes(mesh: &TriMesh, kind: PlyKind) -> Vec<u8> {
    let format = match kind.encoding {
        Encoding::Ascii => "ascii",
        Encoding::Binary => "binary_little_endian",
    };
    let scalar = if kind.double { "double" } else { "float" };
    let count = if kind.uchar_count { "uchar" } else { "int" };
    let index = if kind.uint_index { "uint" } else { "int" };
    let mut out = format!(
        "ply\nformat {format} 1.0\ncomment written by the test\nelement vertex {}\n\
         property {scalar} x\nproperty {scalar} y\nproperty {scalar} z\nproperty float nx\n\
         element face {}\nproperty list {count} {index} vertex_indices\nproperty uchar red\nend_header\n",
        mesh.vertices.len(),
        mesh.triangles.len()
    )
    .into_bytes();
    for v in &mesh.vertices {
        match kind.encoding {
            Encoding::Ascii => {
                out.extend(format!("{:.17e} {:.17e} {:.17e} 0\n", v.x, v.y, v.z).bytes())
            }
            Encoding::Binary => {
                for x in v.iter() {
                    if kind.double {
                        out.extend(x.to_le_bytes());
                    } else {
                        out.extend((*x as f32).to_le_bytes());
                    }
                }
                out.extend(0.0_f32.to_le_bytes());
            }
        }
    }
    for t in &mesh.triangles {
        match kind.encoding {
            Encoding::Ascii => out.extend(format!("3 {} {} {} 7\n", t[0], t[1], t[2]).bytes()),
            Encoding::Binary => {
                if kind.uchar_count {
                    out.push(3);
                } else {
                    out.extend(3_i32.to_le_bytes());
                }
                for i in t {
                    out.extend(i.to_le_bytes());
                }
                out.push(7);
            }
        }
    }
    out
}

fn all_ply_kinds() -> Vec<PlyKind> {
    let mut kinds = Vec::new();
    for encoding in [Encoding::Ascii, Encoding::Binary] {
        for double in [false, true] {
            for uchar_count in [false, true] {
                for uint_index in [false, true] {
                    kinds.push(PlyKind {
                        encoding,
                        double,
                        uchar_count,
                        uint_index,
                    });
                }
            }
        }
    }
    kinds
}

fn assert_close(what: &str, value: Real, expected: Real, tolerance: Real) {
    assert!(
        (value - expected).abs() <= tolerance * expected.abs(),
        "{what}: {value} vs {expected} (relative tolerance {tolerance})"
    );
}

/// The quad cube OBJ (fan triangulation, `v/vt/vn`, negative indices,
/// groups) is closed with area 24 and volume 8.
#[test]
fn quad_cube_obj_reads_with_the_cube_area_and_volume() {
    let dir = TempDir::new("quad-cube");
    let loaded = geometry::read::load(&dir.write("cube.OBJ", QUAD_CUBE_OBJ)).expect("valid obj");
    assert_eq!(loaded.dropped, 0);
    let mesh = loaded.mesh;
    assert_eq!((mesh.vertices.len(), mesh.triangles.len()), (8, 12));
    assert!(mesh.is_closed(), "{:?}", mesh.edge_report());
    assert_close("area", mesh.area(), 24.0, 1e-15);
    assert_close("volume", mesh.signed_volume(), 8.0, 1e-15);
}

/// A cube and an icosphere written as OBJ and as PLY in every encoding
/// and number type read back closed; the cube's area and volume are
/// exact, the icosphere's lie between those of the spheres of radius
/// `R - chord` and `R` that bound it (to f32 rounding for `float` PLY).
#[test]
fn cube_and_icosphere_round_trip_through_obj_and_every_ply_kind() {
    let dir = TempDir::new("round-trip");
    let radius = 1.5;
    let sphere = TriMesh::icosphere(Vector::zeros(), radius, 3);
    let chord = radius
        - (0..sphere.triangles.len())
            .map(|t| {
                let [a, b, c] = sphere.corners(t);
                (b - a).cross(&(c - a)).normalize().dot(&a)
            })
            .fold(Real::INFINITY, Real::min);
    let cube = TriMesh::cuboid(Vector::new(-1.0, -0.5, 0.0), Vector::new(1.0, 0.5, 3.0));
    for (name, mesh) in [("cube", &cube), ("sphere", &sphere)] {
        let mut files = vec![(dir.write(&format!("{name}.obj"), obj_text(mesh)), 1e-14)];
        for (k, kind) in all_ply_kinds().into_iter().enumerate() {
            let tolerance = if kind.double { 1e-14 } else { 1e-6 };
            files.push((
                dir.write(&format!("{name}-{k}.ply"), ply_bytes(mesh, kind)),
                tolerance,
            ));
        }
        for (path, tolerance) in files {
            let read = TriMesh::from_path(&path).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(read.triangles, mesh.triangles, "{}", path.display());
            assert!(read.is_closed(), "{}", path.display());
            let (area, volume) = (read.area(), read.signed_volume());
            let what = path.display().to_string();
            if name == "cube" {
                assert_close(&what, area, 2.0 * (2.0 + 6.0 + 3.0), tolerance);
                assert_close(&what, volume, 6.0, tolerance);
            } else {
                let r_in = radius - chord;
                let slack = 1.0 + tolerance;
                assert!(
                    area > 4.0 * PI * r_in * r_in / slack && area < 4.0 * PI * radius * radius,
                    "{what}: area {area}"
                );
                assert!(
                    volume > 4.0 / 3.0 * PI * r_in.powi(3) / slack
                        && volume < 4.0 / 3.0 * PI * radius.powi(3),
                    "{what}: volume {volume}"
                );
                assert_close(&what, area, mesh.area(), tolerance);
            }
        }
    }
}

fn expect_error(path: &Path) -> MeshError {
    match TriMesh::from_path(path) {
        Ok(mesh) => panic!(
            "{} read as {} triangles",
            path.display(),
            mesh.triangles.len()
        ),
        Err(e) => e,
    }
}

/// Every documented failure is an error naming the file and the place.
#[test]
fn bad_files_give_the_documented_errors() {
    let dir = TempDir::new("bad");
    let square = TriMesh {
        vertices: vec![
            Vector::zeros(),
            Vector::x(),
            Vector::new(1.0, 1.0, 0.0),
            Vector::y(),
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
    };
    let binary = PlyKind {
        encoding: Encoding::Binary,
        double: true,
        uchar_count: true,
        uint_index: false,
    };

    let err = expect_error(&dir.0.join("missing.ply"));
    assert!(matches!(err, MeshError::Unreadable { .. }), "{err}");
    let err = expect_error(&dir.write("mesh.stl", "solid"));
    assert!(matches!(err, MeshError::UnknownExtension { .. }), "{err}");

    let err = expect_error(&dir.write("bad-number.obj", "v 0 0 0\nv 1 0 0\nv 0 1 O\nf 1 2 3\n"));
    assert!(
        matches!(&err, MeshError::Parse { location, .. } if location == "line 3"),
        "{err}"
    );
    let err =
        expect_error(&dir.write("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n"));
    assert!(err.to_string().contains("range.obj"), "{err}");
    assert!(
        matches!(&err, MeshError::IndexOutOfRange { index: 4, location, .. } if location == "line 5"),
        "{err}"
    );
    let err = expect_error(&dir.write("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\np 1 2 3\n"));
    assert!(
        matches!(
            err,
            MeshError::NoTriangles {
                vertex_count: 3,
                ..
            }
        ),
        "{err}"
    );

    // Vertex 1's y: each vertex is three doubles and a float normal.
    let mut bytes = ply_bytes(&square, binary);
    let header_end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("header")
        + 11;
    bytes[header_end + 28 + 8..header_end + 28 + 16].copy_from_slice(&Real::NAN.to_le_bytes());
    let err = expect_error(&dir.write("nan.ply", &bytes));
    assert!(
        matches!(&err, MeshError::NonFinite { location, .. } if location == "vertex 1"),
        "{err}"
    );

    let mut bad_index = square.clone();
    bad_index.triangles[1][2] = 9;
    let err = expect_error(&dir.write("index.ply", ply_bytes(&bad_index, binary)));
    assert!(
        matches!(&err, MeshError::IndexOutOfRange { index: 9, location, .. } if location == "face 1"),
        "{err}"
    );

    let mut collapsed = square.clone();
    collapsed.triangles = vec![[0, 1, 1], [2, 2, 3]];
    let err = expect_error(&dir.write("collapsed.ply", ply_bytes(&collapsed, binary)));
    assert!(
        matches!(err, MeshError::NoTriangles { dropped: 2, .. }),
        "{err}"
    );

    let bytes = ply_bytes(&square, binary);
    let err = expect_error(&dir.write("short.ply", &bytes[..bytes.len() - 3]));
    assert!(err.to_string().contains("truncated"), "{err}");
}

/// Truncated and corrupted files never panic: every prefix of a binary
/// and an ASCII PLY and of an OBJ, and single-byte corruptions, are read
/// or rejected with an error.
#[test]
fn truncated_and_corrupted_files_never_panic() {
    let dir = TempDir::new("fuzz");
    let mesh = TriMesh::icosphere(Vector::zeros(), 1.0, 0);
    let binary = ply_bytes(
        &mesh,
        PlyKind {
            encoding: Encoding::Binary,
            double: false,
            uchar_count: false,
            uint_index: true,
        },
    );
    let ascii = ply_bytes(
        &mesh,
        PlyKind {
            encoding: Encoding::Ascii,
            double: false,
            uchar_count: true,
            uint_index: false,
        },
    );
    let obj = obj_text(&mesh).into_bytes();
    let mut tried = 0;
    for (name, bytes) in [("b.ply", &binary), ("a.ply", &ascii), ("o.obj", &obj)] {
        let path = dir.0.join(name);
        for end in (0..bytes.len()).step_by(7) {
            std::fs::write(&path, &bytes[..end]).expect("write");
            let _ = TriMesh::from_path(&path);
            tried += 1;
        }
        let mut state = 0x1234_u64;
        for _ in 0..300 {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let mut corrupted = bytes.clone();
            let at = (state >> 33) as usize % corrupted.len();
            corrupted[at] = (state >> 17) as u8;
            std::fs::write(&path, &corrupted).expect("write");
            if let Ok(read) = TriMesh::from_path(&path) {
                assert!(
                    read.validate().is_ok(),
                    "{name}: a read mesh is always valid"
                );
            }
            tried += 1;
        }
    }
    assert!(tried > 900);
}

/// A mesh read from a file feeds the signed distance and both samplers.
#[test]
fn a_read_mesh_feeds_the_signed_distance_and_the_samplers() {
    let dir = TempDir::new("pipeline");
    let mesh = TriMesh::from_path(&dir.write("cube.obj", QUAD_CUBE_OBJ)).expect("valid");
    let sdf = MeshSdf::new(&mesh).expect("closed");
    assert_close("centre", sdf.distance(&Vector::repeat(1.0)), -1.0, 1e-15);
    assert_close(
        "outside",
        sdf.distance(&Vector::new(3.0, 1.0, 1.0)),
        1.0,
        1e-15,
    );
    let inside = geometry::sample_volume(&sdf, 0.25).expect("fill");
    assert_eq!(inside.len(), 8 * 8 * 8);
    let surface = geometry::sample_surface(&mesh, 0.25).expect("sample");
    let ratio = surface.len() as Real * 0.25 * 0.25 / 24.0;
    assert!(
        (0.9..1.1).contains(&ratio),
        "{} surface samples",
        surface.len()
    );
}
