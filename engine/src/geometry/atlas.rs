//! An atlas of conformal charts (Guo–Qin, Section 4.2, Fig. 8): the
//! parametric domain of a surface one chart cannot flatten (a closed
//! surface, a surface with holes or handles), cut into disk-topology
//! charts that meet along seams.
//!
//! **Cutting.** Charts grow from seed triangles over the triangles'
//! adjacency (a multi-source Dijkstra on the dual graph, centroid to
//! centroid), so each chart is one connected region; the first two seeds
//! are the triangles farthest apart. A region is kept when it is a disk
//! (Euler characteristic 1 with a boundary) and its overlapped patch
//! (below) maps without folding and with an area distortion under
//! [`AtlasParams::max_area_distortion`]; otherwise its triangle farthest
//! from its seed becomes a new seed and the regions grow again. That cut
//! works for any genus: a region that wraps a handle is not a disk, and
//! the farthest triangle from its seed lies across the handle, so the
//! next growth splits it. A surface that is one disk keeps the single
//! chart it had.
//!
//! **Overlap and seams (Fig. 8c).** Each chart owns its region's
//! triangles (every triangle belongs to exactly one chart, so nodes and
//! quadrature points are never duplicated on a seam) but is mapped
//! together with a band of neighbouring triangles as wide as a node's
//! support reaches on the surface ([`AtlasParams::reach`]). A node of one
//! chart whose support crosses a seam therefore has a place in the
//! neighbouring chart's plane too: [`Atlas::transfers`] gives it, with
//! the Jacobian of the transition between the two maps there (piecewise
//! linear, exact on the triangle), so that a shell's shape functions
//! reach across the seam with the node's own support.
//!
//! **One plane.** The charts are laid side by side in one parametric
//! plane, a gap wider than any support between neighbours, so that a
//! point of the plane names its chart and a quadtree over the plane
//! never lets a support cross from one chart to another directly.

use super::TriMesh;
use super::conformal::{ChartError, ConformalChart, Distortion};
use super::quadtree::{ChartDomain, Point2};
use super::topology::{HalfEdge, sorted_half_edges};
use crate::math::{Real, Vector};
use nalgebra::Matrix2;
use rayon::prelude::*;
use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};

#[cfg(test)]
mod tests;

/// Most charts a surface is cut into before the atlas gives up.
pub const MAX_CHARTS: usize = 64;

/// How an atlas is cut.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AtlasParams {
    /// How far on the surface a node's support reaches from the node:
    /// the width of the band each chart is mapped with beyond its seams.
    pub reach: Real,
    /// Largest ratio of a chart's largest to smallest area element
    /// `lambda^2` before the chart is cut smaller.
    pub max_area_distortion: Real,
}

impl AtlasParams {
    /// A band of `reach` and charts cut where their area distortion
    /// passes 16 (four times the length scale across a chart: a
    /// hemisphere's least-squares conformal map stays under it).
    pub fn new(reach: Real) -> Self {
        Self {
            reach,
            max_area_distortion: 16.0,
        }
    }
}

/// Why a surface could not be covered by an atlas.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AtlasError {
    /// One chart was refused.
    #[error(transparent)]
    Chart(#[from] ChartError),
    /// The mesh is not an orientable manifold.
    #[error(
        "the surface is not an orientable manifold ({non_manifold} edges on three or more \
         triangles, {misoriented} edges two triangles run the same way); repair the mesh"
    )]
    NotManifold {
        /// Edges on three or more triangles.
        non_manifold: usize,
        /// Edges two triangles traverse the same way.
        misoriented: usize,
    },
    /// The cut did not settle within [`MAX_CHARTS`] charts.
    #[error(
        "the surface needs more than {MAX_CHARTS} charts ({why}); coarsen the resolution (the \
         overlap band is as wide as a support) or smooth the surface"
    )]
    TooManyCharts {
        /// What the last chart refused was refused for.
        why: String,
    },
    /// The reach is not a positive length.
    #[error("the atlas's reach is {got}; use a finite length > 0")]
    Reach {
        /// The value given.
        got: Real,
    },
}

/// Where a point of one chart lies in an overlapping one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transfer {
    /// The point in the plane, in the other chart's place.
    pub at: Point2,
    /// The transition's Jacobian: a short step `d` in the other chart is
    /// `jacobian * d` in the point's own chart.
    pub jacobian: Matrix2<Real>,
}

/// Two charts that meet, and along how many edges.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Seam {
    /// The charts, the smaller index first.
    pub charts: [usize; 2],
    /// Mesh edges on the seam.
    pub edges: usize,
}

