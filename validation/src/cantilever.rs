//! The cantilever under its own weight: the elastic solids' reference
//! against Euler–Bernoulli beam theory, shared by the validation tests,
//! `meshless study` and the benchmarks.
//!
//! A beam of length `L` and thickness `H` (square section in 3D, unit
//! depth in 2D), clamped at `x = 0` by anchoring three spacings of
//! material behind the wall, sags under gravity. Beam theory gives the
//! static tip deflection and the first bending period
//!
//! ```text
//! delta = q L^4 / (8 E I),         q = rho g A
//! omega_1 = 1.8751^2 sqrt(E I / (rho A L^4)),  T_1 = 2 pi / omega_1
//! ```
//!
//! (Timoshenko 1955, Vibration Problems in Engineering; `1.8751` is the
//! first root of `1 + cos(b) cosh(b) = 0`). With `L / H = 10` shear adds
//! about 1 % to the deflection, below the tolerances used here. Poisson's
//! ratio is 0 so that plane strain (2D) and the beam's plane stress agree.

use meshless_engine::BuildOptions;
use meshless_engine::approx::mls::Order;
use meshless_engine::math::Real;
use meshless_engine::scene::{IntegratorKind, Scene, SceneError};
use meshless_engine::solid::LinearSolver;
use meshless_engine::world::{StepError, World};

/// First root of the clamped-free frequency equation.
const BETA_1: Real = 1.875_104_068_711_961;

/// A cantilever experiment: geometry, material and the knobs under study.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cantilever {
    /// 2 (unit depth) or 3 (square section).
    pub dim: usize,
    /// Length `L` from the wall to the free end, m.
    pub length: Real,
    /// Thickness `H`, m.
    pub thickness: Real,
    /// Young's modulus `E`, Pa.
    pub young: Real,
    /// Density `rho`, kg/m^3.
    pub density: Real,
    /// Gravity `g`, m/s^2, pulling down.
    pub gravity: Real,
    /// Particle spacing, m.
    pub spacing: Real,
    /// MLS basis order.
    pub order: Order,
    /// MLS support in spacings.
    pub support: Real,
    /// Hourglass-control weight relative to Young's modulus.
    pub hourglass: Real,
    /// Time integrator of [`Cantilever::period`] runs.
    pub integrator: IntegratorKind,
    /// Step of the world, s (explicit sub-steps below it as needed).
    pub dt: Real,
    /// The implicit integrator's linear solver (static runs and implicit
    /// period runs).
    pub linear_solver: LinearSolver,
}

impl Default for Cantilever {
    /// A 1 m beam, 0.1 m thick, that sags about 1 % of its length: small
    /// enough for linear beam theory, large enough to measure.
    fn default() -> Self {
        Self {
            dim: 2,
            length: 1.0,
            thickness: 0.1,
            young: 1.5e8,
            density: 1000.0,
            gravity: 9.81,
            spacing: 0.0125,
            order: Order::Linear,
            support: 2.0,
            hourglass: meshless_engine::scene::solid_defaults::HOURGLASS,
            integrator: IntegratorKind::Explicit,
            dt: 1e-3,
            linear_solver: LinearSolver::Auto,
        }
    }
}

/// What one run measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured {
    /// Particles of the beam.
    pub particles: usize,
    /// Tip deflection (positive down), m.
    pub value: Real,
    /// `value / reference - 1`.
    pub error: Real,
    /// World steps taken.
    pub steps: u64,
    /// Period runs: the first peak's tip deflection over twice the static
    /// one of beam theory (about 1 for an undamped beam released at rest;
    /// numerical damping lowers it). Static runs: 1.
    pub amplitude: Real,
}

impl Cantilever {
    /// Second moment of area times the section's depth factor, m^4.
    fn inertia(&self) -> Real {
        let depth = if self.dim == 3 { self.thickness } else { 1.0 };
        depth * self.thickness.powi(3) / 12.0
    }

    /// Load per length `rho g A`, N/m.
    fn load(&self) -> Real {
        let depth = if self.dim == 3 { self.thickness } else { 1.0 };
        self.density * self.gravity * self.thickness * depth
    }

    /// Euler–Bernoulli static tip deflection, m.
    pub fn static_deflection(&self) -> Real {
        self.load() * self.length.powi(4) / (8.0 * self.young * self.inertia())
    }

    /// Euler–Bernoulli first bending period, s.
    pub fn first_period(&self) -> Real {
        let mass_per_length = self.load() / self.gravity;
        let omega = BETA_1
            * BETA_1
            * (self.young * self.inertia() / (mass_per_length * self.length.powi(4))).sqrt();
        2.0 * std::f64::consts::PI / omega
    }

