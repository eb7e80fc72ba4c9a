//! PLY (Stanford) meshes, ASCII or binary of either byte order, parsed by
//! `ply-rs-bw` into the two elements a surface needs: `vertex` with scalar
//! `x`, `y`, `z` (any numeric type) and `face` with an integer list
//! `vertex_indices` (or `vertex_index`). Other elements and properties
//! (normals, colours, edges, materials) are read past and ignored.

use super::{LoadedMesh, Triangulator, non_finite, parser_message, quote};
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

/// One `vertex` element: its position; other properties are skipped.
struct PlyVertex([Real; 3]);

impl PropertyAccess for PlyVertex {
    fn new() -> Self {
        Self([0.0; 3])
    }

    fn set_property(&mut self, name: &str, property: Property) {
        let axis = match name {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => return,
        };
        // The header check admits only scalar coordinates.
        self.0[axis] = match property {
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

/// Parses a whole PLY file held in memory.
pub(super) fn parse(path: &Path, bytes: &[u8]) -> Result<LoadedMesh, MeshError> {
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
        match element.name.as_str() {
            "vertex" => {
                check_vertex_header(element).map_err(|m| parse_error("header", m))?;
                vertices = Parser::<PlyVertex>::new()
                    .read_payload_for_element(reader, element, &header)
                    .map_err(read_error)?;
            }
            "face" => {
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
    let vertices: Vec<Vector> = vertices.into_iter().map(|v| Vector::from(v.0)).collect();
    if let Some((i, value)) = vertices
        .iter()
        .enumerate()
        .find_map(|(i, v)| non_finite(v).map(|value| (i, value)))
    {
        return Err(MeshError::NonFinite {
            path: path.to_path_buf(),
            location: format!("vertex {i}"),
            value,
        });
    }
    let mut triangulator = Triangulator::default();
    let mut polygon = Vec::new();
    for (f, face) in faces.iter().enumerate() {
        if face.0.len() < 3 {
            return Err(parse_error(
                &format!("face {f}"),
                format!(
                    "a face needs at least three corners, found {}",
                    face.0.len()
                ),
            ));
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

fn check_vertex_header(element: &ElementDef) -> Result<(), String> {
    for axis in ["x", "y", "z"] {
        match element.properties.get(axis).map(|p| &p.data_type) {
            Some(PropertyType::Scalar(_)) => {}
            Some(PropertyType::List(..)) => {
                return Err(format!(
                    "vertex property '{axis}' is a list; it must be a number"
                ));
            }
            None => return Err(format!("vertex element has no property '{axis}'")),
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
