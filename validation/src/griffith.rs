//! Griffith's plate: a brittle plate with a central through crack under
//! remote tension, the fracturing solids' reference against linear
//! elastic fracture mechanics, shared by the validation tests and the
//! docs' table.
//!
//! A plate of width `W` and height `H` (plane, unit depth) holds a crack
//! of half-length `a` across its middle and is pulled by its top and
//! bottom rows. Griffith (1921), in Irwin's form: the crack runs when the
//! stress intensity `K_I = sigma sqrt(pi a)` reaches the toughness
//! `K_Ic = sqrt(2 E gamma)` (plane stress, surface energy `gamma`), so
//!
//! ```text
//! sigma_c = sqrt(2 E gamma / (pi a)) = K_Ic / sqrt(pi a),
//! ```
//!
//! times Feddersen's finite-width factor `1 / sqrt(sec(pi a / W))`
//! (Feddersen 1966, in Tada, Paris & Irwin, The Stress Analysis of
//! Cracks Handbook, 2000: within 0.3 % for `2a / W <= 0.7`). Poisson's
//! ratio is 0, so that the plane-strain solid and the plane-stress
//! formula agree and the clamped grips bear no lateral stress.
//!
//! The solid's criterion is the point method (`Threshold::Toughness`):
//! the front runs when the stress a critical distance `r_c` ahead of it
//! reaches the strength. On the crack's exact field that differs from
//! Griffith by a factor that tends to 1 as `r_c / a` falls: on
//! Westergaard's field of a crack in an infinite plate, `sigma_yy(a + r)
//! = sigma (a + r) / sqrt(r (2a + r))` on the crack line, so the front
//! runs at `sigma_c sqrt((2a^2 + a r_c) / (2 (a + r_c)^2))` (0.85 of
//! Griffith at `a = 4 r_c`, 0.96 at `a = 16 r_c`): the theory of critical
//! distances' short-crack regime (Taylor 2007). [`Griffith::point_method`]
//! is that, with the same width factor; the table lists both.
//!
//! The failure stress is measured quasi-statically: each load is a
//! static solve (`ImplicitScheme::Static`), and the solid's own fracture
//! update decides whether the front runs at it; bisection on the load
//! brackets the least load at which it does. The remote stress is the
//! top grip's reaction over the width.

use meshless_engine::approx::mls::Order;
use meshless_engine::geometry::Shape;
use meshless_engine::math::{Real, Vector};
use meshless_engine::solid::fracture::{Discontinuity, Notch, Resampling, Threshold};
use meshless_engine::solid::{
    ElasticSolid, FractureParams, ImplicitParams, ImplicitScheme, Integrator, LinearSolver,
    Material, Obstacles, SolidParams,
};
use std::f64::consts::PI;

/// The plate's density, kg/m^3 (only the dynamic hold sees it).
const DENSITY: Real = 1000.0;

/// A Griffith plate: geometry, material and the knobs under study.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Griffith {
    /// Width `W`, m.
    pub width: Real,
    /// Height `H`, m.
    pub height: Real,
    /// Young's modulus `E`, Pa.
    pub young: Real,
    /// Tensile strength `sigma_0`, Pa.
    pub strength: Real,
    /// Fracture toughness `K_Ic`, Pa m^(1/2).
    pub toughness: Real,
    /// Particle spacing, m.
    pub spacing: Real,
    /// MLS support in spacings.
    pub support: Real,
    /// How the crack cuts its pairs.
    pub discontinuity: Discontinuity,
    /// Relative width of the final load bracket.
    pub resolution: Real,
    /// Resampling beside the crack (tutorial Eq. 71), done once the
    /// notch is cut; none keeps the lattice.
    pub resample: Option<Resampling>,
}