/// One chart: its own triangles, and the overlapped patch it was mapped
/// with.
#[derive(Debug, Clone)]
struct Chart {
    /// The triangles it owns, with their places in the map.
    owned: ConformalChart,
    /// Owned triangles and the band, as mapped.
    extended: ConformalChart,
    /// Each extended triangle's index in the mesh.
    extended_faces: Vec<u32>,
    /// Added to the map's coordinates to place the chart in the plane.
    offset: Point2,
    /// Where the chart's place starts along the plane's first axis (its
    /// half of the gap before it included).
    start: Real,
}

/// A surface cut into conformal charts laid in one plane (see the
/// module's documentation).
#[derive(Debug, Clone)]
pub struct Atlas {
    charts: Vec<Chart>,
    /// For each mesh triangle, the charts whose patch holds it and its
    /// index there (empty for a single chart).
    placed: Vec<Vec<(u32, u32)>>,
    /// Each mesh triangle's chart (empty for a single chart).
    face_owner: Vec<u32>,
    /// Each mesh vertex's point in the plane, in a chart owning one of its
    /// triangles.
    vertex_at: Vec<Point2>,
    /// The mesh's boundary edges with their ends' points, in the chart
    /// owning the edge's triangle.
    boundary: Vec<([u32; 2], [Point2; 2])>,
    seams: Vec<Seam>,
    lo: Point2,
    hi: Point2,
}

impl Atlas {
    /// One chart when the mesh is a disk the least-squares conformal map
    /// flattens, else the cut described in the module's documentation.
    ///
    /// # Errors
    /// [`AtlasError`]: a degenerate triangle, a mesh that is not an
    /// orientable manifold, a surface that needs more than
    /// [`MAX_CHARTS`] charts, or a reach that is not a positive length.
    pub fn new(mesh: &TriMesh, params: &AtlasParams) -> Result<Self, AtlasError> {
        if !(params.reach > 0.0 && params.reach.is_finite()) {
            return Err(AtlasError::Reach { got: params.reach });
        }
        match ConformalChart::new(mesh) {
            Ok(chart) => return Ok(Self::single(chart)),
            // A degenerate triangle, or nothing to cut.
            Err(e @ ChartError::Degenerate { .. }) => return Err(e.into()),
            Err(e) if mesh.triangles.is_empty() => return Err(e.into()),
            Err(_) => {}
        }
        let report = mesh.edge_report();
        if report.non_manifold > 0 || report.misoriented > 0 {
            return Err(AtlasError::NotManifold {
                non_manifold: report.non_manifold,
                misoriented: report.misoriented,
            });
        }
        Self::cut(mesh, params)
    }

    /// The atlas of one chart, placed where its map put it.
    pub fn single(chart: ConformalChart) -> Self {
        let (lo, hi) = chart.bounds();
        let vertex_at = chart.uv().to_vec();
        let boundary = chart
            .boundary()
            .iter()
            .map(|&[a, b]| ([a, b], [vertex_at[a as usize], vertex_at[b as usize]]))
            .collect();
        Self {
            charts: vec![Chart {
                extended_faces: Vec::new(),
                extended: chart.clone(),
                owned: chart,
                offset: [0.0, 0.0],
                start: Real::NEG_INFINITY,
            }],
            placed: Vec::new(),
            face_owner: Vec::new(),
            vertex_at,
            boundary,
            seams: Vec::new(),
            lo,
            hi,
        }
    }

    /// Whether the surface is closed: it has no rim (one chart never is,
    /// as a chart is a disk).
    pub fn is_closed(&self) -> bool {
        self.boundary.is_empty()
    }

    /// Number of charts.
    pub fn chart_count(&self) -> usize {
        self.charts.len()
    }

    /// Each chart's distortion over the triangles it owns.
    pub fn distortions(&self) -> Vec<Distortion> {
        self.charts.iter().map(|c| c.owned.distortion()).collect()
    }

    /// Where the charts meet.
    pub fn seams(&self) -> &[Seam] {
        &self.seams
    }

    /// Each mesh vertex's point in the plane.
    pub fn vertex_parameters(&self) -> &[Point2] {
        &self.vertex_at
    }

    /// The mesh's boundary edges (an open surface's rims, not seams) with
    /// their ends' points in the plane.
    pub fn boundary(&self) -> &[([u32; 2], [Point2; 2])] {
        &self.boundary
    }

