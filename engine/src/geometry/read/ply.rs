//! PLY (Stanford) files, ASCII or binary of either byte order, parsed by
//! `ply-rs-bw`. A mesh takes two elements: `vertex` with scalar `x`, `y`,
//! `z` (any numeric type) and `face` with an integer list
//! `vertex_indices` (or `vertex_index`). An oriented point cloud takes the
//! `vertex` element alone, with scalar normals `nx`, `ny`, `nz` as well;
//! its faces, if any, are read past. Other elements and properties
//! (colours, edges, materials; normals for a mesh) are read past and
//! ignored.

use super::{LoadedMesh, OrientedPoints, Triangulator, non_finite, parser_message, quote};
use crate::geometry::MeshError;
use crate::math::{Real, Vector};
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{ElementDef, Property, PropertyAccess, PropertyType, ScalarType};
use std::path::Path;

/// Longest parser message an error carries, in characters: short enough
/// that what it quotes stays within the quoting rule.
const MAX_MESSAGE_CHARS: usize = 72;

/// What an error keeps of the parser's message: its first line, cut to
/// [`MAX_MESSAGE_CHARS`]. The parser quotes the offending line in full on
/// the lines after it (`String: '...'`, with content that may hold quotes
/// of its own), which would echo the file back to whoever sent it (found
/// by the `mesh_ply` fuzz target).
fn parser_summary(message: &str) -> String {
    parser_message(
        message.lines().next().unwrap_or_default(),
        MAX_MESSAGE_CHARS,
    )
}

const FACE_LISTS: [&str; 2] = ["vertex_indices", "vertex_index"];

/// The vertex properties kept, in the order [`PlyVertex`] stores them:
/// the position, then the normal.
const VERTEX_SCALARS: [&str; 6] = ["x", "y", "z", "nx", "ny", "nz"];

/// One `vertex` element: its position and its normal (zero where the file
/// has none; only an oriented point cloud asks for it, and its header
/// check makes sure the file has one). Other properties are skipped.
struct PlyVertex([Real; 6]);

impl PlyVertex {
    fn position(&self) -> Vector {
        Vector::new(self.0[0], self.0[1], self.0[2])
    }

    fn normal(&self) -> Vector {
        Vector::new(self.0[3], self.0[4], self.0[5])
    }
}

impl PropertyAccess for PlyVertex {
    fn new() -> Self {
        Self([0.0; 6])
    }

    fn set_property(&mut self, name: &str, property: Property) {
        let Some(slot) = VERTEX_SCALARS.iter().position(|&s| s == name) else {
            return;
        };
        // The header check admits only scalars for the properties it asks
        // for; a list-valued normal of a mesh, which is never read, reads
        // as NaN here.
        self.0[slot] = match property {
            Property::Char(v) => v.into(),
            Property::UChar(v) => v.into(),
            Property::Short(v) => v.into(),
            Property::UShort(v) => v.into(),
            Property::Int(v) => v.into(),
            Property::UInt(v) => v.into(),
            Property::Float(v) => v.into(),
            Property::Double(v) => v,
            _ => Real::NAN,
        };
    }
}

/// One `face` element: its corner indices, widened so that negative and
/// out-of-range values can be reported rather than wrapped.
struct PlyFace(Vec<i64>);

impl PropertyAccess for PlyFace {
    fn new() -> Self {
        Self(Vec::new())
    }

    fn set_property(&mut self, name: &str, property: Property) {
        if !FACE_LISTS.contains(&name) {
            return;
        }
        self.0 = match property {
            Property::ListChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListInt(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUInt(v) => v.into_iter().map(i64::from).collect(),
            _ => Vec::new(),
        };
    }
}

/// Any other element, read past.
struct Skipped;

impl PropertyAccess for Skipped {
    fn new() -> Self {
        Self
    }
}

/// What the caller makes of the file, which decides the elements read and
/// the properties required.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Wanted {
    /// Vertices (positions) and faces.
    Mesh,
    /// Vertices with normals; faces are read past.
    OrientedPoints,
}