    /// The scene: the beam from `x = -3 spacing` (anchored behind the
    /// wall at `x = 0`) to `x = L`, centred on `y = z = 0`.
    pub fn scene(&self) -> Result<Scene, SceneError> {
        let clamp = 3.0 * self.spacing;
        let half = [
            0.5 * (self.length + clamp),
            0.5 * self.thickness,
            0.5 * self.thickness,
        ];
        let centre_x = 0.5 * (self.length - clamp);
        let order = match self.order {
            Order::Constant => "constant",
            Order::Linear => "linear",
            Order::Quadratic => "quadratic",
        };
        let integrator = match self.integrator {
            IntegratorKind::Explicit => "explicit",
            IntegratorKind::Implicit => "implicit",
        };
        let linear_solver = match self.linear_solver {
            LinearSolver::Auto => "auto",
            LinearSolver::Cholesky => "cholesky",
            LinearSolver::ConjugateGradient => "conjugate_gradient",
        };
        let text = format!(
            r#"
            name = "cantilever"
            dimension = {dim}
            gravity = [0.0, {g}, 0.0]
            [domain]
            min = [-1.0, -2.0, -1.0]
            max = [2.0, 1.0, 1.0]
            [time]
            dt = {dt}
            max_substeps = 1000000
            [[systems]]
            kind = "solid"
            shape = {{ type = "box", half_extents = [{hx}, {hy}, {hz}] }}
            position = [{centre_x}, 0.0, 0.0]
            spacing = {spacing}
            density = {density}
            young = {young}
            poisson = 0.0
            order = "{order}"
            support = {support}
            hourglass = {hourglass}
            integrator = "{integrator}"
            implicit = {{ linear_solver = "{linear_solver}" }}
            anchors = [{{ min = [-1.0, -1.0, -1.0], max = [0.0, 1.0, 1.0] }}]
            "#,
            dim = self.dim,
            g = -self.gravity,
            dt = self.dt,
            hx = half[0],
            hy = half[1],
            hz = half[2],
            spacing = self.spacing,
            density = self.density,
            young = self.young,
            support = self.support,
            hourglass = self.hourglass,
        );
        let scene = Scene::from_toml_str(&text)?;
        scene.validate(&BuildOptions::default())?;
        Ok(scene)
    }

    /// The beam as the lattice sampled it: the wall sits halfway between
    /// the last anchored and the first free column, the free end half a
    /// spacing beyond the last column. Returns that length and the last
    /// column's distance from the wall.
    fn sampled(&self, world: &World) -> Option<(Real, Real)> {
        let (_, solid) = world.solids().next()?;
        let rest = solid.rest_positions();
        let free = (0..rest.len()).filter(|&i| !solid.is_fixed(i));
        let first_free = free
            .clone()
            .map(|i| rest[i].x)
            .fold(Real::INFINITY, Real::min);
        let last = free.map(|i| rest[i].x).fold(Real::NEG_INFINITY, Real::max);
        let last_fixed = (0..rest.len())
            .filter(|&i| solid.is_fixed(i))
            .map(|i| rest[i].x)
            .fold(Real::NEG_INFINITY, Real::max);
        let wall = 0.5 * (first_free + last_fixed);
        Some((last + 0.5 * self.spacing - wall, last - wall))
    }

    /// Mean downward displacement of the last column of particles, m.
    pub fn tip(&self, world: &World) -> Real {
        let Some((_, solid)) = world.solids().next() else {
            return 0.0;
        };
        let rest = solid.rest_positions();
        let last = rest.iter().map(|x| x.x).fold(Real::NEG_INFINITY, Real::max);
        let (sum, count) = solid
            .positions
            .iter()
            .zip(rest)
            .filter(|(_, rest)| rest.x > last - 0.5 * self.spacing)
            .fold((0.0, 0), |(s, c), (x, rest)| (s + rest.y - x.y, c + 1));
        sum / count.max(1) as Real
    }

    /// Euler–Bernoulli deflection of the sampled beam at its last column,
    /// `q x^2 (6 L^2 - 4 L x + x^2) / (24 E I)`, and its first period.
    fn reference(&self, world: &World) -> (Real, Real) {
        let (length, x) = self.sampled(world).unwrap_or((self.length, self.length));
        let beam = Self { length, ..*self };
        let deflection = self.load() * x * x * (6.0 * length * length - 4.0 * length * x + x * x)
            / (24.0 * self.young * self.inertia());
        (deflection, beam.first_period())
    }

