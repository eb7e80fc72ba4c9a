//! The mesh readers (`meshless_engine::geometry::read`), which read bytes
//! a client sends inline in a scene or an obstacle.

use crate::echo::assert_quotes_briefly;
use meshless_engine::geometry::LoadedMesh;
use meshless_engine::geometry::read::{MeshFormat, parse};
use std::path::Path;

/// OBJ bytes through the reader; asserts the properties
/// of the private `read`.
pub fn mesh_obj(data: &[u8]) {
    read(MeshFormat::Obj, data);
}

/// PLY bytes (ASCII or binary) through the reader; as [`mesh_obj`].
pub fn mesh_ply(data: &[u8]) {
    read(MeshFormat::Ply, data);
}

/// Reads `data` as `format`. A mesh the reader accepts has at least one
/// triangle, only finite vertices, indices that name existing vertices,
/// and no triangle that repeats a corner (those are dropped and counted);
/// an error quotes briefly.
///
/// # Panics
/// When a property fails.
fn read(format: MeshFormat, data: &[u8]) {
    let LoadedMesh { mesh, dropped: _ } = match parse(Path::new("fuzz"), format, data) {
        Ok(loaded) => loaded,
        Err(e) => return assert_quotes_briefly(data, &e.to_string()),
    };
    assert!(
        !mesh.triangles.is_empty(),
        "an accepted mesh has no triangle"
    );
    if let Some((i, v)) = mesh
        .vertices
        .iter()
        .enumerate()
        .find(|(_, v)| !v.iter().all(|c| c.is_finite()))
    {
        panic!("vertex {i} of an accepted mesh is {v:?}");
    }
    let n = mesh.vertices.len();
    for (t, triangle) in mesh.triangles.iter().enumerate() {
        let [a, b, c] = *triangle;
        assert!(
            triangle.iter().all(|&i| (i as usize) < n),
            "triangle {t} is {triangle:?}, but there are {n} vertices"
        );
        assert!(
            a != b && b != c && c != a,
            "triangle {t} is {triangle:?}: a collapsed triangle was kept"
        );
    }
}