/// Reads the header and every element of a whole PLY file held in memory:
/// the vertices, and the faces when a mesh is wanted (empty otherwise).
fn read_elements(
    path: &Path,
    bytes: &[u8],
    wanted: Wanted,
) -> Result<(Vec<PlyVertex>, Vec<PlyFace>), MeshError> {
    let parse_error = |location: &str, message: String| MeshError::Parse {
        path: path.to_path_buf(),
        location: location.to_string(),
        message,
    };
    let reader = &mut std::io::BufReader::new(bytes);
    let header = Parser::<Skipped>::new()
        .read_header(reader)
        .map_err(|e| parse_error("header", parser_summary(&e.to_string())))?;
    // Every element takes at least one byte of the file, so a header that
    // announces more elements than the file has bytes is refused before
    // the parser reserves room for them (a 100-byte file could otherwise
    // ask for billions).
    let announced: u128 = header.elements.values().map(|e| e.count as u128).sum();
    if announced > bytes.len() as u128 {
        return Err(parse_error(
            "header",
            format!(
                "the header announces {announced} elements but the file has only {} bytes; \
                 fix the element counts",
                bytes.len()
            ),
        ));
    }
    if wanted == Wanted::OrientedPoints && !header.elements.contains_key("vertex") {
        return Err(parse_error(
            "header",
            "no 'vertex' element; an oriented point cloud needs one with x, y, z, nx, ny, nz"
                .to_string(),
        ));
    }
    let mut vertices = Vec::new();
    let mut faces = Vec::new();
    for element in header.elements.values() {
        let location = format!("element {}", quote(&element.name));
        // The parser folds end-of-file into its message text, so the hint
        // names both causes.
        let read_error = |e: std::io::Error| {
            parse_error(
                &location,
                format!(
                    "{} (is the file truncated, or does it not match its header?)",
                    parser_summary(&e.to_string())
                ),
            )
        };
        match (element.name.as_str(), wanted) {
            ("vertex", _) => {
                check_vertex_header(element, wanted).map_err(|m| parse_error("header", m))?;
                vertices = Parser::<PlyVertex>::new()
                    .read_payload_for_element(reader, element, &header)
                    .map_err(read_error)?;
            }
            ("face", Wanted::Mesh) => {
                check_face_header(element).map_err(|m| parse_error("header", m))?;
                faces = Parser::<PlyFace>::new()
                    .read_payload_for_element(reader, element, &header)
                    .map_err(read_error)?;
            }
            _ => {
                Parser::<Skipped>::new()
                    .read_payload_for_element(reader, element, &header)
                    .map_err(read_error)?;
            }
        }
    }
    Ok((vertices, faces))
}

/// The first vertex with a non-finite value among those `values` gives,
/// and that value.
fn first_non_finite(
    vertices: &[PlyVertex],
    values: impl Fn(&PlyVertex) -> Vector,
) -> Option<(usize, Real)> {
    vertices
        .iter()
        .enumerate()
        .find_map(|(i, v)| non_finite(&values(v)).map(|value| (i, value)))
}

/// Parses a whole PLY mesh held in memory.
pub(super) fn parse(path: &Path, bytes: &[u8]) -> Result<LoadedMesh, MeshError> {
    let (vertices, faces) = read_elements(path, bytes, Wanted::Mesh)?;
    if let Some((i, value)) = first_non_finite(&vertices, PlyVertex::position) {
        return Err(MeshError::NonFinite {
            path: path.to_path_buf(),
            location: format!("vertex {i}"),
            value,
        });
    }
    let vertices: Vec<Vector> = vertices.iter().map(PlyVertex::position).collect();
    let mut triangulator = Triangulator::default();
    let mut polygon = Vec::new();
    for (f, face) in faces.iter().enumerate() {
        if face.0.len() < 3 {
            return Err(MeshError::Parse {
                path: path.to_path_buf(),
                location: format!("face {f}"),
                message: format!(
                    "a face needs at least three corners, found {}",
                    face.0.len()
                ),
            });
        }
        polygon.clear();
        for &index in &face.0 {
            match u32::try_from(index) {
                Ok(i) if (i as usize) < vertices.len() => polygon.push(i),
                _ => {
                    return Err(MeshError::IndexOutOfRange {
                        path: path.to_path_buf(),
                        location: format!("face {f}"),
                        index,
                        vertex_count: vertices.len(),
                    });
                }
            }
        }
        triangulator.add_polygon(&polygon);
    }
    triangulator.finish(path, vertices)
}