impl Default for Griffith {
    /// A 1.1 m x 1.65 m plate of 110 x 165 particles whose critical
    /// distance is three spacings (`K_Ic = sigma_0 sqrt(6 pi s)`).
    fn default() -> Self {
        let spacing = 0.01;
        let strength = 1e6;
        Self {
            width: 1.1,
            height: 1.65,
            young: 1e9,
            strength,
            toughness: strength * (2.0 * PI * 3.0 * spacing).sqrt(),
            spacing,
            support: 2.0,
            discontinuity: Discontinuity::Visibility,
            resolution: 2e-3,
            resample: None,
        }
    }
}

/// What one plate measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Failure {
    /// Half-length `a` of the crack, m (as placed on the lattice).
    pub half_length: Real,
    /// Particles of the plate.
    pub particles: usize,
    /// The remote stress at which the front first ran, Pa (the middle of
    /// the final bracket).
    pub stress: Real,
    /// Griffith's failure stress with the width factor, Pa.
    pub griffith: Real,
    /// The point method's on Westergaard's field, with the width factor,
    /// Pa.
    pub point_method: Real,
    /// Static solves taken.
    pub solves: usize,
}

/// Why a measurement could not be made.
#[derive(Debug, thiserror::Error)]
pub enum GriffithError {
    /// The plate could not be built.
    #[error("the plate: {0}")]
    Build(String),
    /// No load up to the strength made the front run, or the least load
    /// already did.
    #[error("no bracket: the front {0}")]
    Bracket(&'static str),
}

impl Griffith {
    /// The point method's critical distance `K_Ic^2 / (2 pi sigma_0^2)`.
    pub fn critical_distance(&self) -> Real {
        self.threshold().critical_distance().unwrap_or(0.0)
    }

    /// The surface energy `gamma = K_Ic^2 / (2 E)` the toughness stands
    /// for (plane stress), J/m^2.
    pub fn surface_energy(&self) -> Real {
        self.toughness * self.toughness / (2.0 * self.young)
    }

    /// Griffith's failure stress for half-length `a` in this plate:
    /// `sqrt(2 E gamma / (pi a))` over Feddersen's `sqrt(sec(pi a / W))`.
    pub fn griffith(&self, a: Real) -> Real {
        self.infinite(a) * (PI * a / self.width).cos().sqrt()
    }

    /// Griffith's failure stress in an infinite plate,
    /// `sqrt(2 E gamma / (pi a))`.
    pub fn infinite(&self, a: Real) -> Real {
        (2.0 * self.young * self.surface_energy() / (PI * a)).sqrt()
    }

    /// The point method's failure stress: Griffith's times the point
    /// method's factor on Westergaard's field (module documentation).
    pub fn point_method(&self, a: Real) -> Real {
        let r = self.critical_distance();
        self.griffith(a) * ((2.0 * a * a + a * r) / (2.0 * (a + r) * (a + r))).sqrt()
    }

    fn threshold(&self) -> Threshold {
        Threshold::Toughness {
            stress: self.strength,
            toughness: self.toughness,
        }
    }

    /// The central crack of half-length `a`.
    pub fn central(a: Real) -> Notch {
        Notch {
            center: Vector::zeros(),
            normal: Vector::y(),
            radius: a,
        }
    }

    /// The plate cut by `notch`, unloaded.
    ///
    /// # Errors
    /// [`GriffithError::Build`] when the solid refuses the parameters.
    pub fn plate(&self, notch: Notch) -> Result<ElasticSolid, GriffithError> {
        self.plate_with(
            notch,
            Integrator::Implicit(ImplicitParams {
                linear_solver: LinearSolver::Cholesky,
                scheme: ImplicitScheme::Static,
                ..ImplicitParams::default()
            }),
        )
    }

