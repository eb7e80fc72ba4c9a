//! The crack surfaces as a frame shows them: each crack's two faces, each
//! carried by the material on its own side, so a crack that opens shows
//! a gap and each fragment's side of it moves with that fragment.
//!
//! A crack lives in reference coordinates. For each face (`s = +1` and
//! `-1` along the crack's normal at a vertex), the vertex `X` moves by
//! the displacement of the material just off that face, at `P = X + s
//! (spacing / 4) n`: the poly6-weighted (Shepard) mean of the
//! displacements of the particles within the support of `P` that see it
//! through no crack (the visibility criterion, so the other face's
//! material never pulls it). A vertex with no such particle (outside the
//! body, beyond a fragment's edge) keeps the displacement of the nearest
//! particle (in 2D, where a crack is a line extruded along `z`, the
//! probe is taken in the particles' plane). Face winding is chosen so each face's normal points out of
//! the material behind it, into the crack.

use super::Fracture;
use crate::approx::KernelKind;
use crate::geometry::{TriMesh, vertex_normals};
use crate::math::{Real, Vector};
use crate::neighbors::{CandidateSearch, KdTree};

/// A fracturing solid's crack faces, deformed, with unit vertex normals;
/// `None` before any crack.
pub(in crate::solid) fn crack_faces(
    fracture: &Fracture,
    rest: &[Vector],
    positions: &[Vector],
    spacing: Real,
    support: Real,
) -> Option<(TriMesh, Vec<Vector>)> {
    if fracture.cracks.is_empty() {
        return None;
    }
    let search = fracture.search.or_built(support, rest);
    let search = &*search;
    let mut mesh = TriMesh {
        vertices: Vec::new(),
        triangles: Vec::new(),
    };
    let offset = 0.25 * spacing;
    for crack in &fracture.cracks {
        let reference = crack.vertices();
        let normals = vertex_normals(crack.triangles(), reference);
        for side in [1.0, -1.0] {
            let first = mesh.vertices.len() as u32;
            for (x, n) in reference.iter().zip(&normals) {
                let mut probe = x + n * (side * offset);
                if crack.dim() == 2 {
                    // The 2D crack is extruded along z; its material lies
                    // in the plane z = 0.
                    probe.z = 0.0;
                }
                let u = displacement(fracture, search, rest, positions, &probe, support)
                    .or_else(|| nearest_displacement(search, rest, positions, x))
                    .unwrap_or_else(Vector::zeros);
                mesh.vertices.push(x + u);
            }
            // The `+` face's material lies along `+n`: its outward normal
            // is `-n`, so its triangles turn the other way.
            mesh.triangles.extend(crack.triangles().iter().map(|t| {
                let [a, b, c] = t.map(|v| v + first);
                if side > 0.0 { [a, c, b] } else { [a, b, c] }
            }));
        }
    }
    let normals = vertex_normals(&mesh.triangles, &mesh.vertices);
    Some((mesh, normals))
}

/// The Shepard mean displacement at `probe` of the particles that see it
/// through no crack, or `None` when none does.
fn displacement(
    fracture: &Fracture,
    search: &KdTree,
    rest: &[Vector],
    positions: &[Vector],
    probe: &Vector,
    support: Real,
) -> Option<Vector> {
    let (mut sum, mut total) = (Vector::zeros(), 0.0);
    search.for_each_candidate(probe, |j| {
        let j = j as usize;
        let q = (rest[j] - probe).norm() / support;
        if q >= 1.0 {
            return;
        }
        if fracture
            .cracks
            .iter()
            .any(|c| c.crossing(probe, &rest[j]).is_some())
        {
            return;
        }
        let w = KernelKind::Poly6.profile(q)[0];
        sum += (positions[j] - rest[j]) * w;
        total += w;
    });
    (total > 0.0).then(|| sum / total)
}

fn nearest_displacement(
    search: &KdTree,
    rest: &[Vector],
    positions: &[Vector],
    x: &Vector,
) -> Option<Vector> {
    let mut best: Option<(Real, usize)> = None;
    search.for_each_candidate(x, |j| {
        let d = (rest[j as usize] - x).norm();
        if best.is_none_or(|(b, _)| d < b) {
            best = Some((d, j as usize));
        }
    });
    best.map(|(_, j)| positions[j] - rest[j])
}
