//! A thin-shell cantilever plate (Guo–Qin's shells, served as a scene's
//! `kind = "shell"`) against Euler–Bernoulli: what `meshless study --knob
//! shell-*` sweeps.
//!
//! The plate is `L x W x t`, clamped along its edge at `x = 0`, its
//! weight along `-y`, with Poisson's ratio 0 so that its strip bends as a
//! beam of stiffness `D = E t^3 / 12` per unit width (no anticlastic
//! curvature). Two measurements, both through the scene and the world,
//! the path a served session takes:
//!
//! - **static**: backward-Euler steps far longer than the first period
//!   settle the plate (each damps a mode by `(omega h)^2 / 2`); its tip
//!   sag against `rho t g L^4 / (8 D)`;
//! - **period**: released from rest, Newmark's average acceleration at
//!   the knob's step; the time of the tip's first lowest point, half the
//!   first period, against `pi / omega_1`, `omega_1 = 1.875^2 sqrt(D /
//!   (rho t L^4))` (the plate starts straight, so the first mode carries
//!   nearly all the swing).

use meshless_engine::approx::mls::Order;
use meshless_engine::math::Real;
use meshless_engine::scene::{
    Aabb, OutputSpec, ShapeSpec, ShellSpec, SystemSpec, TimeSpec, shell_defaults,
};
use meshless_engine::shell::Integrator;
use meshless_engine::{BuildOptions, Scene, World};
use std::time::Instant;

/// Standard gravity, m/s^2.
const G: Real = 9.81;

/// What a setting measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShellMeasure {
    /// The static tip sag, by long backward-Euler steps.
    Static,
    /// Half the first period, by Newmark steps of the knob's length.
    Period,
}

/// One cantilever plate and how it is discretised and stepped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShellCantilever {
    /// Length along x, m.
    pub length: Real,
    /// Width along z, m.
    pub width: Real,
    /// m.
    pub thickness: Real,
    /// Young's modulus, Pa.
    pub young: Real,
    /// kg/m^3.
    pub density: Real,
    /// Largest quadtree cell on the surface, m.
    pub resolution: Real,
    /// Support side in leaf sides.
    pub eta: Real,
    /// Gauss points per axis of an integration cell.
    pub quadrature_order: u32,
    /// MLS basis.
    pub basis: Order,
    /// Time step of the released plate, s.
    pub dt: Real,
}

impl Default for ShellCantilever {
    /// A 0.5 x 0.2 m plate, 1 cm thick (E = 10 GPa, rho = 1000: it sags
    /// 0.18 % of its length, where linear theory holds; first period 49
    /// ms), on 16 cells along it, the served defaults otherwise, 40 steps
    /// a period.
    fn default() -> Self {
        Self {
            length: 0.5,
            width: 0.2,
            thickness: 0.01,
            young: 1e10,
            density: 1000.0,
            resolution: 0.5 / 16.0,
            eta: shell_defaults::ETA,
            quadrature_order: shell_defaults::QUADRATURE_ORDER,
            basis: Order::Quadratic,
            dt: 0.049 / 40.0,
        }
    }
}

/// One measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShellMeasured {
    /// Nodes of the quadtree.
    pub nodes: usize,
    /// Wall time of the scene's check and build (chart, quadtree, shape
    /// functions, first factorisation), s.
    pub precompute: Real,
    /// Mean wall time of a step, ms.
    pub step_ms: Real,
    /// The tip sag (m) or the half period (s).
    pub value: Real,
    /// Its reference.
    pub reference: Real,
    /// `value / reference - 1`.
    pub error: Real,
}

impl ShellCantilever {
    /// Bending stiffness per unit width, `E t^3 / 12` (nu = 0).
    fn stiffness(&self) -> Real {
        self.young * self.thickness.powi(3) / 12.0
    }

    /// Euler–Bernoulli's tip sag under the plate's own weight.
    pub fn sag(&self) -> Real {
        self.density * self.thickness * G * self.length.powi(4) / (8.0 * self.stiffness())
    }

    /// Euler–Bernoulli's first bending frequency, rad/s.
    pub fn omega(&self) -> Real {
        1.875_f64.powi(2)
            * (self.stiffness() / (self.density * self.thickness * self.length.powi(4))).sqrt()
    }