    fn plate_with(
        &self,
        notch: Notch,
        integrator: Integrator,
    ) -> Result<ElasticSolid, GriffithError> {
        let params = SolidParams {
            dim: 2,
            spacing: self.spacing,
            density: DENSITY,
            young: self.young,
            material: Material::from_young_poisson(self.young, 0.0, 0.0),
            order: Order::Linear,
            support: self.support * self.spacing,
            hourglass: 0.1,
            damping: 0.0,
            friction: 0.0,
            integrator,
            plasticity: None,
            fracture: Some(FractureParams {
                threshold: self.threshold(),
                discontinuity: self.discontinuity,
                advance: FractureParams::DEFAULT_ADVANCE,
                max_cracks: 4,
                branching: None,
                resample: self.resample,
                surface_cell: FractureParams::DEFAULT_SURFACE_CELL,
            }),
        };
        let shape = Shape::Box {
            half_extents: Vector::new(0.5 * self.width, 0.5 * self.height, 0.0),
        };
        let rest = shape
            .sample_volume(self.spacing, 2)
            .ok_or_else(|| GriffithError::Build("no particles".into()))?;
        let grip = 0.5 * self.height - 2.0 * self.spacing;
        let fixed: Vec<bool> = rest.iter().map(|x| x.y.abs() > grip).collect();
        let n = rest.len();
        let mut solid = ElasticSolid::new(
            params,
            rest,
            vec![Vector::zeros(); n],
            fixed,
            Obstacles::default(),
        )
        .map_err(|e| GriffithError::Build(e.to_string()))?;
        solid
            .notch(&[notch])
            .map_err(|e| GriffithError::Build(e.to_string()))?;
        solid
            .resample()
            .map_err(|e| GriffithError::Build(e.to_string()))?;
        Ok(solid)
    }

    /// Loads `plate` statically to the grips' strain `strain` (each
    /// particle starting from the uniform stretch) and returns the remote
    /// stress and whether the solid's fracture update runs a front.
    fn load(&self, plate: &ElasticSolid, strain: Real) -> (Real, bool) {
        let mut solid = plate.clone();
        let sigma = self.stretch(&mut solid, strain);
        let runs = solid.fracture_step().is_ok_and(|step| step.advanced > 0);
        (sigma, runs)
    }

    /// The plate cut by `notch` in static equilibrium with its grips at
    /// `strain`, and the remote stress.
    ///
    /// # Errors
    /// [`GriffithError::Build`] when the solid refuses the parameters.
    pub fn loaded(
        &self,
        notch: Notch,
        strain: Real,
    ) -> Result<(ElasticSolid, Real), GriffithError> {
        let mut solid = self.plate(notch)?;
        let stress = self.stretch(&mut solid, strain);
        Ok((solid, stress))
    }

    /// Solves `solid` statically with its grips at `strain` from the
    /// uniform stretch, and returns the remote stress.
    fn stretch(&self, solid: &mut ElasticSolid, strain: Real) -> Real {
        let rest = solid.rest_positions().to_vec();
        for (x, x0) in solid.positions.iter_mut().zip(&rest) {
            *x = x0 + Vector::new(0.0, strain * x0.y, 0.0);
        }
        solid.step(1.0, &Vector::zeros(), 1);
        let forces = solid.forces();
        let pull: Real = (0..solid.len())
            .filter(|&i| solid.is_fixed(i) && rest[i].y > 0.0)
            .map(|i| -forces[i].y)
            .sum();
        pull / self.width
    }

    /// The remote stress at which the front of a crack of half-length
    /// about `a` first runs, bracketed by bisection on the grips' strain
    /// to [`Self::resolution`].
    ///
    /// The half-length is moved to the nearest that puts each tip a
    /// quarter spacing past a column of particles (the particles sit at
    /// half-integer spacings), and the references are taken at it: a tip
    /// midway between two columns lies exactly on the diagonal pairs'
    /// segments, where rounding alone would decide whether they are cut,
    /// a difference of half a spacing in the crack's length.
    ///
    /// # Errors
    /// [`GriffithError`] when the plate cannot be built or no load below
    /// the strength runs the front.
    pub fn failure(&self, a: Real) -> Result<Failure, GriffithError> {
        let s = self.spacing;
        let a = ((a / s - 0.75).round() + 0.75) * s;
        let plate = self.plate(Self::central(a))?;
        let (stress, _, solves) = self.bracket(&plate)?;
        Ok(Failure {
            half_length: a,
            particles: plate.len(),
            stress,
            griffith: self.griffith(a),
            point_method: self.point_method(a),
            solves,
        })
    }

