//! Wavefront OBJ, the subset that describes a surface: `v x y z` vertices
//! and `f` polygons whose corners are `i`, `i/t`, `i//n` or `i/t/n`
//! (1-based; negative counts back from the last vertex read so far).
//! Every other statement (`vt`, `vn`, `o`, `g`, `s`, `usemtl`, `mtllib`,
//! `l`, `p`, ...) is ignored.
//!
//! Written here rather than taken from `tobj`: that crate's errors carry no
//! line number, and it re-indexes each `o`/`g` group on its own, which
//! splits the vertices groups share and would make a closed mesh look open.

use super::{LoadedMesh, Triangulator, non_finite, quote};
use crate::geometry::MeshError;
use crate::math::{Real, Vector};
use std::path::Path;

/// A face as read: its line and its corners (0-based, not yet range-checked).
struct Face {
    line: usize,
    corners: std::ops::Range<usize>,
}

pub(super) fn parse(path: &Path, text: &str) -> Result<LoadedMesh, MeshError> {
    let parse_error = |line: usize, message: String| MeshError::Parse {
        path: path.to_path_buf(),
        location: format!("line {line}"),
        message,
    };
    let mut vertices = Vec::new();
    let mut faces = Vec::new();
    let mut corners: Vec<i64> = Vec::new();
    for (n, raw) in text.lines().enumerate() {
        let line = n + 1;
        let content = raw.split('#').next().unwrap_or_default();
        let mut tokens = content.split_whitespace();
        match tokens.next() {
            Some("v") => {
                let mut xyz = [0.0; 3];
                for (a, value) in xyz.iter_mut().enumerate() {
                    let token = tokens.next().ok_or_else(|| {
                        parse_error(line, "a vertex needs three coordinates `v x y z`".into())
                    })?;
                    *value = token.parse::<Real>().map_err(|_| {
                        parse_error(
                            line,
                            format!("coordinate {a} {} is not a number", quote(token)),
                        )
                    })?;
                }
                let v = Vector::from(xyz);
                if let Some(value) = non_finite(&v) {
                    return Err(MeshError::NonFinite {
                        path: path.to_path_buf(),
                        location: format!("line {line}"),
                        value,
                    });
                }
                vertices.push(v);
            }
            Some("f") => {
                let start = corners.len();
                for token in tokens {
                    let index = token.split('/').next().unwrap_or_default();
                    let index: i64 = index.parse().map_err(|_| {
                        parse_error(
                            line,
                            format!(
                                "face corner {} is not `i`, `i/t`, `i//n` or `i/t/n`",
                                quote(token)
                            ),
                        )
                    })?;
                    // 1-based; negative is relative to the vertices so far.
                    let resolved = match index {
                        0 => {
                            return Err(parse_error(
                                line,
                                "vertex index 0: OBJ counts from 1".into(),
                            ));
                        }
                        i if i > 0 => i - 1,
                        i => vertices.len() as i64 + i,
                    };
                    if resolved < 0 {
                        return Err(MeshError::IndexOutOfRange {
                            path: path.to_path_buf(),
                            location: format!("line {line}"),
                            index,
                            vertex_count: vertices.len(),
                        });
                    }
                    corners.push(resolved);
                }
                if corners.len() - start < 3 {
                    return Err(parse_error(
                        line,
                        format!(
                            "a face needs at least three corners, found {}",
                            corners.len() - start
                        ),
                    ));
                }
                faces.push(Face {
                    line,
                    corners: start..corners.len(),
                });
            }
            _ => {}
        }
    }
    // Positive indices may point forward, so ranges are checked at the end.
    let mut triangulator = Triangulator::default();
    let mut polygon = Vec::new();
    for face in &faces {
        polygon.clear();
        for &index in &corners[face.corners.clone()] {
            match u32::try_from(index) {
                Ok(i) if (i as usize) < vertices.len() => polygon.push(i),
                _ => {
                    return Err(MeshError::IndexOutOfRange {
                        path: path.to_path_buf(),
                        location: format!("line {}", face.line),
                        index: index + 1,
                        vertex_count: vertices.len(),
                    });
                }
            }
        }
        triangulator.add_polygon(&polygon);
    }
    triangulator.finish(path, vertices)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> Result<LoadedMesh, MeshError> {
        parse(Path::new("test.obj"), text)
    }

    /// A unit square as one quad, with texture and normal indices, a
    /// comment, groups and negative indices: two triangles, area 1.
    #[test]
    fn reads_index_forms_and_fans_quads() {
        let text = "# square\nmtllib x.mtl\no sq\nv 0 0 0\nv 1 0 0\nv 1 1 0 # c\nv 0 1 0\n\
                    vt 0 0\nvn 0 0 1\ng a\nf 1/1/1 2//1 -2/1 -1\n";
        let loaded = read(text).expect("valid obj");
        assert_eq!(loaded.mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(loaded.dropped, 0);
        assert!((loaded.mesh.area() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn errors_name_the_line() {
        let cases = [
            ("v 0 0\n", "line 1", "three coordinates"),
            ("v 0 0 0\nv 1 x 0\n", "line 2", "not a number"),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n",
                "line 4",
                "at least three",
            ),
            ("v 0 0 0\nf 0 1 2\n", "line 2", "counts from 1"),
            ("v 0 0 0\nv 1 0 0\nf a/1 2 3\n", "line 3", "not `i`"),
        ];
        for (text, line, what) in cases {
            let err = read(text).expect_err(text);
            let message = err.to_string();
            assert!(matches!(err, MeshError::Parse { .. }), "{message}");
            assert!(
                message.contains(line) && message.contains(what),
                "{message}"
            );
        }
    }

    #[test]
    fn out_of_range_nan_and_empty_are_rejected() {
        let err = read("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n").expect_err("4 > 3");
        assert!(
            matches!(
                err,
                MeshError::IndexOutOfRange {
                    index: 4,
                    vertex_count: 3,
                    ..
                }
            ),
            "{err}"
        );
        let err = read("v 0 0 0\nf -1 -2 -3\n").expect_err("before the first vertex");
        assert!(
            matches!(err, MeshError::IndexOutOfRange { index: -2, .. }),
            "{err}"
        );
        let err = read("v 0 0 0\nv nan 0 0\n").expect_err("nan");
        assert!(err.to_string().contains("line 2"), "{err}");
        assert!(matches!(err, MeshError::NonFinite { .. }), "{err}");
        let err = read("v 0 0 0\nv 1 0 0\nf 1 2 2\n").expect_err("only a collapsed face");
        assert!(matches!(
            err,
            MeshError::NoTriangles {
                dropped: 1,
                vertex_count: 2,
                ..
            }
        ));
    }
}
