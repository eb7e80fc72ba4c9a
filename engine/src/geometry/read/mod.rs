//! Reading triangle meshes from OBJ and PLY files.
//!
//! Both readers apply the same policy, so a mesh means the same thing
//! whichever format it came in:
//!
//! - polygons are fan-triangulated from their first corner (exact for the
//!   convex polygons modelling tools write);
//! - a triangle that repeats a vertex index is *collapsed* (a fan over a
//!   polygon that lists a corner twice makes them): it has no area and no
//!   edges of its own, so it is dropped and counted in [`LoadedMesh::dropped`];
//! - a triangle with three distinct corners is kept even when its corners
//!   are collinear, because dropping it would open the mesh along its
//!   edges; [`crate::geometry::MeshSdf::new`] rejects such meshes, sampling
//!   just gives them no points;
//! - an index out of range, a non-finite coordinate, a face of fewer than
//!   three corners and a file without any triangle are errors that name
//!   the file and the line (OBJ) or element (PLY).

mod obj;
mod ply;

use super::{MeshError, TriMesh};
use crate::math::Vector;
use serde::{Deserialize, Serialize};
use std::io::Read;
use std::path::Path;

/// A mesh as read, with what the reader dropped.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedMesh {
    /// The triangulated mesh, coordinates as in the file.
    pub mesh: TriMesh,
    /// Collapsed triangles (a repeated vertex index) that were dropped.
    pub dropped: usize,
}

/// An oriented point cloud as read: each point with its normal, as
/// written in the file (finite, but neither unit nor checked nonzero).
#[derive(Debug, Clone, PartialEq)]
pub struct OrientedPoints {
    /// The points, coordinates as in the file.
    pub points: Vec<Vector>,
    /// The normal of each point, `normals[i]` that of `points[i]`.
    pub normals: Vec<Vector>,
}

/// The file formats the readers know.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MeshFormat {
    /// Wavefront OBJ (text).
    Obj,
    /// Stanford PLY (ASCII or binary).
    Ply,
}

impl MeshFormat {
    /// The format a file's extension names (`.obj` or `.ply`, any case).
    ///
    /// # Errors
    /// [`MeshError::UnknownExtension`] for any other extension.
    pub fn of_path(path: &Path) -> Result<Self, MeshError> {
        let extension = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        match extension.as_str() {
            "obj" => Ok(Self::Obj),
            "ply" => Ok(Self::Ply),
            _ => Err(MeshError::UnknownExtension {
                path: path.to_path_buf(),
                // A file's name is the caller's; still, no unbounded echo.
                extension: extension.chars().take(16).collect(),
            }),
        }
    }
}

/// Largest mesh file [`load`] reads: far above any mesh a scene samples
/// (the bodies' sampling limit is reached long before), and a bound on
/// what a path to `/dev/zero` or a runaway file can cost.
pub const MAX_FILE_BYTES: u64 = 1 << 30;

