//! Crack surfaces in material coordinates, as triangulated fronts.
//!
//! A crack is a surface that grows from its front (tutorial Section 7.3,
//! after Pauly et al. 2005): each step the front's nodes advance, and the
//! strip they sweep is added to the surface as triangles. Triangles rather
//! than Pauly's surfels because the two questions the solid asks of a
//! crack are exact on them: whether the segment between two particles
//! crosses it (the visibility criterion, Belytschko et al. 1994) and how
//! far the crossing lies from the front (Eq. 70's `d_s`); and because a
//! frame's crack mesh is then the surface itself, with no splatting.
//!
//! In 2D the solid lies in the plane `z = 0` and a crack is a line: it is
//! stored as that line extruded along `z` by `depth` either way, so that
//! the same segment–triangle test serves both dimensions, and each front
//! node (a tip of the line) owns the two vertices of its extruded edge.
//! In 3D a crack starts as a small disc whose rim is a closed front.
//!
//! Everything here is in reference coordinates: the weights that cracks
//! change are evaluated there (Lagrangian kernels), so a crack never
//! moves with the material; the frames deform it with the particles.

use super::params::Notch;
use crate::math::{Real, Vector};

/// Nodes on the rim of a crack that starts in 3D.
const RIM_NODES: usize = 6;

/// Most nodes on the rim of a 3D notch: a bound on its geometry whatever
/// radius a scene names (the solid's vertex bound checks the rest).
const MAX_RIM_NODES: usize = 1 << 16;

/// One point of a crack front.
#[derive(Debug, Clone, PartialEq)]
pub struct FrontNode {
    /// Where the front is, reference coordinates (in 2D on `z = 0`).
    pub at: Vector,
    /// Unit direction it advances in, in the crack's plane.
    pub heading: Vector,
    /// Its vertices: in 3D the same one twice, in 2D the two ends of the
    /// extruded tip.
    tips: [u32; 2],
    /// Whether it may still advance: false once it left the body or met
    /// another crack.
    pub active: bool,
}

/// A crack surface and its front.
#[derive(Debug, Clone, PartialEq)]
pub struct Crack {
    dim: usize,
    /// Half the extrusion along `z` of a 2D crack; unused in 3D.
    depth: Real,
    vertices: Vec<Vector>,
    triangles: Vec<[u32; 3]>,
    /// In order along the front; in 3D a closed loop.
    front: Vec<FrontNode>,
    /// Bounding box of the vertices.
    lo: Vector,
    hi: Vector,
}

/// Where a segment crosses a crack.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crossing {
    /// The crossing point, reference coordinates.
    pub at: Vector,
    /// Its distance to the nearest point of the front (`d_s` in Eq. 70).
    pub to_front: Real,
}

impl FrontNode {
    /// A front node at `at` advancing along `heading`, whose vertices in
    /// its crack are `tips` (see [`Self::tips`]).
    pub fn new(at: Vector, heading: Vector, tips: [u32; 2], active: bool) -> Self {
        Self {
            at,
            heading,
            tips,
            active,
        }
    }

    /// Its vertices: in 3D the same one twice, in 2D the two ends of the
    /// extruded tip.
    pub fn tips(&self) -> [u32; 2] {
        self.tips
    }
}

