//! The object being designed: a sparse set of particles sampled in the
//! shape (tens to hundreds) and the MLS deformation field with a linear
//! basis over them (Eq. 72-73), coupled by distance inside the shape
//! ([`Inside`]).
//!
//! Everything the energies need is precomputed once at rest: at each
//! particle `x_i`, the shape functions `phi_j(x_i)` and their gradients
//! `grad phi_j(x_i)` (Eq. 32) over the particles it sees, so that
//! `f(x_i) = x_i + sum_j phi_j(x_i) u_j` and `grad f(x_i) = I + sum_j u_j
//! grad phi_j(x_i)^T` are sums over a short list. Material points
//! elsewhere (handles, a simulation's particles, surface vertices) get
//! their own rows of shape functions, an [`Embedding`].

use super::constraints::Selection;
use super::inside::Inside;
use super::{DesignError, DesignParams, Quadrature};
use crate::approx::mls::{Mls, MlsParams, Order, ShapeFunctions};
use crate::geometry::{Shape, TriMesh};
use crate::math::{Real, Vector, vector};
use crate::neighbors::{CandidateSearch, KdTree};
use crate::solid::embedded::{EmbeddedSurface, EmbeddingMethod};
use rayon::prelude::*;

/// Design particles at most: the optimiser is meant for a sparse set.
pub const MAX_PARTICLES: usize = 20_000;

/// Shape-function rows for a set of points: `phi_j(x)` (and, at the
/// particles, `grad phi_j(x)`) for the particles `j` each point sees.
#[derive(Debug, Clone, Default)]
pub struct Embedding {
    offsets: Vec<u32>,
    particles: Vec<u32>,
    values: Vec<Real>,
    gradients: Vec<Vector>,
    rest: Vec<Vector>,
}

impl Embedding {
    /// The number of points embedded.
    pub fn len(&self) -> usize {
        self.rest.len()
    }

    /// Whether no point is embedded.
    pub fn is_empty(&self) -> bool {
        self.rest.is_empty()
    }

    /// The points at rest.
    pub fn rest(&self) -> &[Vector] {
        &self.rest
    }

    /// Point `k`'s particles, shape functions and their gradients.
    pub fn row(&self, k: usize) -> (&[u32], &[Real], &[Vector]) {
        let r = self.offsets[k] as usize..self.offsets[k + 1] as usize;
        (
            &self.particles[r.clone()],
            &self.values[r.clone()],
            &self.gradients[r],
        )
    }

    /// `u(x_k) = sum_j phi_j(x_k) u_j` (Eq. 72).
    pub fn displacement(&self, k: usize, u: &[Vector]) -> Vector {
        let (js, phi, _) = self.row(k);
        js.iter().zip(phi).map(|(&j, p)| u[j as usize] * *p).sum()
    }

    /// `grad u(x_k) = sum_j u_j grad phi_j(x_k)^T`, entry `(a, b) = du_a /
    /// dx_b`.
    pub fn displacement_gradient(&self, k: usize, u: &[Vector]) -> nalgebra::Matrix3<Real> {
        let (js, _, g) = self.row(k);
        js.iter()
            .zip(g)
            .map(|(&j, g)| u[j as usize] * g.transpose())
            .sum()
    }

    /// The deformed points `f(x_k) = x_k + u(x_k)` (Eq. 73), in parallel.
    pub fn deform(&self, u: &[Vector], out: &mut Vec<Vector>) {
        out.resize(self.len(), Vector::zeros());
        out.par_iter_mut()
            .enumerate()
            .for_each(|(k, x)| *x = self.rest[k] + self.displacement(k, u));
    }
}