/// Parses a whole PLY oriented point cloud held in memory. Normals are
/// taken as written (their length and direction are the surface fit's to
/// judge, see [`crate::geometry::PointSurface::new`]); only a value that
/// is not a number is refused here, where the file and vertex can be
/// named.
pub(super) fn parse_oriented_points(
    path: &Path,
    bytes: &[u8],
) -> Result<OrientedPoints, MeshError> {
    let (vertices, _) = read_elements(path, bytes, Wanted::OrientedPoints)?;
    if let Some((i, value)) = first_non_finite(&vertices, PlyVertex::position) {
        return Err(MeshError::NonFinite {
            path: path.to_path_buf(),
            location: format!("vertex {i}"),
            value,
        });
    }
    if let Some((i, value)) = first_non_finite(&vertices, PlyVertex::normal) {
        return Err(MeshError::Parse {
            path: path.to_path_buf(),
            location: format!("vertex {i}"),
            message: format!(
                "normal component {value} is not finite; every vertex needs finite nx, ny, nz"
            ),
        });
    }
    Ok(OrientedPoints {
        points: vertices.iter().map(PlyVertex::position).collect(),
        normals: vertices.iter().map(PlyVertex::normal).collect(),
    })
}

/// Checks that the vertex element has the scalar properties `wanted`
/// reads: the position, and for an oriented point cloud the normal.
fn check_vertex_header(element: &ElementDef, wanted: Wanted) -> Result<(), String> {
    let required = match wanted {
        Wanted::Mesh => &VERTEX_SCALARS[..3],
        Wanted::OrientedPoints => &VERTEX_SCALARS[..],
    };
    for name in required {
        match element.properties.get(*name).map(|p| &p.data_type) {
            Some(PropertyType::Scalar(_)) => {}
            Some(PropertyType::List(..)) => {
                return Err(format!(
                    "vertex property '{name}' is a list; it must be a number"
                ));
            }
            None if name.starts_with('n') => {
                return Err(format!(
                    "vertex element has no property '{name}'; an oriented point cloud needs \
                     a normal (nx, ny, nz) for every vertex"
                ));
            }
            None => return Err(format!("vertex element has no property '{name}'")),
        }
    }
    Ok(())
}