impl Crack {
    /// A crack from its parts, as [`Self::vertices`], [`Self::triangles`]
    /// and [`Self::front`] give them (a snapshot's). Its dimension is read
    /// from its front: a 2D tip has two vertices, a 3D node one (the
    /// solid it is put back into checks that it agrees).
    ///
    /// # Errors
    /// A message naming what does not hold: a value that is not finite, a
    /// vertex index out of range, an empty front or surface.
    pub fn from_parts(
        vertices: Vec<Vector>,
        triangles: Vec<[u32; 3]>,
        front: Vec<FrontNode>,
    ) -> Result<Self, String> {
        if vertices.is_empty() || triangles.is_empty() || front.is_empty() {
            return Err("a crack needs vertices, triangles and a front".into());
        }
        let dim = if front[0].tips[0] == front[0].tips[1] {
            3
        } else {
            2
        };
        if front.iter().any(|f| (f.tips[0] == f.tips[1]) != (dim == 3)) {
            return Err("a front mixes 2D tips and 3D nodes".into());
        }
        let finite = |v: &Vector| v.iter().all(|c| c.is_finite());
        if let Some(k) = vertices.iter().position(|v| !finite(v)) {
            return Err(format!("vertex {k} is not finite"));
        }
        let n = vertices.len() as u64;
        if let Some(k) = triangles
            .iter()
            .position(|t| t.iter().any(|&v| u64::from(v) >= n))
        {
            return Err(format!(
                "triangle {k} names a vertex past the {n} there are"
            ));
        }
        for (k, node) in front.iter().enumerate() {
            if !finite(&node.at) || !finite(&node.heading) {
                return Err(format!("front node {k} is not finite"));
            }
            if node.tips.iter().any(|&v| u64::from(v) >= n) {
                return Err(format!(
                    "front node {k} names a vertex past the {n} there are"
                ));
            }
        }
        let depth = vertices[0].z.abs();
        let lo = vertices.iter().fold(vertices[0], |lo, v| lo.inf(v));
        let hi = vertices.iter().fold(vertices[0], |hi, v| hi.sup(v));
        Ok(Self {
            dim,
            depth,
            vertices,
            triangles,
            front,
            lo,
            hi,
        })
    }

    /// The dimension of the solid it cracks.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// A crack started at `center` with unit plane normal `normal`: in 2D
    /// a segment of half-length `radius` across the normal, in 3D a disc
    /// of that radius. `depth` is the 2D extrusion's half-height (any
    /// length above the particles' `z` spread; the solid passes its
    /// support radius).
    pub fn start(dim: usize, center: Vector, normal: Vector, radius: Real, depth: Real) -> Self {
        Self::disc(dim, center, normal, radius, depth, RIM_NODES)
    }

    /// A crack the solid is built with ([`Notch`]): as [`Self::start`]
    /// makes one, its 3D rim with nodes at most `spacing` apart, so that
    /// the front is as fine as the particles it will cut.
    pub fn notch(dim: usize, notch: &Notch, spacing: Real, depth: Real) -> Self {
        let mut normal = notch.normal;
        if dim == 2 {
            normal.z = 0.0;
        }
        Self::disc(
            dim,
            notch.center,
            normal.normalize(),
            notch.radius,
            depth,
            rim_nodes(notch, spacing),
        )
    }

    /// How many vertices [`Self::notch`] makes of `notch`, without making
    /// them: what a scene checks against the solid's bound.
    pub fn notch_vertices(dim: usize, notch: &Notch, spacing: Real) -> usize {
        if dim == 2 {
            4
        } else {
            rim_nodes(notch, spacing) + 1
        }
    }

    fn disc(
        dim: usize,
        center: Vector,
        normal: Vector,
        radius: Real,
        depth: Real,
        rim: usize,
    ) -> Self {
        let mut crack = Self::empty(dim, depth, center);
        if dim == 2 {
            let tangent = Vector::new(-normal.y, normal.x, 0.0).normalize();
            for heading in [-tangent, tangent] {
                let at = center + heading * radius;
                let tips = crack.tip_vertices(at);
                crack.front.push(FrontNode {
                    at,
                    heading,
                    tips,
                    active: true,
                });
            }
            let [a, b] = [crack.front[0].tips, crack.front[1].tips];
            crack.quad(a, b);
        } else {
            crack.rim(center, plane_axes(&normal), radius, rim);
        }
        crack
    }

    /// A crack with no geometry yet, its box at `center`.
    fn empty(dim: usize, depth: Real, center: Vector) -> Self {
        Self {
            dim,
            depth,
            vertices: Vec::new(),
            triangles: Vec::new(),
            front: Vec::new(),
            lo: center,
            hi: center,
        }
    }