/// The lattice spacing that puts close to `particles` particles in
/// `shape`: `(V / n)^(1/dim)` to start, then corrected by the count a
/// few times (a lattice fills a box's corners or not depending on where
/// its planes fall).
fn spacing_for(shape: &Shape, dim: usize, volume: Real, particles: u32) -> Real {
    let target = Real::from(particles);
    let mut spacing = (volume / target).powf(1.0 / dim as Real);
    let mut best = (Real::INFINITY, spacing);
    for _ in 0..8 {
        let count = shape.sample_volume(spacing, dim).map_or(0, |p| p.len()) as Real;
        let miss = (count / target).ln().abs();
        if miss < best.0 {
            best = (miss, spacing);
        }
        if miss < 0.05 || count == 0.0 {
            break;
        }
        spacing *= (count / target).powf(1.0 / dim as Real);
    }
    best.1
}

/// The design particles of a shape and their deformation field.
#[derive(Debug, Clone)]
pub struct DesignBody {
    dim: usize,
    spacing: Real,
    h: Real,
    inside: Inside,
    rest: Vec<Vector>,
    /// `V_i / spacing^dim`.
    volumes: Vec<Real>,
    /// At the particles themselves.
    field: Embedding,
    /// Where rigidity and volume are measured, and the volume (relative
    /// to `spacing^dim`) each point stands for.
    quadrature: Embedding,
    quadrature_volumes: Vec<Real>,
    /// Rest positions of the simulated solid's particles, and its system,
    /// for selections by particle index and for playback.
    solid: Option<(usize, Vec<Vector>)>,
    tree: KdTree,
}

impl DesignBody {
    /// Samples `shape` (body frame; placed at `centre`, turned by
    /// `rotation`) with particles `params.spacing` apart, or about
    /// `params.particles` of them when the spacing is 0. `solid`, when
    /// given, is a scene solid's system index and particles at rest, which
    /// selections by index refer to.
    ///
    /// # Errors
    /// [`DesignError::Parameter`] for an unusable spacing, support or
    /// shape, or too few or too many particles.
    pub fn new(
        shape: &Shape,
        centre: Vector,
        rotation: nalgebra::Rotation3<Real>,
        dim: usize,
        params: &DesignParams,
        solid: Option<(usize, Vec<Vector>)>,
    ) -> Result<Self, DesignError> {
        let invalid = |field, message: String| Err(DesignError::Parameter { field, message });
        if !(2..=3).contains(&dim) {
            return invalid("dimension", format!("is {dim}; design works in 2D or 3D"));
        }
        if !(params.support.is_finite() && params.support >= 1.5 && params.support <= 6.0) {
            return invalid(
                "support",
                format!(
                    "is {}; a linear MLS basis needs a support of 1.5 to 6 spacings (2.2 is the \
                     default)",
                    params.support
                ),
            );
        }
        let Some(volume) = shape.volume(dim).filter(|v| *v > 0.0 && v.is_finite()) else {
            return invalid(
                "shape",
                "has no finite volume; design a bounded shape".into(),
            );
        };
        let spacing = if params.spacing == 0.0 {
            if params.particles < 8 {
                return invalid(
                    "particles",
                    format!("is {}; ask for at least 8", params.particles),
                );
            }
            spacing_for(shape, dim, volume, params.particles)
        } else {
            params.spacing
        };
        if !(spacing.is_finite() && spacing > 0.0) {
            return invalid(
                "spacing",
                format!("is {spacing}; give a positive spacing, or 0 to use `particles`"),
            );
        }
        let local = shape.sample_volume(spacing, dim).unwrap_or_default();
        if local.len() < dim + 1 || local.len() > MAX_PARTICLES {
            return invalid(
                "spacing",
                format!(
                    "places {} particles in the shape; choose a spacing that places between {} \
                     and {MAX_PARTICLES}",
                    local.len(),
                    dim + 1
                ),
            );
        }
        let rest: Vec<Vector> = local.iter().map(|p| centre + rotation * p).collect();
        let h = params.support * spacing;
        let inside = Inside::new(shape, centre, rotation, dim, spacing)?;
        let mut tree = KdTree::new(h);
        tree.rebuild(&rest);
        let share = volume / (rest.len() as Real * spacing.powi(dim as i32));
        let mut body = Self {
            dim,
            spacing,
            h,
            inside,
            volumes: vec![share; rest.len()],
            rest,
            field: Embedding::default(),
            quadrature: Embedding::default(),
            quadrature_volumes: Vec::new(),
            solid,
            tree,
        };
        body.field = body.embed(&body.rest.clone())?;
        (body.quadrature, body.quadrature_volumes) = match params.quadrature {
            Quadrature::Particles => (body.field.clone(), body.volumes.clone()),
            Quadrature::Cells => {
                let corners = 1usize << dim;
                let inside = &body.inside;
                let points: Vec<Vector> = body
                    .rest
                    .iter()
                    .flat_map(|x| {
                        (0..corners).map(move |c| {
                            let local = Vector::from_fn(|a, _| {
                                if a < dim {
                                    if (c >> a) & 1 == 1 { 0.25 } else { -0.25 }
                                } else {
                                    0.0
                                }
                            });
                            // A lattice need not align with the shape's
                            // faces: a point that falls outside moves back
                            // onto its particle.
                            let p = x + rotation * local * spacing;
                            if inside.distance(&p) > 0.0 { *x } else { p }
                        })
                    })
                    .collect();
                let volumes = vec![share / corners as Real; points.len()];
                (body.embed(&points)?, volumes)
            }
        };
        Ok(body)
    }