    /// The box of the charts' places in the plane.
    pub fn bounds(&self) -> (Point2, Point2) {
        (self.lo, self.hi)
    }

    /// The point of the plane nearest to the surface point `p`, and its
    /// distance from `p` (see [`ConformalChart::parameter_of`]: a search
    /// over every triangle, for a user's pick).
    pub fn parameter_of(&self, p: &Vector) -> Option<(Point2, Real)> {
        self.charts
            .iter()
            .filter_map(|c| {
                c.owned
                    .parameter_of(p)
                    .map(|(u, d)| ([u[0] + c.offset[0], u[1] + c.offset[1]], d))
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// The point in the plane of the mesh triangle `face`'s point with
    /// barycentric `weights`, in the chart that owns the triangle: where
    /// a point found on the mesh (a cloud's sample projected onto the
    /// surface rebuilt from it) lies. `None` for a face the mesh has not.
    pub fn parameter_in(&self, face: usize, weights: [Real; 3]) -> Option<Point2> {
        let corners = self.face_corners(face)?;
        Some([0, 1].map(|a| (0..3).map(|k| weights[k] * corners[k][a]).sum()))
    }

    /// A mesh triangle's corners in the plane, in its own chart.
    fn face_corners(&self, face: usize) -> Option<[Point2; 3]> {
        if self.face_owner.is_empty() {
            let chart = &self.charts[0].owned;
            let tri = chart.triangles().get(face)?;
            return Some(tri.map(|v| self.vertex_at[v as usize]));
        }
        let c = *self.face_owner.get(face)?;
        let &(_, t) = self.placed[face].iter().find(|(o, _)| *o == c)?;
        let chart = &self.charts[c as usize];
        Some(
            corners(&chart.extended, t as usize)
                .map(|q| [q[0] + chart.offset[0], q[1] + chart.offset[1]]),
        )
    }

    /// The surface's point at `u` (see [`ConformalChart::surface_point`]).
    pub fn surface_point(&self, u: Point2) -> Vector {
        let (chart, local) = self.local(u);
        chart.owned.surface_point(local)
    }

    /// Where the point `u` also lies in the other charts whose patches
    /// hold it, with the transitions' Jacobians (empty for one chart, or
    /// for a point outside its chart's patch).
    pub fn transfers(&self, u: Point2) -> Vec<Transfer> {
        if self.charts.len() < 2 {
            return Vec::new();
        }
        let index = self.chart_of(u);
        let (chart, local) = self.local(u);
        let Some((t, w)) = chart.extended.locate(local) else {
            return Vec::new();
        };
        let face = chart.extended_faces[t] as usize;
        let own = corners(&chart.extended, t);
        let mut out = Vec::new();
        for &(other, there) in &self.placed[face] {
            if other as usize == index {
                continue;
            }
            let c = &self.charts[other as usize];
            let q = corners(&c.extended, there as usize);
            let at = [
                c.offset[0] + (0..3).map(|k| w[k] * q[k][0]).sum::<Real>(),
                c.offset[1] + (0..3).map(|k| w[k] * q[k][1]).sum::<Real>(),
            ];
            let Some(jacobian) = transition(&own, &q) else {
                continue;
            };
            out.push(Transfer { at, jacobian });
        }
        out
    }

    /// The chart whose place holds `u` (the nearest for a point in a gap).
    pub fn chart_of(&self, u: Point2) -> usize {
        self.charts
            .partition_point(|c| c.start <= u[0])
            .saturating_sub(1)
    }

    fn local(&self, u: Point2) -> (&Chart, Point2) {
        let chart = &self.charts[self.chart_of(u)];
        (chart, [u[0] - chart.offset[0], u[1] - chart.offset[1]])
    }

    /// Cuts a surface that is not one disk (see the module's
    /// documentation).
    fn cut(mesh: &TriMesh, params: &AtlasParams) -> Result<Self, AtlasError> {
        let half_edges = sorted_half_edges(mesh);
        let dual = Dual::new(mesh, &half_edges);
        let rings = vertex_rings(mesh);
        let first = dual.farthest(&[0]);
        let mut seeds = vec![first, dual.farthest(&[first])];
        if seeds[0] == seeds[1] {
            seeds.pop();
        }
        // Charts accepted in the last round, by their faces: a region the
        // new seeds did not reach is the same region, mapped the same way.
        let mut kept: HashMap<Vec<u32>, Chart> = HashMap::new();
        loop {
            let (owner, distance) = dual.grow(&seeds);
            // A piece of the mesh no seed reached gets its own seed.
            if let Some(lost) = owner.iter().position(|&o| o == u32::MAX) {
                if seeds.len() >= MAX_CHARTS {
                    return Err(AtlasError::TooManyCharts {
                        why: "the mesh is in more pieces than that".into(),
                    });
                }
                seeds.push(lost as u32);
                continue;
            }
            let mut regions: Vec<Vec<u32>> = vec![Vec::new(); seeds.len()];
            for (f, &o) in owner.iter().enumerate() {
                regions[o as usize].push(f as u32);
            }
            // Each region's map is its own sparse solve: they run side by
            // side, and are read back in region order (the same atlas on
            // any number of threads).
            let cached: Vec<Option<Chart>> = regions.iter().map(|f| kept.remove(f)).collect();
            kept.clear();
            let mapped: Vec<Result<Chart, String>> = regions
                .par_iter()
                .zip(cached)
                .map(|(faces, cached)| match cached {
                    Some(chart) => Ok(chart),
                    None => chart_of(mesh, &rings, faces, &owner, params),
                })
                .collect();
            let mut charts = Vec::with_capacity(regions.len());
            let mut more = Vec::new();
            let mut why = String::new();
            for (r, mapped) in mapped.into_iter().enumerate() {
                let faces = &regions[r];
                match mapped {
                    Ok(chart) => charts.push((r, chart)),
                    Err(e) => {
                        why = e;
                        let farthest = faces
                            .iter()
                            .copied()
                            .max_by(|&a, &b| distance[a as usize].total_cmp(&distance[b as usize]));
                        more.extend(farthest.filter(|f| !seeds.contains(f)));
                    }
                }
            }
            if more.is_empty() && charts.len() == regions.len() {
                let charts = charts.into_iter().map(|(_, chart)| chart).collect();
                return Ok(Self::assemble(mesh, &half_edges, charts, &owner, params));
            }
            if more.is_empty() || seeds.len() + more.len() > MAX_CHARTS {
                return Err(AtlasError::TooManyCharts { why });
            }
            for (r, chart) in charts {
                kept.insert(std::mem::take(&mut regions[r]), chart);
            }
            seeds.extend(more);
        }
    }

    /// Lays the charts in the plane and indexes them.
    fn assemble(
        mesh: &TriMesh,
        half_edges: &[HalfEdge],
        mut charts: Vec<Chart>,
        owner: &[u32],
        params: &AtlasParams,
    ) -> Self {
        let lambda_min = charts
            .iter()
            .flat_map(|c| c.extended.lambda_vertices().iter().copied())
            .fold(Real::INFINITY, Real::min)
            .max(Real::MIN_POSITIVE);
        let gap = 4.0 * params.reach / lambda_min;
        let mut x = 0.0;
        let mut height: Real = 0.0;
        for chart in &mut charts {
            let (lo, hi) = chart.extended.bounds();
            chart.start = x - 0.5 * gap;
            chart.offset = [x - lo[0], -lo[1]];
            x += hi[0] - lo[0] + gap;
            height = height.max(hi[1] - lo[1]);
        }
        let mut placed = vec![Vec::new(); mesh.triangles.len()];
        for (c, chart) in charts.iter().enumerate() {
            for (t, &f) in chart.extended_faces.iter().enumerate() {
                placed[f as usize].push((c as u32, t as u32));
            }
        }
        let mut atlas = Self {
            charts,
            placed,
            face_owner: owner.to_vec(),
            vertex_at: Vec::new(),
            boundary: Vec::new(),
            seams: Vec::new(),
            lo: [-0.5 * gap, 0.0],
            hi: [x - 0.5 * gap, height],
        };
        // Every face is placed in its owner's patch (the band's patch
        // lists the region's own faces first).
        let place = |face: usize| atlas.face_corners(face).unwrap_or_default();
        let mut vertex_at = vec![[0.0; 2]; mesh.vertices.len()];
        for (f, tri) in mesh.triangles.iter().enumerate() {
            let at = place(f);
            for (k, &v) in tri.iter().enumerate() {
                vertex_at[v as usize] = at[k];
            }
        }
        let mut boundary = Vec::new();
        let mut seams: HashMap<[usize; 2], usize> = HashMap::new();
        for uses in half_edges.chunk_by(|a, b| a.key == b.key) {
            match uses {
                [h] => {
                    let (f, k) = (h.triangle as usize, h.corner as usize);
                    let tri = mesh.triangles[f];
                    let at = place(f);
                    boundary.push(([tri[k], tri[(k + 1) % 3]], [at[k], at[(k + 1) % 3]]));
                }
                [h, i] if owner[h.triangle as usize] != owner[i.triangle as usize] => {
                    let (c, d) = (
                        owner[h.triangle as usize] as usize,
                        owner[i.triangle as usize] as usize,
                    );
                    *seams.entry([c.min(d), c.max(d)]).or_default() += 1;
                }
                _ => {}
            }
        }
        boundary.sort_unstable_by_key(|(e, _)| *e);
        let mut seams: Vec<Seam> = seams
            .into_iter()
            .map(|(charts, edges)| Seam { charts, edges })
            .collect();
        seams.sort_unstable_by_key(|s| s.charts);
        atlas.vertex_at = vertex_at;
        atlas.boundary = boundary;
        atlas.seams = seams;
        atlas
    }
}

/// The chart's domain is the union of the charts' own triangles, each in
/// its place; a point of a gap belongs to the nearer chart.
impl ChartDomain for Atlas {
    fn distance(&self, u: Point2) -> Real {
        let (chart, local) = self.local(u);
        chart.owned.distance(local)
    }

    fn lambda(&self, u: Point2) -> Real {
        let (chart, local) = self.local(u);
        chart.owned.lambda(local)
    }

    fn contains(&self, u: Point2) -> bool {
        let (chart, local) = self.local(u);
        chart.owned.contains(local)
    }
}

/// The chart of `faces` (a region of `mesh`), mapped with its band, or
/// why it cannot be one.
fn chart_of(
    mesh: &TriMesh,
    rings: &[Vec<u32>],
    faces: &[u32],
    owner: &[u32],
    params: &AtlasParams,
) -> Result<Chart, String> {
    let (region, _) = patch(mesh, faces);
    let report = region.edge_report();
    let euler = region.vertices.len() as i64 - report.edges as i64 + region.triangles.len() as i64;
    if euler != 1 || report.boundary == 0 {
        return Err(format!(
            "a region is not a disk (Euler characteristic {euler})"
        ));
    }
    let region_of = owner[faces[0] as usize];
    let extended_faces = band(mesh, rings, faces, region_of, owner, params.reach);
    let (extended_mesh, _) = patch(mesh, &extended_faces);
    let extended = ConformalChart::new(&extended_mesh).map_err(|e| e.to_string())?;
    let distortion = extended.distortion();
    let ratio = distortion.area_max / distortion.area_min;
    if ratio > params.max_area_distortion {
        return Err(format!(
            "a chart's area distortion is {ratio:.1}, over {}",
            params.max_area_distortion
        ));
    }
    // The band's patch lists the region's triangles first and numbers
    // vertices in the order it meets them, so the region's vertices are
    // the band's first ones, in the same order.
    let owned_uv = extended.uv()[..region.vertices.len()].to_vec();
    let owned = ConformalChart::with_map(&region, owned_uv).map_err(|e| e.to_string())?;
    Ok(Chart {
        owned,
        extended,
        extended_faces,
        offset: [0.0, 0.0],
        start: 0.0,
    })
}

/// The region's faces, then those whose every corner lies within
/// `reach` (along the mesh's edges) of the region.
fn band(
    mesh: &TriMesh,
    rings: &[Vec<u32>],
    faces: &[u32],
    region: u32,
    owner: &[u32],
    reach: Real,
) -> Vec<u32> {
    let mut distance = vec![Real::INFINITY; mesh.vertices.len()];
    let mut heap = BinaryHeap::new();
    for &f in faces {
        for v in mesh.triangles[f as usize] {
            if distance[v as usize] > 0.0 {
                distance[v as usize] = 0.0;
                heap.push((Reverse(Ordered(0.0)), v));
            }
        }
    }
    while let Some((Reverse(Ordered(d)), v)) = heap.pop() {
        if d > distance[v as usize] {
            continue;
        }
        for &w in &rings[v as usize] {
            let next = d + (mesh.vertices[w as usize] - mesh.vertices[v as usize]).norm();
            if next <= reach && next < distance[w as usize] {
                distance[w as usize] = next;
                heap.push((Reverse(Ordered(next)), w));
            }
        }
    }
    let mut out = faces.to_vec();
    out.extend(
        mesh.triangles
            .iter()
            .enumerate()
            .filter(|(f, tri)| {
                owner[*f] != region && tri.iter().all(|&v| distance[v as usize] <= reach)
            })
            .map(|(f, _)| f as u32),
    );
    out
}

/// Each vertex's neighbours along the mesh's edges.
fn vertex_rings(mesh: &TriMesh) -> Vec<Vec<u32>> {
    let mut rings = vec![Vec::new(); mesh.vertices.len()];
    for tri in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            rings[a as usize].push(b);
            rings[b as usize].push(a);
        }
    }
    for ring in &mut rings {
        ring.sort_unstable();
        ring.dedup();
    }
    rings
}

/// The sub-mesh of `faces` (in that order) and each of its vertices'
/// index in `mesh`.
fn patch(mesh: &TriMesh, faces: &[u32]) -> (TriMesh, Vec<u32>) {
    let mut index: HashMap<u32, u32> = HashMap::new();
    let mut vertices = Vec::new();
    let triangles = faces
        .iter()
        .map(|&f| {
            mesh.triangles[f as usize].map(|v| {
                *index.entry(v).or_insert_with(|| {
                    vertices.push(v);
                    vertices.len() as u32 - 1
                })
            })
        })
        .collect();
    (
        TriMesh {
            vertices: vertices
                .iter()
                .map(|&v| mesh.vertices[v as usize])
                .collect(),
            triangles,
        },
        vertices,
    )
}

/// A triangle's corners in a chart's map.
fn corners(chart: &ConformalChart, t: usize) -> [Point2; 3] {
    chart.triangles()[t].map(|k| chart.uv()[k as usize])
}

/// The linear map taking the triangle `there` onto `here`, as the
/// Jacobian `d here / d there`, or `None` for a flat one.
fn transition(here: &[Point2; 3], there: &[Point2; 3]) -> Option<Matrix2<Real>> {
    let edges = |q: &[Point2; 3]| {
        Matrix2::new(
            q[1][0] - q[0][0],
            q[2][0] - q[0][0],
            q[1][1] - q[0][1],
            q[2][1] - q[0][1],
        )
    };
    Some(edges(here) * edges(there).try_inverse()?)
}

/// A distance that orders (never NaN here: lengths of finite edges).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Ordered(Real);

impl Eq for Ordered {}

impl PartialOrd for Ordered {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Ordered {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

/// Triangles as a graph: neighbours across edges, centroid to centroid.
struct Dual {
    neighbours: Vec<Vec<(u32, Real)>>,
}

impl Dual {
    /// The triangles of `mesh` joined across the edges two of them share
    /// (`half_edges` sorted by edge, as `sorted_half_edges` gives them).
    fn new(mesh: &TriMesh, half_edges: &[HalfEdge]) -> Self {
        let centroid = |f: u32| -> Vector { mesh.corners(f as usize).iter().sum::<Vector>() / 3.0 };
        let mut neighbours = vec![Vec::new(); mesh.triangles.len()];
        for uses in half_edges.chunk_by(|a, b| a.key == b.key) {
            if let [h, i] = uses {
                let (f, g) = (h.triangle, i.triangle);
                let d = (centroid(f) - centroid(g)).norm();
                neighbours[f as usize].push((g, d));
                neighbours[g as usize].push((f, d));
            }
        }
        Self { neighbours }
    }