    /// The least remote stress and grip strain at which a front of
    /// `plate` runs, and the static solves it took.
    fn bracket(&self, plate: &ElasticSolid) -> Result<(Real, Real, usize), GriffithError> {
        let mut solves = 0;
        let mut at = |strain: Real| {
            solves += 1;
            self.load(plate, strain)
        };
        // The strain at which the unnotched plate bears the strength.
        let (mut lo, mut hi) = (0.0, self.strength / self.young);
        let (top, runs) = at(hi);
        if !runs {
            return Err(GriffithError::Bracket("did not run at the strength"));
        }
        let mut stress = (0.0, top);
        while hi - lo > self.resolution * hi {
            let mid = 0.5 * (lo + hi);
            let (sigma, runs) = at(mid);
            if runs {
                hi = mid;
                stress.1 = sigma;
            } else {
                lo = mid;
                stress.0 = sigma;
            }
        }
        if lo == 0.0 {
            return Err(GriffithError::Bracket("ran at every load tried"));
        }
        Ok((0.5 * (stress.0 + stress.1), hi, solves))
    }

    /// Mode I from `notch`, loaded quasi-statically under displacement
    /// control: the grips start at the strain at which its front first
    /// runs; each of at most `steps` static steps is followed by the
    /// fracture update, and a step in which no front ran raises the
    /// grips' strain by 1 %. Stops once the notch's tip has run `length`
    /// metres or a part split off.
    ///
    /// # Errors
    /// [`GriffithError`] when the plate cannot be built or no load below
    /// the strength runs the front.
    pub fn notched(
        &self,
        notch: Notch,
        length: Real,
        steps: usize,
    ) -> Result<NotchRun, GriffithError> {
        let mut solid = self.plate(notch)?;
        let (stress, mut strain, _) = self.bracket(&solid)?;
        let mut run = NotchRun {
            failure: stress,
            failure_strain: strain,
            paths: solid.fracture().map_or_else(Vec::new, |f| {
                f.cracks()[0].front().iter().map(|n| vec![n.at]).collect()
            }),
            ..NotchRun::default()
        };
        for _ in 0..steps {
            run.last_stress = self.stretch(&mut solid, strain);
            let step = solid
                .fracture_step()
                .map_err(|e| GriffithError::Build(e.to_string()))?;
            run.started += step.started;
            run.advances += step.advanced;
            run.steps += 1;
            if step.advanced == 0 {
                strain *= 1.01;
            }
            let Some(fracture) = solid.fracture() else {
                break;
            };
            let front = fracture.cracks()[0].front();
            run.paths.resize(front.len(), Vec::new());
            for (path, node) in run.paths.iter_mut().zip(front) {
                if path.last() != Some(&node.at) {
                    path.push(node.at);
                }
            }
            run.fragments = fracture.fragment_count();
            if run.fragments > 1 || run.ran() >= length {
                break;
            }
        }
        Ok(run)
    }
}

impl Griffith {
    /// The plate cut by `notch` in static equilibrium with its grips at
    /// `strain` (below [`NotchRun::failure_strain`]: a plate held below
    /// its threshold), then stepped dynamically (explicit, from rest
    /// there) for `updates` steps of the time an elastic wave takes to
    /// cross four spacings, each followed by the fracture update. Returns
    /// the cracks started and the front advances.
    ///
    /// # Errors
    /// [`GriffithError`] when the plate cannot be built.
    pub fn hold(
        &self,
        notch: Notch,
        strain: Real,
        updates: usize,
    ) -> Result<(u32, u32), GriffithError> {
        let (statics, _) = self.loaded(notch, strain)?;
        let mut solid = self.plate_with(notch, Integrator::Explicit { cfl: 0.5 })?;
        solid.positions.clone_from(&statics.positions);
        let wave = (self.young / DENSITY).sqrt();
        let dt = 4.0 * self.spacing / wave;
        let (mut started, mut advanced) = (0, 0);
        for _ in 0..updates {
            solid.step(dt, &Vector::zeros(), 1000);
            let step = solid
                .fracture_step()
                .map_err(|e| GriffithError::Build(e.to_string()))?;
            started += step.started;
            advanced += step.advanced;
        }
        Ok((started, advanced))
    }
}

/// How rough the strain field is at a crack's tips ([`Griffith::roughness`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Roughness {
    /// The largest jump of the displacement gradient between adjacent
    /// particles on the same side of the crack, within two spacings of a
    /// tip, over the grips' strain.
    pub beside: Real,
    /// The same across the line the crack would run on, ahead of a tip:
    /// where the visibility criterion leaves a line of discontinuity
    /// beyond the front (the tutorial's Figure 9).
    pub ahead: Real,
}