    /// The spatial dimension, 2 or 3.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The design spacing, m.
    pub fn spacing(&self) -> Real {
        self.spacing
    }

    /// The MLS support radius, m.
    pub fn support(&self) -> Real {
        self.h
    }

    /// The number of design particles.
    pub fn len(&self) -> usize {
        self.rest.len()
    }

    /// Whether the body has no design particle.
    pub fn is_empty(&self) -> bool {
        self.rest.is_empty()
    }

    /// The design particles at rest.
    pub fn rest(&self) -> &[Vector] {
        &self.rest
    }

    /// `V_i / spacing^dim`.
    pub fn volumes(&self) -> &[Real] {
        &self.volumes
    }

    /// Shape functions and gradients at the particles.
    pub fn field(&self) -> &Embedding {
        &self.field
    }

    /// The points where rigidity and volume are measured (Eq. 76-77),
    /// with shape-function gradients, and the volume each stands for
    /// (relative to `spacing^dim`).
    pub fn quadrature(&self) -> (&Embedding, &[Real]) {
        (&self.quadrature, &self.quadrature_volumes)
    }

    /// The shape's sampled signed distance, which decides which particles
    /// a point sees.
    pub fn inside(&self) -> &Inside {
        &self.inside
    }

    /// The simulated solid this body stands for, if any.
    pub fn solid(&self) -> Option<(usize, &[Vector])> {
        self.solid.as_ref().map(|(s, x)| (*s, x.as_slice()))
    }

    /// The particles `x` sees within the support, in index order.
    fn visible(&self, x: &Vector, out: &mut Vec<u32>) {
        out.clear();
        let h2 = self.h * self.h;
        self.tree.for_each_candidate(x, |j| {
            let xj = &self.rest[j as usize];
            if (xj - x).norm_squared() < h2 && self.inside.sees(x, xj) {
                out.push(j);
            }
        });
        out.sort_unstable();
    }