    /// A 3D disc's rim of `rim` nodes at `radius` from `center`, the first
    /// along `u`, then turning towards `v`, fanned from a middle vertex.
    fn rim(&mut self, center: Vector, (u, v): (Vector, Vector), radius: Real, rim: usize) {
        let middle = self.vertex(center);
        for k in 0..rim {
            let angle = std::f64::consts::TAU * k as Real / rim as Real;
            let heading = u * angle.cos() + v * angle.sin();
            let at = center + heading * radius;
            let id = self.vertex(at);
            self.front.push(FrontNode {
                at,
                heading,
                tips: [id, id],
                active: true,
            });
        }
        let first = self.front.len() - rim;
        for k in 0..rim {
            let a = self.front[first + k].tips[0];
            let b = self.front[first + (k + 1) % rim].tips[0];
            self.triangles.push([middle, a, b]);
        }
    }

    /// A branch of the front node at `at`, which advances along the unit
    /// `heading` with the material opening along the unit `normal` (the
    /// largest principal direction): a new crack that leaves `at`
    /// [`FractureParams::BRANCH_ANGLE`] to one side of `heading`, turned
    /// about the front's tangent, and the heading the front takes to the
    /// other side. In 2D the tangent is `z` and the branch a segment of
    /// length `step` from `at`; in 3D a disc of diameter `step` through
    /// `at`. The branch's end at the junction (in 3D, the half of its rim
    /// behind its centre, seen along its arm, which lies along the
    /// parent's front) is no front. `None` where the tangent is undefined
    /// (`normal` along `heading`).
    ///
    /// [`FractureParams::BRANCH_ANGLE`]: super::FractureParams::BRANCH_ANGLE
    pub fn branch(
        dim: usize,
        at: Vector,
        heading: Vector,
        normal: Vector,
        step: Real,
        depth: Real,
    ) -> Option<(Self, Vector)> {
        let angle = super::FractureParams::BRANCH_ANGLE;
        let radius = 0.5 * step;
        if dim == 2 {
            let turn = |angle: Real| {
                let (sin, cos) = angle.sin_cos();
                Vector::new(
                    cos * heading.x - sin * heading.y,
                    sin * heading.x + cos * heading.y,
                    0.0,
                )
            };
            let arm = turn(angle);
            let mut branch = Self::start(
                2,
                at + arm * radius,
                Vector::new(-arm.y, arm.x, 0.0),
                radius,
                depth,
            );
            if let Some(junction) = branch
                .front
                .iter()
                .position(|f| (f.at - at).norm() < 0.5 * radius)
            {
                branch.stop(junction);
            }
            return Some((branch, turn(-angle)));
        }
        // The front's tangent; turning `heading` about it by `a` gives
        // `cos a heading + sin a normal`.
        let tangent = heading.cross(&normal);
        if tangent.norm() < 1e-9 {
            return None;
        }
        let tangent = tangent.normalize();
        let turn = |angle: Real| {
            let (sin, cos) = angle.sin_cos();
            (heading * cos + normal * sin).normalize()
        };
        let arm = turn(angle);
        let center = at + arm * radius;
        let mut branch = Self::empty(3, depth, center);
        // The rim's first node at `at`, the junction, and its nodes
        // running round the disc's plane (spanned by the arm and the
        // tangent).
        branch.rim(center, (-arm, tangent), radius, RIM_NODES);
        for node in &mut branch.front {
            if (node.at - center).dot(&arm) < 0.0 {
                node.active = false;
            }
        }
        Some((branch, turn(-angle)))
    }

    /// The front, in order.
    pub fn front(&self) -> &[FrontNode] {
        &self.front
    }

    /// The surface's vertices, reference coordinates.
    pub fn vertices(&self) -> &[Vector] {
        &self.vertices
    }

    /// The surface's triangles.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// Stops front node `k` where it is.
    pub fn stop(&mut self, k: usize) {
        self.front[k].active = false;
    }