fn check_face_header(element: &ElementDef) -> Result<(), String> {
    let list = FACE_LISTS
        .iter()
        .find_map(|name| element.properties.get(*name))
        .ok_or("face element has no list property 'vertex_indices' (or 'vertex_index')")?;
    match &list.data_type {
        PropertyType::List(_, ScalarType::Float | ScalarType::Double) | PropertyType::Scalar(_) => {
            Err(format!(
                "face property '{}' must be a list of integers",
                list.name
            ))
        }
        PropertyType::List(..) => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(bytes: &[u8]) -> Result<LoadedMesh, MeshError> {
        parse(Path::new("test.ply"), bytes)
    }

    const SQUARE: &str = "ply\nformat ascii 1.0\ncomment unit square\nelement vertex 4\n\
        property double x\nproperty double y\nproperty double z\nproperty uchar red\n\
        element face 1\nproperty list uchar int vertex_indices\nelement edge 1\n\
        property int vertex1\nproperty int vertex2\nend_header\n\
        0 0 0 1\n1 0 0 2\n1 1 0 3\n0 1 0 4\n4 0 1 2 3\n0 1\n";

    #[test]
    fn reads_ascii_quads_skipping_other_properties_and_elements() {
        let loaded = read(SQUARE.as_bytes()).expect("valid ply");
        assert_eq!(loaded.mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(loaded.mesh.vertices[2], Vector::new(1.0, 1.0, 0.0));
    }

    #[test]
    fn a_header_announcing_more_elements_than_bytes_is_refused_before_reading() {
        let header = "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\n\
            property float x\nproperty float y\nproperty float z\nend_header\n";
        let err = read(header.as_bytes()).expect_err("a hostile count");
        assert!(err.to_string().contains("4000000000 elements"), "{err}");
    }

    #[test]
    fn bad_headers_and_bodies_are_errors() {
        let cases = [
            (SQUARE.replace("ply\n", "plx\n"), "header"),
            (SQUARE.replace("property double z\n", ""), "no property 'z'"),
            (
                SQUARE.replace("vertex_indices", "corners"),
                "vertex_indices",
            ),
            (
                SQUARE.replace("list uchar int", "list uchar float"),
                "list of integers",
            ),
            (
                SQUARE.replace("0 1 0 4\n", "0 1 zero 4\n"),
                "element \"vertex\"",
            ),
            (SQUARE.replace("4 0 1 2 3\n0 1\n", ""), "truncated"),
            (SQUARE.replace("4 0 1 2 3", "4 0 1 2 9"), "face 0"),
            (SQUARE.replace("4 0 1 2 3", "2 0 1"), "at least three"),
        ];
        for (text, what) in cases {
            let err = read(text.as_bytes()).expect_err(what);
            assert!(err.to_string().contains(what), "{what}: {err}");
        }
    }

    /// A cloud of four points with normals, and the header before its
    /// body in each format: ASCII, and binary with floats (little endian)
    /// or doubles (big endian), with an extra property and a face element
    /// that the reader skips.
    const CLOUD: [[Real; 6]; 4] = [
        [0.0, 0.0, 0.0, 0.0, 0.0, -1.0],
        [1.5, 0.0, 0.0, 1.0, 0.0, 0.0],
        [0.0, -2.25, 0.0, 0.0, -1.0, 0.0],
        [0.0, 0.0, 3.0, 0.0, 0.6, 0.8],
    ];

    fn cloud_header(format: &str, scalar: &str) -> String {
        let properties: String = ["x", "y", "z", "nx", "ny", "nz"]
            .iter()
            .map(|p| format!("property {scalar} {p}\n"))
            .collect();
        format!(
            "ply\nformat {format} 1.0\nelement vertex 4\n{properties}property uchar red\n\
             element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        )
    }

    fn ascii_cloud() -> String {
        let mut text = cloud_header("ascii", "float");
        for v in CLOUD {
            let row: Vec<String> = v.iter().map(Real::to_string).collect();
            text += &format!("{} 7\n", row.join(" "));
        }
        text + "3 0 1 2\n"
    }

    /// `cloud` in binary, little endian floats, its face included.
    fn binary_cloud(cloud: [[Real; 6]; 4]) -> Vec<u8> {
        let mut bytes = cloud_header("binary_little_endian", "float").into_bytes();
        for v in cloud {
            for x in v {
                bytes.extend((x as f32).to_le_bytes());
            }
            bytes.push(7);
        }
        bytes.push(3);
        for corner in 0_i32..3 {
            bytes.extend(corner.to_le_bytes());
        }
        bytes
    }

    fn assert_cloud(cloud: &OrientedPoints) {
        let points: Vec<Vector> = CLOUD
            .iter()
            .map(|v| Vector::new(v[0], v[1], v[2]))
            .collect();
        let normals: Vec<Vector> = CLOUD
            .iter()
            .map(|v| Vector::new(v[3], v[4], v[5]))
            .collect();
        assert_eq!(cloud.points, points);
        // 0.6 and 0.8 went through f32 in two of the files.
        for (n, expected) in cloud.normals.iter().zip(&normals) {
            assert!((n - expected).norm() < 1e-7, "{n} != {expected}");
        }
    }

    #[test]
    fn oriented_points_round_trip_ascii_and_binary() {
        let dir = std::env::temp_dir().join(format!("meshless-ply-cloud-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let mut big = cloud_header("binary_big_endian", "double").into_bytes();
        for v in CLOUD {
            for x in v {
                big.extend(x.to_be_bytes());
            }
            big.push(7);
        }
        big.push(3);
        for corner in 0_i32..3 {
            big.extend(corner.to_be_bytes());
        }
        for (name, bytes) in [
            ("ascii.ply", ascii_cloud().into_bytes()),
            ("little.ply", binary_cloud(CLOUD)),
            ("big.ply", big),
        ] {
            let file = dir.join(name);
            std::fs::write(&file, &bytes).expect("write");
            let cloud = crate::geometry::read::oriented_points(&file).expect(name);
            assert_cloud(&cloud);
            // The mesh reader still reads the same file as a mesh.
            let mesh = parse(&file, &bytes).expect(name);
            assert_eq!(mesh.mesh.triangles, vec![[0, 1, 2]]);
        }
        std::fs::remove_dir_all(&dir).expect("clean up");
    }

    #[test]
    fn oriented_points_without_normals_or_vertices_are_refused() {
        let read = |text: String| parse_oriented_points(Path::new("cloud.ply"), text.as_bytes());
        let err = read(ascii_cloud().replace("property float ny\n", "")).expect_err("no ny");
        assert!(matches!(&err, MeshError::Parse { location, .. } if location == "header"));
        assert!(err.to_string().contains("no property 'ny'"), "{err}");
        assert!(err.to_string().contains("normal (nx, ny, nz)"), "{err}");
        // A mesh file without normals reads as a mesh, not as a cloud.
        let err = read(SQUARE.to_string()).expect_err("a mesh without normals");
        assert!(err.to_string().contains("no property 'nx'"), "{err}");
        let err = read(
            "ply\nformat ascii 1.0\nelement point 1\nproperty float x\nend_header\n1\n".to_string(),
        )
        .expect_err("no vertex element");
        assert!(err.to_string().contains("no 'vertex' element"), "{err}");
        // Not-a-number values come in binary files (ASCII ones cannot
        // spell them).
        let mut cloud = CLOUD;
        cloud[3][4] = Real::NAN;
        let err =
            parse_oriented_points(Path::new("cloud.ply"), &binary_cloud(cloud)).expect_err("NaN");
        assert!(
            err.to_string().contains("vertex 3: normal component NaN"),
            "{err}"
        );
        cloud[1][0] = Real::INFINITY;
        let err = parse_oriented_points(Path::new("cloud.ply"), &binary_cloud(cloud))
            .expect_err("infinite");
        assert!(
            matches!(&err, MeshError::NonFinite { location, .. } if location == "vertex 1"),
            "{err}"
        );
        // Normals as lists are not numbers.
        let err = read(ascii_cloud().replace("property float nz", "property list uchar float nz"))
            .expect_err("a list");
        assert!(err.to_string().contains("'nz' is a list"), "{err}");
    }

    /// Garbage, whether not PLY at all or a body that does not match its
    /// header, is refused with a message that quotes no more than a short
    /// prefix of it.
    #[test]
    fn garbage_clouds_are_refused_without_echoing_them() {
        let long = "g".repeat(5000);
        let mut seed = 1_u64;
        let noise: Vec<u8> = (0..5000)
            .map(|_| (crate::testing::uniform(&mut seed) * 256.0) as u8)
            .collect();
        for (bytes, what) in [
            (format!("{long}\n{long}").into_bytes(), "header"),
            (noise, "header"),
            (
                ascii_cloud().replacen("1.5", &long, 1).into_bytes(),
                "element \"vertex\"",
            ),
            (
                ascii_cloud()
                    .replace("3 0 1 2\n", &format!("3 0 {long}\n"))
                    .into_bytes(),
                "element \"face\"",
            ),
        ] {
            let err = parse_oriented_points(Path::new("cloud.ply"), &bytes).expect_err(what);
            let message = err.to_string();
            assert!(message.contains(what), "{what}: {message}");
            assert!(!message.contains(&"g".repeat(65)), "{message}");
            assert!(message.len() < 300, "{} bytes: {message}", message.len());
        }
    }

    /// The parser quotes a bad header line, and the reader names an
    /// element, in full; an error repeats neither past a short prefix
    /// (`fuzz/regressions/mesh_ply` holds the input that found it: a
    /// header line with a quote of its own inside).
    #[test]
    fn errors_quote_at_most_a_short_prefix_of_the_file() {
        let long = "q".repeat(500);
        for text in [
            SQUARE.replace("comment unit square", &format!("format ascii 1.'{long}")),
            SQUARE
                .replace("element edge 1", &format!("element {long} 1"))
                .replace("4 0 1 2 3\n0 1\n", "4 0 1 2 3\n"),
        ] {
            let message = read(text.as_bytes()).expect_err("refused").to_string();
            assert!(!message.contains(&"q".repeat(65)), "{message}");
            assert!(message.len() < 300, "{message}");
        }
    }
}