/// Reads a mesh file, choosing the format by the extension (`.obj` or
/// `.ply`, any case).
///
/// # Errors
/// See [`MeshError`]: unreadable file, not a regular file, larger than
/// [`MAX_FILE_BYTES`], unknown extension, parse errors, indices out of
/// range, non-finite coordinates, no triangles.
pub fn load(path: &Path) -> Result<LoadedMesh, MeshError> {
    let format = MeshFormat::of_path(path)?;
    let bytes = read_regular_file(path, MAX_FILE_BYTES).map_err(|e| MeshError::Unreadable {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    parse(path, format, &bytes)
}

/// Parses a mesh file's bytes; `label` names it in errors (a file's path,
/// or where an inline mesh sits in a scene).
///
/// # Errors
/// As [`load`], less the file's own failures.
pub fn parse(label: &Path, format: MeshFormat, bytes: &[u8]) -> Result<LoadedMesh, MeshError> {
    match format {
        // Lossy: a stray Latin-1 byte in a comment or name is no reason to
        // refuse the geometry.
        MeshFormat::Obj => obj::parse(label, &String::from_utf8_lossy(bytes)),
        MeshFormat::Ply => ply::parse(label, bytes),
    }
}

/// Reads an oriented point cloud from a PLY file (ASCII or binary): the
/// `vertex` element's `x`, `y`, `z` and `nx`, `ny`, `nz`; faces and other
/// elements are read past. The format is PLY whatever the extension: a
/// file that is not fails at its header.
///
/// # Errors
/// See [`MeshError`]: unreadable file, not a regular file, larger than
/// [`MAX_FILE_BYTES`], parse errors (among them a vertex element without
/// normals, and a normal that is not finite), non-finite coordinates.
pub fn oriented_points(path: &Path) -> Result<OrientedPoints, MeshError> {
    let bytes = read_regular_file(path, MAX_FILE_BYTES).map_err(|e| MeshError::Unreadable {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    parse_oriented_points(path, &bytes)
}

/// Parses an oriented point cloud's PLY bytes; `label` names it in errors.
///
/// # Errors
/// As [`oriented_points`], less the file's own failures.
pub fn parse_oriented_points(label: &Path, bytes: &[u8]) -> Result<OrientedPoints, MeshError> {
    ply::parse_oriented_points(label, bytes)
}

/// The whole of a regular file of at most `max_bytes`. A FIFO, a device
/// or a directory is refused before it is opened (reading a FIFO blocks
/// until a writer comes, a device may never end), and a file that grows
/// past the limit while read is refused rather than read on.
///
/// # Errors
/// The I/O error; `InvalidInput` for anything but a regular file,
/// `FileTooLarge` past the limit.
pub fn read_regular_file(path: &Path, max_bytes: u64) -> std::io::Result<Vec<u8>> {
    use std::io::{Error, ErrorKind};
    let invalid = |message: &str| Error::new(ErrorKind::InvalidInput, message);
    let too_large = |message: String| Error::new(ErrorKind::FileTooLarge, message);
    let metadata = std::fs::metadata(path)?;
    if !metadata.is_file() {
        return Err(invalid("not a regular file"));
    }
    if metadata.len() > max_bytes {
        return Err(too_large(format!(
            "{} bytes, over the limit of {max_bytes}",
            metadata.len()
        )));
    }
    let file = std::fs::File::open(path)?;
    // The file may have been swapped between the check and the open.
    if !file.metadata()?.is_file() {
        return Err(invalid("not a regular file"));
    }
    let mut bytes = Vec::with_capacity(metadata.len() as usize);
    file.take(max_bytes + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_large(format!("over the limit of {max_bytes} bytes")));
    }
    Ok(bytes)
}

/// Longest piece of a file's content an error quotes, in characters.
const MAX_QUOTE_CHARS: usize = 32;

/// `text` debug-quoted, cut to [`MAX_QUOTE_CHARS`] characters: an error
/// names the offending token without echoing a file's content.
pub(crate) fn quote(text: &str) -> String {
    match text.char_indices().nth(MAX_QUOTE_CHARS) {
        None => format!("{text:?}"),
        Some((end, _)) => format!("{:?}... ({} bytes)", &text[..end], text.len()),
    }
}

/// A third-party parser's message as an error may carry it: each span it
/// quotes between backticks or double quotes (serde's ``unknown variant
/// `...` `` and `string "...", expected`) cut to [`MAX_QUOTE_CHARS`]
/// characters, and the whole to `max_chars`. Parsers quote the offending
/// token in full, which would echo a file's content back to whoever sent
/// it (found by the `scene_toml` fuzz target).
///
/// A token may hold the quote character itself, so a span does not end
/// at the first quote after it opens: it ends where serde's formats end
/// a token (the last `` `, expected `` or `", expected` of the message),
/// or else at a quote followed by what cannot go on a token (the end,
/// white space or punctuation). Tokens with quotes inside were echoed
/// past their first one (found by `scene_toml` and `requests`). The work
/// is linear in the message, and stops once the output is past
/// `max_chars`.
pub(crate) fn parser_message(message: &str, max_chars: usize) -> String {
    // Where serde's formats end a token, found once: a message can be as
    // long as the request that caused it, and hold a quote per byte.
    let serde_end = |quote: char| message.rfind(&format!("{quote}, expected"));
    let serde_ends = [serde_end('`'), serde_end('"')];
    let mut out = String::new();
    let mut k = 0;
    // Quotes are ASCII, so every index below is a character boundary.
    while k < message.len() && out.len() <= 4 * max_chars {
        let Some(offset) = message[k..].find(['`', '"']) else {
            out.push_str(&message[k..]);
            break;
        };
        let open = k + offset;
        let quote = char::from(message.as_bytes()[open]);
        out.push_str(&message[k..=open]);
        let serde_end = serde_ends[usize::from(quote == '"')].filter(|&e| e > open);
        let end = serde_end.unwrap_or_else(|| span_end(message, open + 1, quote));
        let inside = &message[open + 1..end];
        match inside.char_indices().nth(MAX_QUOTE_CHARS) {
            None => out.push_str(inside),
            Some((cut, _)) => {
                out.push_str(&inside[..cut]);
                out.push_str("...");
            }
        }
        if end < message.len() {
            out.push(quote);
        }
        k = end + 1;
    }
    match out.char_indices().nth(max_chars) {
        None => out,
        Some((end, _)) => format!("{}...", &out[..end]),
    }
}

/// Where a span that `quote` opened just before `start` closes, when no
/// serde format ends it: at the first unescaped quote followed by what
/// cannot go on a token (the end, white space or punctuation), or at the
/// end of `message`.
fn span_end(message: &str, start: usize, quote: char) -> usize {
    let mut escaped = false;
    for (i, c) in message[start..].char_indices() {
        let i = start + i;
        if c == quote && !escaped {
            let next = message[i + 1..].chars().next();
            if next.is_none_or(|n| n.is_whitespace() || ",.;:)]".contains(n)) {
                return i;
            }
        }
        escaped = c == '\\' && !escaped;
    }
    message.len()
}

impl TriMesh {
    /// Reads an OBJ or PLY mesh; see [`load`] for the policy and
    /// [`LoadedMesh::dropped`] for the count of collapsed faces dropped.
    ///
    /// # Errors
    /// As [`load`].
    pub fn from_path(path: &Path) -> Result<TriMesh, MeshError> {
        load(path).map(|loaded| loaded.mesh)
    }
}

/// Collects triangles from polygons whose indices are already checked.
#[derive(Debug, Default)]
struct Triangulator {
    triangles: Vec<[u32; 3]>,
    dropped: usize,
}

impl Triangulator {
    /// Fans `polygon` (at least three checked indices) from its first corner.
    fn add_polygon(&mut self, polygon: &[u32]) {
        for k in 1..polygon.len() - 1 {
            let t = [polygon[0], polygon[k], polygon[k + 1]];
            if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
                self.dropped += 1;
            } else {
                self.triangles.push(t);
            }
        }
    }

    fn finish(self, path: &Path, vertices: Vec<Vector>) -> Result<LoadedMesh, MeshError> {
        if self.triangles.is_empty() {
            return Err(MeshError::NoTriangles {
                path: path.to_path_buf(),
                vertex_count: vertices.len(),
                dropped: self.dropped,
            });
        }
        Ok(LoadedMesh {
            mesh: TriMesh {
                vertices,
                triangles: self.triangles,
            },
            dropped: self.dropped,
        })
    }
}

/// The first non-finite coordinate of `v`, if any.
fn non_finite(v: &Vector) -> Option<crate::math::Real> {
    v.iter().copied().find(|x| !x.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_extension_and_missing_file_are_named() {
        let err = load(Path::new("shape.stl")).expect_err("stl is not read");
        assert!(
            matches!(&err, MeshError::UnknownExtension { extension, .. } if extension == "stl")
        );
        assert!(err.to_string().contains(".obj"), "{err}");
        let err = load(Path::new("/nonexistent/dir/shape.OBJ")).expect_err("missing");
        assert!(matches!(err, MeshError::Unreadable { .. }), "{err}");
        assert!(
            err.to_string().contains("/nonexistent/dir/shape.OBJ"),
            "{err}"
        );
    }

    #[test]
    fn only_regular_files_within_the_limit_are_read() {
        // A device (and, the same way, a FIFO) is refused before it is
        // opened: reading /dev/zero would never end.
        let err = read_regular_file(Path::new("/dev/zero"), 1 << 20).expect_err("a device");
        assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput, "{err}");
        assert!(err.to_string().contains("regular file"), "{err}");
        let err = load(Path::new("/dev/null.obj")).expect_err("missing");
        assert!(matches!(err, MeshError::Unreadable { .. }), "{err}");
        let dir = std::env::temp_dir().join(format!("meshless-read-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let file = dir.join("big.obj");
        std::fs::write(&file, vec![b'#'; 4096]).expect("write");
        let err = read_regular_file(&file, 1000).expect_err("over the limit");
        assert_eq!(err.kind(), std::io::ErrorKind::FileTooLarge, "{err}");
        assert!(err.to_string().contains("limit of 1000"), "{err}");
        assert_eq!(
            read_regular_file(&file, 4096).expect("at the limit").len(),
            4096
        );
        let err = read_regular_file(&dir, 1 << 20).expect_err("a directory");
        assert!(err.to_string().contains("regular file"), "{err}");
        std::fs::remove_dir_all(&dir).expect("clean up");
    }

    #[test]
    fn errors_quote_at_most_a_short_prefix_of_the_content() {
        let long = "x".repeat(100_000);
        let text = format!("v 0 0 {long}\n");
        let err =
            parse(Path::new("inline"), MeshFormat::Obj, text.as_bytes()).expect_err("not a number");
        let message = err.to_string();
        assert!(
            message.len() < 200,
            "{} bytes: {message:.300}",
            message.len()
        );
        assert!(message.contains("100000 bytes"), "{message}");
    }

    /// The quoting rule holds for what parsers say too: a quoted token
    /// is cut to a short prefix wherever it sits in the message, and the
    /// rest of the message is kept (`fuzz/regressions/scene_toml` holds
    /// the input that found it).
    #[test]
    fn parser_messages_quote_a_short_prefix() {
        let long = "w".repeat(500);
        let message = format!(
            "unknown variant `{long}`, expected `wcsph` or `dfsph`; can't use \"{long}\" here"
        );
        let cut = parser_message(&message, 10_000);
        assert!(!cut.contains(&"w".repeat(MAX_QUOTE_CHARS + 1)), "{cut}");
        assert_eq!(
            cut.matches(&"w".repeat(MAX_QUOTE_CHARS)).count(),
            2,
            "{cut}"
        );
        assert!(
            cut.contains("expected `wcsph` or `dfsph`; can't use"),
            "{cut}"
        );
        assert!(cut.ends_with("...\" here"), "{cut}");
        // An escaped quote does not close the span; the cap still holds.
        let escaped = parser_message(&format!("string \"a\\\"{long}\" here"), 10_000);
        assert!(escaped.ends_with("...\" here"), "{escaped}");
        assert_eq!(parser_message(&"z".repeat(50), 20).chars().count(), 23);
        // A token holding the quote character does not end its span
        // there (`fuzz/regressions/scene_toml/variant-with-backticks-echoed.toml`,
        // `fuzz/regressions/requests/format-with-backtick-echoed.pb`).
        for token in [
            format!("ri{}gid_body", "`".repeat(80)),
            format!("pl{long}`{long}"),
            format!("a` {long}"),
        ] {
            let message = format!("unknown variant `{token}`, expected one of `fluid`, `solid`");
            let cut = parser_message(&message, 10_000);
            assert!(cut.chars().count() < 120, "{cut}");
            assert!(
                cut.ends_with("...`, expected one of `fluid`, `solid`"),
                "{cut}"
            );
        }
        let unclosed = parser_message(&format!("string \"{long}"), 10_000);
        assert!(unclosed.len() < 60, "{unclosed}");
        // A message of quotes only, as long as a large request, comes out
        // cut (the span search once rescanned the message per quote).
        let quotes = parser_message(&"`a` ".repeat(250_000), 300);
        assert!(quotes.chars().count() <= 303, "{} chars", quotes.len());
    }

    #[test]
    fn fans_polygons_and_drops_collapsed_triangles() {
        let mut t = Triangulator::default();
        t.add_polygon(&[0, 1, 2, 3, 4]);
        assert_eq!(t.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
        t.add_polygon(&[5, 6, 6, 7]);
        assert_eq!(t.dropped, 1);
        assert_eq!(t.triangles[3], [5, 6, 7]);
    }
}