    /// Moves each front node `k` with `moves[k] = Some((to, heading))` and
    /// adds the strip the front swept to the surface; then splits every
    /// 3D front edge longer than `max_edge` at its middle, so the front
    /// stays as fine as the particles it cuts.
    ///
    /// # Panics
    /// When `moves` does not have one entry per front node (a programming
    /// error of the caller, which sizes it from [`Self::front`]).
    pub fn advance(&mut self, moves: &[Option<(Vector, Vector)>], max_edge: Real) {
        assert_eq!(moves.len(), self.front.len(), "one move per front node");
        let old: Vec<[u32; 2]> = self.front.iter().map(|n| n.tips).collect();
        for (k, step) in moves.iter().enumerate() {
            if let Some((to, heading)) = *step {
                let tips = if self.dim == 2 {
                    self.tip_vertices(to)
                } else {
                    let id = self.vertex(to);
                    [id, id]
                };
                let node = &mut self.front[k];
                node.at = to;
                node.heading = heading;
                node.tips = tips;
            }
        }
        if self.dim == 2 {
            for (k, step) in moves.iter().enumerate() {
                if step.is_some() {
                    let new = self.front[k].tips;
                    self.quad(old[k], new);
                }
            }
            return;
        }
        let n = self.front.len();
        for k in 0..n {
            let next = (k + 1) % n;
            let (a, b) = (old[k][0], old[next][0]);
            let (a2, b2) = (self.front[k].tips[0], self.front[next].tips[0]);
            if b2 != b {
                self.triangles.push([a, b, b2]);
            }
            if a2 != a {
                self.triangles.push([a, b2, a2]);
            }
        }
        self.refine(max_edge);
    }

    /// The box of the crack's vertices, `(lo, hi)`.
    pub fn bounds(&self) -> (Vector, Vector) {
        (self.lo, self.hi)
    }

    /// Where the segment `a -> b` crosses the surface, if it does: the
    /// crossing nearest the front where it crosses more than once. Ends
    /// exactly on the surface do not count, so a particle on a crack's
    /// plane still sees its neighbours.
    pub fn crossing(&self, a: &Vector, b: &Vector) -> Option<Crossing> {
        let lo = a.inf(b);
        let hi = a.sup(b);
        if (0..3).any(|k| hi[k] < self.lo[k] || lo[k] > self.hi[k]) {
            return None;
        }
        let mut best: Option<Crossing> = None;
        for t in &self.triangles {
            let [p, q, r] = t.map(|v| self.vertices[v as usize]);
            // A segment crosses a triangle only inside both their boxes:
            // this test rejects most of a large crack's triangles for a
            // fraction of Möller–Trumbore's cost (a 3D crack across a bar
            // holds thousands, and building a broken solid's surfaces asks
            // millions of segments).
            let (near, far) = (p.inf(&q).inf(&r), p.sup(&q).sup(&r));
            if (0..3).any(|k| hi[k] < near[k] || lo[k] > far[k]) {
                continue;
            }
            if let Some(at) = segment_triangle(a, b, &p, &q, &r) {
                let to_front = self.distance_to_front(&at);
                if best.is_none_or(|c| to_front < c.to_front) {
                    best = Some(Crossing { at, to_front });
                }
            }
        }
        best
    }

    /// Distance from `p` to the nearest point of the live front: in 2D to
    /// the nearest tip (in the plane), in 3D to the polyline through the
    /// active nodes. A node that left the body or met another crack is
    /// no front any more (the crack ends on a surface there), so a crack
    /// whose every node stopped is infinitely far from its front: it cuts
    /// every pair it crosses.
    pub fn distance_to_front(&self, p: &Vector) -> Real {
        if self.dim == 2 {
            return self
                .front
                .iter()
                .filter(|n| n.active)
                .map(|n| (p.xy() - n.at.xy()).norm())
                .fold(Real::INFINITY, Real::min);
        }
        let n = self.front.len();
        (0..n)
            .filter(|&k| self.front[k].active)
            .map(|k| {
                let next = &self.front[(k + 1) % n];
                if next.active {
                    point_segment(p, &self.front[k].at, &next.at)
                } else {
                    (p - self.front[k].at).norm()
                }
            })
            .fold(Real::INFINITY, Real::min)
    }