    /// Shape functions (linear basis, lowered where the visible particles
    /// cannot support it) at each of `points`.
    ///
    /// # Errors
    /// [`DesignError::Unsupported`] naming the first point that sees no
    /// particle.
    pub fn embed(&self, points: &[Vector]) -> Result<Embedding, DesignError> {
        let mls = Mls::new(self.dim, MlsParams::new(Order::Linear, self.h)).map_err(|e| {
            DesignError::Parameter {
                field: "support",
                message: e.to_string(),
            }
        })?;
        type Row = (Vec<u32>, Vec<Real>, Vec<Vector>);
        let rows: Vec<Result<Row, DesignError>> = points
            .par_iter()
            .enumerate()
            .map_init(
                || (Vec::new(), Vec::new(), ShapeFunctions::new()),
                |(js, nodes, shape), (k, x)| {
                    self.visible(x, js);
                    nodes.clear();
                    nodes.extend(js.iter().map(|&j| self.rest[j as usize]));
                    mls.shape_functions(x, nodes, shape)
                        .map_err(|_| DesignError::Unsupported {
                            point: k,
                            position: [x[0], x[1], x[2]],
                        })?;
                    Ok((
                        js.clone(),
                        shape.values().to_vec(),
                        shape.gradients().to_vec(),
                    ))
                },
            )
            .collect();
        let mut e = Embedding {
            offsets: vec![0],
            rest: points.to_vec(),
            ..Embedding::default()
        };
        for row in rows {
            let (js, phi, g) = row?;
            for ((j, p), g) in js.into_iter().zip(phi).zip(g) {
                if p != 0.0 || g != Vector::zeros() {
                    e.particles.push(j);
                    e.values.push(p);
                    e.gradients.push(g);
                }
            }
            e.offsets.push(e.particles.len() as u32);
        }
        Ok(e)
    }

    /// A high-resolution surface that follows the field (Alternative 1 of
    /// Section 7.2), coupled by distance inside the shape like the field.
    /// Deform it with [`EmbeddedSurface::update`] and the particles'
    /// positions `x_i + u_i`.
    ///
    /// # Errors
    /// [`DesignError::Surface`] when a vertex sees no particle or the mesh
    /// is invalid.
    pub fn surface(&self, mesh: &TriMesh) -> Result<EmbeddedSurface, DesignError> {
        EmbeddedSurface::new_coupled(
            mesh,
            &self.rest,
            self.dim,
            self.h,
            Order::Linear,
            EmbeddingMethod::ShapeFunctions,
            &|v, x| self.inside.sees(v, x),
        )
        .map_err(|e| DesignError::Surface(e.to_string()))
    }

    /// The material points a selection names, at rest.
    ///
    /// # Errors
    /// A message saying what to change: a selection by particle index of
    /// another system or with no simulated solid, points outside the
    /// shape, a region holding no design particle.
    pub fn select(&self, selection: &Selection) -> Result<Vec<Vector>, String> {
        match selection {
            Selection::Particles { system, indices } => {
                let Some((own, rest)) = &self.solid else {
                    return Err(
                        "selects particles by index, but the design has no simulated \
                                solid; select points or a region"
                            .into(),
                    );
                };
                if own != system {
                    return Err(format!(
                        "selects particles of system {system}, but the design is of system {own}"
                    ));
                }
                indices
                    .iter()
                    .map(|&i| {
                        rest.get(i as usize).copied().ok_or_else(|| {
                            format!(
                                "particle {i} does not exist: system {own} has {}",
                                rest.len()
                            )
                        })
                    })
                    .collect()
            }
            Selection::Points(points) => points
                .iter()
                .enumerate()
                .map(|(k, p)| {
                    let p = vector(*p);
                    if self.inside.contains(&p) {
                        Ok(p)
                    } else {
                        Err(format!(
                            "point {k} at {:?} lies outside the shape; select points in it",
                            [p.x, p.y, p.z]
                        ))
                    }
                })
                .collect(),
            Selection::Region { min, max } => {
                let (min, max) = (vector(*min), vector(*max));
                let found: Vec<Vector> = self
                    .rest
                    .iter()
                    .filter(|x| (0..self.dim).all(|a| x[a] >= min[a] && x[a] <= max[a]))
                    .copied()
                    .collect();
                if found.is_empty() {
                    Err(format!(
                        "the region holds no design particle (spacing {:.4} m); enlarge it or \
                         lower the spacing",
                        self.spacing
                    ))
                } else {
                    Ok(found)
                }
            }
        }
    }
}