    /// Each triangle's nearest seed (`u32::MAX` where none reaches) and
    /// its distance from it.
    fn grow(&self, seeds: &[u32]) -> (Vec<u32>, Vec<Real>) {
        let n = self.neighbours.len();
        let mut owner = vec![u32::MAX; n];
        let mut distance = vec![Real::INFINITY; n];
        let mut heap = BinaryHeap::new();
        for (s, &f) in seeds.iter().enumerate() {
            owner[f as usize] = s as u32;
            distance[f as usize] = 0.0;
            heap.push((Reverse(Ordered(0.0)), f));
        }
        while let Some((Reverse(Ordered(d)), f)) = heap.pop() {
            if d > distance[f as usize] {
                continue;
            }
            for &(g, step) in &self.neighbours[f as usize] {
                let next = d + step;
                if next < distance[g as usize] {
                    distance[g as usize] = next;
                    owner[g as usize] = owner[f as usize];
                    heap.push((Reverse(Ordered(next)), g));
                }
            }
        }
        (owner, distance)
    }

    /// The triangle farthest from `from` among those it reaches.
    fn farthest(&self, from: &[u32]) -> u32 {
        let (_, distance) = self.grow(from);
        (0..distance.len())
            .filter(|&f| distance[f].is_finite())
            .max_by(|&a, &b| distance[a].total_cmp(&distance[b]))
            .unwrap_or(0) as u32
    }
}