    /// The plate as a scene stepped by `integrator` at `dt`.
    pub fn scene(&self, integrator: Integrator, dt: Real) -> Scene {
        let (l, w) = (self.length, self.width);
        Scene {
            name: "shell cantilever".into(),
            dimension: 3,
            domain: Aabb {
                min: [-0.1 * l, -l, -w],
                max: [1.1 * l, 0.5 * l, w],
            },
            periodic: [false; 3],
            gravity: [0.0, -G, 0.0],
            time: TimeSpec {
                dt,
                max_substeps: 1,
                cfl: 0.4,
            },
            systems: vec![SystemSpec::Shell(ShellSpec {
                shape: ShapeSpec::Box {
                    half_extents: [l / 2.0, 0.0, w / 2.0],
                },
                position: [l / 2.0, 0.0, 0.0],
                orientation: [0.0; 3],
                thickness: self.thickness,
                density: self.density,
                young: self.young,
                poisson: 0.0,
                resolution: self.resolution,
                eta: self.eta,
                basis: self.basis,
                quadrature_order: self.quadrature_order,
                subdivision: shell_defaults::SUBDIVISION,
                integrator,
                mechanics: Default::default(),
                mass_damping: 0.0,
                stiffness_damping: 0.0,
                penalty: shell_defaults::PENALTY,
                tolerance: shell_defaults::TOLERANCE,
                max_iterations: shell_defaults::MAX_ITERATIONS,
                pressure: 0.0,
                clamped: vec![Aabb {
                    min: [-1e-3 * l, -1e-3 * l, -w],
                    max: [1e-3 * l, 1e-3 * l, w],
                }],
                pinned: Vec::new(),
                surface_cells: 32,
            })],
            output: OutputSpec::default(),
        }
    }

    /// Measures the plate.
    ///
    /// # Errors
    /// The scene's refusal or a step's failure, in words.
    pub fn measure(&self, measure: ShellMeasure) -> Result<ShellMeasured, String> {
        let (integrator, dt) = match measure {
            ShellMeasure::Static => (Integrator::BackwardEuler, 1e3 / self.omega()),
            ShellMeasure::Period => (Integrator::Newmark, self.dt),
        };
        let scene = self.scene(integrator, dt);
        let clock = Instant::now();
        let mut world = scene
            .build(&BuildOptions::default())
            .map_err(|e| e.to_string())?;
        let precompute = clock.elapsed().as_secs_f64();
        let nodes = world.frame().particle_count;
        let mut steps = 0;
        let mut stepping = 0.0;
        let mut step = |world: &mut World| -> Result<Real, String> {
            let clock = Instant::now();
            world.step().map_err(|e| e.to_string())?;
            stepping += clock.elapsed().as_secs_f64();
            steps += 1;
            Ok(tip(world))
        };
        let (value, reference) = match measure {
            ShellMeasure::Static => {
                let mut sag = 0.0;
                for _ in 0..4 {
                    sag = -step(&mut world)?;
                }
                (sag, self.sag())
            }
            ShellMeasure::Period => {
                // The first lowest point: a parabola through the three
                // steps around it.
                let half = std::f64::consts::PI / self.omega();
                let limit = (3.0 * half / dt).ceil() as usize + 3;
                let mut y = vec![0.0, step(&mut world)?];
                let turned = loop {
                    if y.len() > limit {
                        return Err(format!(
                            "the tip did not turn within {limit} steps of {dt} s"
                        ));
                    }
                    let next = step(&mut world)?;
                    let n = y.len();
                    if next > y[n - 1] && y[n - 1] < y[n - 2] {
                        let (a, b, c) = (y[n - 2], y[n - 1], next);
                        let offset = 0.5 * (a - c) / (a - 2.0 * b + c);
                        break ((n - 1) as Real + offset) * dt;
                    }
                    y.push(next);
                };
                (turned, half)
            }
        };
        Ok(ShellMeasured {
            nodes,
            precompute,
            step_ms: 1e3 * stepping / steps.max(1) as Real,
            value,
            reference,
            error: value / reference - 1.0,
        })
    }
}

/// The lowest point of the plate's carried surface, m along y.
fn tip(world: &World) -> Real {
    world.frame().solid_surfaces.first().map_or(Real::NAN, |s| {
        s.mesh
            .vertices
            .iter()
            .map(|v| v.y)
            .fold(Real::INFINITY, Real::min)
    })
}