impl Griffith {
    /// Transparency against visibility (the tutorial's Figures 9 and 10):
    /// the plate with a central crack of half-length `a` held statically
    /// at the grips' `strain`, and the [`Roughness`] of its strain field
    /// at the tips. The displacement gradient is what the shape
    /// functions' derivatives make of the displacements, so a kink in
    /// them shows as a jump between neighbours.
    ///
    /// # Errors
    /// [`GriffithError::Build`] when the solid refuses the parameters.
    pub fn roughness(&self, a: Real, strain: Real) -> Result<Roughness, GriffithError> {
        let (solid, _) = self.loaded(Self::central(a), strain)?;
        let mut gradients = Vec::new();
        solid.displacement_gradients(&mut gradients);
        let rest = solid.rest_positions();
        let s = self.spacing;
        let near: Vec<usize> = (0..rest.len())
            .filter(|&i| (rest[i].x.abs() - a).hypot(rest[i].y) < 2.0 * s)
            .collect();
        let mut roughness = Roughness {
            beside: 0.0,
            ahead: 0.0,
        };
        for (k, &i) in near.iter().enumerate() {
            for &j in &near[k + 1..] {
                if (rest[i] - rest[j]).norm() > 1.01 * s {
                    continue;
                }
                let jump = (gradients[i] - gradients[j]).norm() / strain;
                if rest[i].y * rest[j].y > 0.0 {
                    roughness.beside = roughness.beside.max(jump);
                } else if rest[i].x.abs() > a && rest[j].x.abs() > a {
                    roughness.ahead = roughness.ahead.max(jump);
                }
            }
        }
        Ok(roughness)
    }
}

/// Where a notch's crack went ([`Griffith::notched`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NotchRun {
    /// The remote stress at which the notch's front first ran, Pa.
    pub failure: Real,
    /// The grips' strain at that stress.
    pub failure_strain: Real,
    /// Each front node of the notch's crack, where it was after each step
    /// that moved it, from where it began (the notch's tips).
    pub paths: Vec<Vec<Vector>>,
    /// Cracks started anywhere else.
    pub started: u32,
    /// Front node advances, all cracks.
    pub advances: u32,
    /// Fragments at the end.
    pub fragments: u32,
    /// Static steps taken.
    pub steps: usize,
    /// The remote stress of the last step, Pa.
    pub last_stress: Real,
}

impl NotchRun {
    /// How far the tip that ran farthest ran, m.
    pub fn ran(&self) -> Real {
        self.paths
            .iter()
            .filter_map(|p| Some((p.last()? - p.first()?).norm()))
            .fold(0.0, Real::max)
    }

    /// The angle, degrees from the `x` axis (the load pulls along `y`),
    /// of the last `length` metres of each tip's path that ran as far;
    /// the one farthest from 0.
    pub fn final_angle(&self, length: Real) -> Option<Real> {
        self.paths
            .iter()
            .filter_map(|path| {
                let end = *path.last()?;
                let start = path.iter().rev().find(|p| (end - *p).norm() >= length)?;
                let d = end - start;
                Some(d.y.atan2(d.x.abs()).to_degrees())
            })
            .max_by(|a, b| a.abs().total_cmp(&b.abs()))
    }
}