    /// The static deflection: backward Euler steps of a hundred beam
    /// periods each, whose inertia is negligible, so each is a Newton solve
    /// of the static equilibrium, until the out-of-balance force of the
    /// free particles is below `tolerance` times their weight (both as
    /// 2-norms). The integrator and step of `self` are not used.
    ///
    /// # Errors
    /// A scene error, or a step that blew up.
    pub fn settle(&self, tolerance: Real) -> Result<Measured, CantileverError> {
        let statics = Self {
            integrator: IntegratorKind::Implicit,
            dt: 100.0 * self.first_period(),
            ..*self
        };
        let mut world = statics.scene()?.build(&BuildOptions::default())?;
        for _ in 0..10 {
            world.step()?;
            let solid = world
                .solids()
                .next()
                .map(|(_, s)| s)
                .ok_or(CantileverError::NoSolid)?;
            if self.imbalance(solid) <= tolerance {
                break;
            }
        }
        let value = self.tip(&world);
        Ok(Measured {
            particles: world.particle_count(),
            value,
            error: value / self.reference(&world).0 - 1.0,
            steps: world.clock().step,
            amplitude: 1.0,
        })
    }

    /// `|f + m g| / |m g|` over the free particles.
    fn imbalance(&self, solid: &meshless_engine::solid::ElasticSolid) -> Real {
        let forces = solid.forces();
        let (mut unbalanced, mut weight) = (0.0, 0.0);
        for (i, (f, m)) in forces.iter().zip(solid.masses()).enumerate() {
            if !solid.is_fixed(i) {
                let w = m * self.gravity;
                unbalanced += (f.y - w).powi(2) + f.x * f.x + f.z * f.z;
                weight += w * w;
            }
        }
        (unbalanced / weight).sqrt()
    }

    /// The first bending period from a release: the beam starts straight
    /// and at rest, so the tip swings down to its first maximum at half a
    /// period. Returns that period.
    ///
    /// # Errors
    /// A scene error, or a step that blew up.
    pub fn period(&self) -> Result<Measured, CantileverError> {
        let mut world = self.scene()?.build(&BuildOptions::default())?;
        let limit = (2.0 * self.first_period() / self.dt).ceil() as u64;
        // The last three (time, tip) samples; the peak is the vertex of the
        // parabola through them, finer than the step.
        let mut samples = [(0.0, 0.0); 3];
        let mut half = None;
        while world.clock().step < limit {
            world.step()?;
            samples = [
                samples[1],
                samples[2],
                (world.clock().time, self.tip(&world)),
            ];
            if world.clock().step >= 3 && samples[2].1 < samples[1].1 {
                half = Some(parabola_vertex(samples));
                break;
            }
        }
        let half = half.ok_or(CantileverError::NoPeak)?;
        let value = 2.0 * half;
        let (deflection, period) = self.reference(&world);
        Ok(Measured {
            particles: world.particle_count(),
            value,
            error: value / period - 1.0,
            steps: world.clock().step,
            amplitude: samples[1].1 / (2.0 * deflection),
        })
    }
}

/// What a cantilever study measures (`meshless study --knob solid-*`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    /// Static tip deflection (a Newton solve).
    Deflection,
    /// First bending period of the released beam (a dynamic run).
    Period,
}

/// Out-of-balance force, as a fraction of the weight, at which a study's
/// static solve counts as settled.
const STUDY_TOLERANCE: Real = 1e-6;

impl Cantilever {
    /// Measures `quantity`: the static deflection settled to a
    /// millionth of the weight ([`Cantilever::settle`]), or the first
    /// period ([`Cantilever::period`]).
    ///
    /// # Errors
    /// As those.
    pub fn measure(&self, quantity: Quantity) -> Result<Measured, CantileverError> {
        match quantity {
            Quantity::Deflection => self.settle(STUDY_TOLERANCE),
            Quantity::Period => self.period(),
        }
    }
}

/// The abscissa of the extremum of the parabola through three points
/// equally spaced in time.
fn parabola_vertex([(_, y0), (t1, y1), (t2, y2)]: [(Real, Real); 3]) -> Real {
    let curvature = y0 - 2.0 * y1 + y2;
    if curvature == 0.0 {
        return t1;
    }
    t1 + 0.5 * (t2 - t1) * (y0 - y2) / curvature
}

/// Why a cantilever run did not produce a figure.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CantileverError {
    /// The beam's scene is invalid.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// A step failed.
    #[error(transparent)]
    Step(#[from] StepError),
    /// The scene built no solid.
    #[error("the cantilever scene holds no solid")]
    NoSolid,
    /// The released beam never swung back.
    #[error("the tip did not turn within two beam periods; lower the step or the damping")]
    NoPeak,
}