    /// Distance from `p` to the nearest vertex (a cheap bound of how close
    /// a crack is, for starting no second crack on top of it).
    pub fn distance_to_vertices(&self, p: &Vector) -> Real {
        let points = self
            .front
            .iter()
            .map(|n| n.at)
            .chain(self.vertices.iter().copied());
        let flat = |v: Vector| {
            if self.dim == 2 {
                Vector::new(v.x, v.y, 0.0)
            } else {
                v
            }
        };
        points
            .map(|v| (flat(v) - p).norm())
            .fold(Real::INFINITY, Real::min)
    }

    fn vertex(&mut self, at: Vector) -> u32 {
        self.lo = self.lo.inf(&at);
        self.hi = self.hi.sup(&at);
        self.vertices.push(at);
        (self.vertices.len() - 1) as u32
    }

    /// The two vertices of a 2D tip at `at`, extruded along `z`.
    fn tip_vertices(&mut self, at: Vector) -> [u32; 2] {
        let up = Vector::new(0.0, 0.0, self.depth);
        [self.vertex(at + up), self.vertex(at - up)]
    }

    /// Two triangles between the extruded edges `a` and `b` (2D).
    fn quad(&mut self, a: [u32; 2], b: [u32; 2]) {
        self.triangles.push([a[0], a[1], b[1]]);
        self.triangles.push([a[0], b[1], b[0]]);
    }

    fn refine(&mut self, max_edge: Real) {
        let mut k = 0;
        while k < self.front.len() {
            let next = (k + 1) % self.front.len();
            let (a, b) = (&self.front[k], &self.front[next]);
            if (a.at - b.at).norm() > max_edge {
                let at = (a.at + b.at) * 0.5;
                let sum = a.heading + b.heading;
                let heading = if sum.norm() > 1e-12 {
                    sum.normalize()
                } else {
                    a.heading
                };
                let active = a.active || b.active;
                let id = self.vertex(at);
                // The midpoint lies on the edge the last advance made,
                // so the surface stays closed behind it.
                self.front.insert(
                    k + 1,
                    FrontNode {
                        at,
                        heading,
                        tips: [id, id],
                        active,
                    },
                );
            } else {
                k += 1;
            }
        }
    }
}

/// Nodes on a 3D notch's rim: at most `spacing` apart, at least as many
/// as a started crack's, at most [`MAX_RIM_NODES`].
fn rim_nodes(notch: &Notch, spacing: Real) -> usize {
    let rim = (std::f64::consts::TAU * notch.radius / spacing).ceil();
    if rim.is_finite() {
        (rim as usize).clamp(RIM_NODES, MAX_RIM_NODES)
    } else {
        MAX_RIM_NODES
    }
}

/// Two unit vectors spanning the plane normal to `n`.
fn plane_axes(n: &Vector) -> (Vector, Vector) {
    let helper = if n.x.abs() < 0.9 {
        Vector::x()
    } else {
        Vector::y()
    };
    let u = n.cross(&helper).normalize();
    let v = n.cross(&u).normalize();
    (u, v)
}

/// Where the segment `a -> b` crosses the triangle `p q r`, strictly
/// inside the segment (Möller–Trumbore); `None` when parallel or missing.
pub(super) fn segment_triangle(
    a: &Vector,
    b: &Vector,
    p: &Vector,
    q: &Vector,
    r: &Vector,
) -> Option<Vector> {
    let d = b - a;
    let e1 = q - p;
    let e2 = r - p;
    let h = d.cross(&e2);
    let det = e1.dot(&h);
    let scale = d.norm() * e1.norm() * e2.norm();
    if det.abs() <= 1e-12 * scale {
        return None;
    }
    let inv = 1.0 / det;
    let s = a - p;
    let u = inv * s.dot(&h);
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let qv = s.cross(&e1);
    let v = inv * d.dot(&qv);
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = inv * e2.dot(&qv);
    const END: Real = 1e-9;
    (t > END && t < 1.0 - END).then(|| a + d * t)
}

/// Distance from `p` to the segment `a b`.
fn point_segment(p: &Vector, a: &Vector, b: &Vector) -> Real {
    let d = b - a;
    let length2 = d.norm_squared();
    let t = if length2 > 0.0 {
        ((p - a).dot(&d) / length2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + d * t)).norm()
}
