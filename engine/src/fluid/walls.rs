//! The walls of the domain box as solid boundaries.
//!
//! A fluid particle near a wall misses the neighbours the wall occupies, so
//! its density sum falls short and nothing pushes it off the wall except
//! reflection. The tutorial's remedy is ghost particles sampled inside the
//! solid, counted in the density sum (Eq. 55) and pushing back through the
//! pressure gradient. For the planar walls of a box their sum depends only
//! on the distance `d` to the wall, so it is tabulated once:
//!
//! `Phi(d) = sum_k dx P(d + (k + 1/2) dx)` with `P(z) = 2 pi int_z^h w(r) r dr`,
//!
//! which is the lattice of ghost particles continuing the fluid's own
//! lattice (layers at `dx/2, 3dx/2, …` behind the wall, spacing `dx`),
//! integrated exactly along the wall. A particle at distance `d` then gains
//! density `(m / dx^3) Phi(d)` and the pressure acceleration
//! `-(m / dx^3) (p_i / rho_i^2) Phi_g'(d) n` (`Phi_g` uses the gradient
//! kernel; `n` is the wall's inward normal), the wall's share of
//! `-(p_i / rho_i^2) grad rho_i` as in Akinci et al. 2012. That is the force
//! the wall's density term implies, so walls neither gain nor lose energy.
//! DFSPH pushes off the walls this way (through [`BoxWalls::density_gradient`]).
//!
//! That one-sided push is half of what a particle's own symmetric pair
//! terms miss on the wall's side, so under a uniform pressure it nets a
//! push into the wall: a settled column's floor row sat at 0.2 spacings
//! instead of 0.5 and held the column at 1.8 times its hydrostatic
//! pressure (`validation_tank::floor_rows_read_the_hydrostatic_pressure`).
//! Mirroring the particle's own pressure onto the ghosts (the symmetric
//! form of Eq. 51), even with Adami, Hu & Adams's (2012) hydrostatic
//! correction, balances it (floor row within 9 % of `rho_0 g d`) but is no
//! force of any energy: an undamped tank gained 12 % of its energy scale
//! in 0.15 s and faulted. WCSPH therefore uses the fluid's mirror images
//! instead ([`BoxWalls::mirrors`], Monaghan's mirror particles): every
//! neighbour `j` of a particle near a wall also stands reflected across
//! it, at its own pressure and in the density sum, so the walls are the
//! fluid continued by symmetry. The images enter the density and the
//! symmetric pressure force alike, which makes them the exact gradient of
//! the fluid's energy `sum_k m e(rho_k)`: walls still neither gain nor
//! lose energy, and a uniform pressure balances (floor row within 1 % of
//! `rho_0 g d`). Reflections across two or three walls fill edges and
//! corners. Walls take no part in XSPH.
//!
//! Walls are free-slip unless the scene makes them no-slip. Then the ghost
//! lattice also carries velocity, extrapolated as Morris et al. (1997) do
//! so that the flow meets the wall's velocity at the wall: a ghost at depth
//! `d_g` behind a wall seen from a particle at distance `d` moves relative
//! to the wall at `-(d_g / d)` times the particle's relative velocity,
//! making the pair's relative velocity `beta = 1 + d_g / d` times the
//! particle's (with `d` bounded below by half a spacing rather than their
//! cap on `beta`; see `extrapolation`). The ghosts act through the
//! fluid's own pair form (see `viscosity.rs`), so that the wall is the
//! fluid continued: Monaghan's form along the pair, or Morris's along the
//! velocity difference (also standing in for the kernel-Laplacian form,
//! which pushes along it too). Either sum over a planar lattice is again
//! a function of `d` alone, in two tables: one for the velocity along the
//! wall and one across it.

use super::ViscosityModel;
use crate::approx::Kernel;
use crate::approx::layers::{extrapolation, friction_layer, integrate};
use crate::math::{Real, Vector};
use std::f64::consts::PI;

/// Samples of the tables over `[0, h]`.
const SAMPLES: usize = 512;

/// Tabulated ghost-layer sums of one wall, as functions of distance.
#[derive(Debug, Clone)]
pub struct BoxWalls {
    min: Vector,
    max: Vector,
    h: Real,
    /// Axes with walls: x, y and z, less z for a planar (2D) fluid and
    /// less the periodic axes.
    walled: [bool; 3],
    /// `Phi(d)` with the density kernel, times `m / dx^3`: the density a
    /// wall adds at distance `d`.
    density: Vec<Real>,
    /// `Phi_g'(d)` with the gradient kernel, times `m / dx^3`.
    slope: Vec<Real>,
    /// No-slip walls' friction, when the scene asks for it.
    friction: Option<Friction>,
}

/// The friction of no-slip walls (see the module documentation).
#[derive(Debug, Clone)]
struct Friction {
    /// Ghost-lattice sum, times `m / dx^3`, of Monaghan's
    /// `2 (d + 2) beta x_t^2 W'(r) / (r (r^2 + eta^2))` for one tangential
    /// component, or Morris's `2 beta r W'(r) / (r^2 + eta^2)`.
    tangential: Vec<Real>,
    /// The same with the normal component `x_n^2` in Monaghan's form;
    /// Morris's is isotropic, the same as `tangential`.
    normal: Vec<Real>,
    /// Each wall's velocity, `[axis][0 below, 1 above]`.
    velocity: [[Vector; 2]; 3],
}

/// `P(z)`: the kernel integrated over the plane (3D) or line (2D) at
/// distance `z`.
fn layer_integral(kernel: &Kernel, z: Real) -> Real {
    let h = kernel.support();
    if z >= h {
        return 0.0;
    }
    if kernel.dim() == 2 {
        2.0 * integrate(0.0, (h * h - z * z).sqrt(), |s| {
            kernel.value((s * s + z * z).sqrt())
        })
    } else {
        2.0 * PI * integrate(z, h, |r| kernel.value(r) * r)
    }
}

/// `dP/dz`: in 3D `-2 pi w(z) z`; in 2D
/// `2 int_0^sqrt(h^2 - z^2) w'(r) z / r ds` with `r = sqrt(s^2 + z^2)`.
fn layer_slope(kernel: &Kernel, z: Real) -> Real {
    let h = kernel.support();
    if z >= h {
        return 0.0;
    }
    if kernel.dim() == 2 {
        2.0 * integrate(0.0, (h * h - z * z).sqrt(), |s| {
            let r = (s * s + z * z).sqrt();
            if r > 0.0 {
                kernel.derivative(r) * z / r
            } else {
                0.0
            }
        })
    } else {
        -2.0 * PI * kernel.value(z) * z
    }
}

impl BoxWalls {
    /// Walls of the box `[min, max]` for a fluid sampled at `spacing` with
    /// particle `mass`.
    pub fn new(
        min: Vector,
        max: Vector,
        spacing: Real,
        mass: Real,
        density_kernel: &Kernel,
        gradient_kernel: &Kernel,
    ) -> Self {
        let h = density_kernel.support();
        let axes = density_kernel.dim();
        let per_volume = mass / spacing.powi(axes as i32);
        let layers = (h / spacing).ceil() as usize + 1;
        let sample = |i: usize| h * i as Real / (SAMPLES - 1) as Real;
        let layer_sum = |d: Real, term: &dyn Fn(Real) -> Real| {
            (0..layers)
                .map(|k| spacing * term(d + (k as Real + 0.5) * spacing))
                .sum::<Real>()
        };
        let density = (0..SAMPLES)
            .map(|i| per_volume * layer_sum(sample(i), &|z| layer_integral(density_kernel, z)))
            .collect();
        // d/dz P(z) = -2 pi w(z) z.
        let slope = (0..SAMPLES)
            .map(|i| per_volume * layer_sum(sample(i), &|z| layer_slope(gradient_kernel, z)))
            .collect();
        Self {
            min,
            max,
            h,
            walled: [true, true, axes == 3],
            density,
            slope,
            friction: None,
        }
    }

    /// Makes the walls no-slip for a fluid sampled at `spacing` with
    /// particle `mass`, viscous through `model` with `gradient_kernel`;
    /// `velocity` gives each wall's (tangential) velocity, `[axis][0
    /// below, 1 above]`.
    pub fn with_friction(
        mut self,
        spacing: Real,
        mass: Real,
        gradient_kernel: &Kernel,
        model: ViscosityModel,
        velocity: [[Vector; 2]; 3],
    ) -> Self {
        let axes = gradient_kernel.dim();
        let per_volume = mass / spacing.powi(axes as i32);
        // A layer's `(int x_t^2 g, int z^2 g)` as the pair form weighs it:
        // Monaghan's projects onto the pair (`2 (d + 2)` restores the
        // Laplacian); Morris's `2 r^2 g` sums every component of `r^2`.
        let weigh = |(t, n): (Real, Real)| match model {
            ViscosityModel::Monaghan => {
                let projected = 2.0 * (axes as Real + 2.0);
                (projected * t, projected * n)
            }
            ViscosityModel::Morris | ViscosityModel::KernelLaplacian => {
                let isotropic = 2.0 * ((axes - 1) as Real * t + n);
                (isotropic, isotropic)
            }
        };
        let layers = (self.h / spacing).ceil() as usize + 1;
        let sample = |i: usize| self.h * i as Real / (SAMPLES - 1) as Real;
        let sums: Vec<(Real, Real)> = (0..SAMPLES)
            .map(|i| {
                let d = sample(i);
                (0..layers).fold((0.0, 0.0), |(t, n), k| {
                    let depth = (k as Real + 0.5) * spacing;
                    let beta = extrapolation(depth, d, spacing);
                    let (lt, ln) = weigh(friction_layer(gradient_kernel, d + depth));
                    let scale = per_volume * spacing * beta;
                    (t + scale * lt, n + scale * ln)
                })
            })
            .collect();
        self.friction = Some(Friction {
            tangential: sums.iter().map(|s| s.0).collect(),
            normal: sums.iter().map(|s| s.1).collect(),
            velocity,
        });
        self
    }

    /// Whether the walls are no-slip.
    pub fn no_slip(&self) -> bool {
        self.friction.is_some()
    }

    /// Whether a no-slip wall moves (and so can drive the fluid).
    pub fn moving(&self) -> bool {
        self.friction
            .as_ref()
            .is_some_and(|f| f.velocity.iter().flatten().any(|v| *v != Vector::zeros()))
    }

    /// Removes the walls of the `open` axes (periodic axes have none).
    pub fn without_axes(mut self, open: [bool; 3]) -> Self {
        for (walled, open) in self.walled.iter_mut().zip(open) {
            *walled &= !open;
        }
        self
    }

    /// Linear interpolation in a table at distance `d`.
    #[inline]
    fn lookup(&self, table: &[Real], d: Real) -> Real {
        if d >= self.h {
            return 0.0;
        }
        let x = d.max(0.0) / self.h * (SAMPLES - 1) as Real;
        let i = (x as usize).min(SAMPLES - 2);
        let t = x - i as Real;
        table[i] * (1.0 - t) + table[i + 1] * t
    }

    /// Calls `visit(d, n, [axis, side])` for every wall within the
    /// support radius of `x`: its distance, inward normal and place (side
    /// 0 below, 1 above).
    #[inline]
    fn near(&self, x: &Vector, mut visit: impl FnMut(Real, Vector, [usize; 2])) {
        for a in (0..3).filter(|&a| self.walled[a]) {
            let mut n = Vector::zeros();
            let below = x[a] - self.min[a];
            if below < self.h {
                n[a] = 1.0;
                visit(below, n, [a, 0]);
            }
            let above = self.max[a] - x[a];
            if above < self.h {
                n[a] = -1.0;
                visit(above, n, [a, 1]);
            }
        }
    }

    /// The density the walls add at `x`.
    #[inline]
    pub fn density(&self, x: &Vector) -> Real {
        let mut rho = 0.0;
        self.near(x, |d, _, _| rho += self.lookup(&self.density, d));
        rho
    }

    /// Gradient of the density the walls add at `x` (with the gradient
    /// kernel): it points into the nearby walls.
    #[inline]
    pub fn density_gradient(&self, x: &Vector) -> Vector {
        let mut gradient = Vector::zeros();
        self.near(x, |d, n, _| gradient += n * self.lookup(&self.slope, d));
        gradient
    }

    /// The no-slip walls' friction on a particle at `x` moving at `v`,
    /// to be scaled by `mu / (rho_i rho_0)`; zero for free-slip walls.
    #[inline]
    pub fn friction(&self, x: &Vector, v: &Vector) -> Vector {
        let Some(friction) = &self.friction else {
            return Vector::zeros();
        };
        let mut sum = Vector::zeros();
        self.near(x, |d, n, [axis, side]| {
            let relative = v - friction.velocity[axis][side];
            let across = relative.dot(&n);
            let along = relative - n * across;
            sum += along * self.lookup(&friction.tangential, d)
                + n * (across * self.lookup(&friction.normal, d));
        });
        sum
    }

    /// The mirror images the walls near `x` cast (Monaghan's "mirror
    /// particles"): every reflection across one wall near `x`, or across
    /// several of them on different axes (the images of the images that
    /// fill a corner). `visit` gets, per reflection, the planes
    /// `[axis] = Some(c)` it reflects across (`x_a -> 2 c - x_a`).
    #[inline]
    pub fn mirrors(&self, x: &Vector, mut visit: impl FnMut(&[Option<Real>; 3])) {
        // Per axis: no reflection, or across its lower or upper wall if near.
        let mut choices = [[None; 3]; 3];
        let mut counts = [1usize; 3];
        for a in (0..3).filter(|&a| self.walled[a]) {
            if x[a] - self.min[a] < self.h {
                choices[a][counts[a]] = Some(self.min[a]);
                counts[a] += 1;
            }
            if self.max[a] - x[a] < self.h {
                choices[a][counts[a]] = Some(self.max[a]);
                counts[a] += 1;
            }
        }
        for i in 0..counts[0] {
            for j in 0..counts[1] {
                for k in 0..counts[2] {
                    if i + j + k > 0 {
                        visit(&[choices[0][i], choices[1][j], choices[2][k]]);
                    }
                }
            }
        }
    }

    /// `x_i - S x_j` for the reflection `S` across `planes` (see
    /// [`Self::mirrors`]), from `r = x_i - x_j` (periodic along the
    /// unwalled axes) and the positions along the reflected ones.
    #[inline]
    pub fn mirrored(planes: &[Option<Real>; 3], r: &Vector, xi: &Vector, xj: &Vector) -> Vector {
        let mut image = *r;
        for (a, plane) in planes.iter().enumerate() {
            if let Some(c) = plane {
                image[a] = xi[a] + xj[a] - 2.0 * c;
            }
        }
        image
    }

    /// The pressure acceleration of the tabulated walls on a particle at
    /// `x` with pressure `p` and density `rho`: `-(p / rho^2) grad
    /// rho_wall`, the one-sided term (see the module documentation; WCSPH
    /// pushes through [`Self::mirrors`] instead).
    #[inline]
    pub fn pressure_acceleration(&self, x: &Vector, p: Real, rho: Real) -> Vector {
        -self.density_gradient(x) * (p / (rho * rho))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::approx::KernelKind;
    use crate::fluid::FluidParams;

    /// The tabulated wall must stand in for the fluid lattice it replaces:
    /// a lattice particle next to a wall, with the fluid's own neighbours
    /// on one side and the wall's table on the other, has the rest density
    /// (within the accuracy of integrating along the wall exactly rather
    /// than summing a lattice), in 2D and 3D.
    #[test]
    fn a_wall_completes_the_density_of_particles_beside_it() {
        let spacing = 0.02;
        for dim in [2, 3] {
            for kind in [
                KernelKind::Poly6,
                KernelKind::CubicSpline,
                KernelKind::WendlandC2,
            ] {
                let kernel = Kernel::new(kind, dim, 2.0 * spacing);
                let mass = FluidParams::lattice_mass(spacing, &kernel, 1000.0);
                let walls = BoxWalls::new(
                    Vector::zeros(),
                    Vector::repeat(1.0),
                    spacing,
                    mass,
                    &kernel,
                    &Kernel::new(KernelKind::Spiky, dim, 2.0 * spacing),
                );
                let depth = if dim == 2 { 0 } else { 3 };
                for layer in 0..3 {
                    // A particle in layer `layer` above the floor, far from other walls.
                    let y = (layer as Real + 0.5) * spacing;
                    let z = if dim == 2 { 0.0 } else { 0.5 };
                    let mut rho = walls.density(&Vector::new(0.5, y, z));
                    for i in -3..=3 {
                        for j in -3..=3 {
                            for k in -depth..=depth {
                                if y + j as Real * spacing > 0.0 {
                                    let d = Vector::new(i as Real, j as Real, k as Real) * spacing;
                                    rho += mass * kernel.value(d.norm());
                                }
                            }
                        }
                    }
                    assert!(
                        (rho - 1000.0).abs() < 5.0,
                        "{kind:?} in {dim}D, layer {layer}: density {rho} beside the wall"
                    );
                }
            }
        }
    }

    /// The walls' mirror images continue a lattice filling a corner of the
    /// box (rows at `dx/2, 3dx/2, …` from each wall) as the lattice itself:
    /// a particle in the first rows, beside one wall, two or three, has
    /// the rest density from its neighbours and their images, and a
    /// uniform pressure pushes it nowhere (the tabulated walls' one-sided
    /// push left it pressed into them). In 2D and 3D.
    #[test]
    fn mirror_images_complete_a_lattice_and_balance_a_uniform_pressure() {
        let spacing = 0.02;
        for dim in [2, 3] {
            let kernel = Kernel::new(KernelKind::CubicSpline, dim, 2.0 * spacing);
            let mass = FluidParams::lattice_mass(spacing, &kernel, 1000.0);
            let walls = BoxWalls::new(
                Vector::zeros(),
                Vector::repeat(1.0),
                spacing,
                mass,
                &kernel,
                &kernel,
            );
            let depth = if dim == 2 { 1 } else { 6 };
            let lattice: Vec<Vector> = (0..6)
                .flat_map(|i| (0..6).flat_map(move |j| (0..depth).map(move |k| (i, j, k))))
                .map(|(i, j, k)| {
                    let z = if dim == 2 {
                        0.0
                    } else {
                        (k as Real + 0.5) * spacing
                    };
                    Vector::new((i as Real + 0.5) * spacing, (j as Real + 0.5) * spacing, z)
                })
                .collect();
            let (p, rho) = (1000.0, 1000.0);
            for (i, xi) in lattice.iter().enumerate() {
                // The corner's first two rows: beside one wall, two or three.
                if (0..dim).any(|a| xi[a] > 2.0 * spacing) {
                    continue;
                }
                let mut density = 0.0;
                let mut push = Vector::zeros();
                let mut add = |r: Vector| {
                    density += mass * kernel.value(r.norm());
                    push -= kernel.gradient(&r, r.norm()) * (mass * 2.0 * p / (rho * rho));
                };
                for xj in &lattice {
                    add(xi - xj);
                }
                walls.mirrors(xi, |planes| {
                    for xj in &lattice {
                        add(BoxWalls::mirrored(planes, &(xi - xj), xi, xj));
                    }
                });
                assert!(
                    (density - 1000.0).abs() < 1e-6 * 1000.0,
                    "{dim}D, particle {i} at {xi:?}: density {density}"
                );
                // One neighbour's term, against which round-off is measured.
                let scale = kernel.derivative(spacing).abs() * mass * 2.0 * p / (rho * rho);
                assert!(
                    push.norm() < 1e-9 * scale,
                    "{dim}D, particle {i} at {xi:?}: a uniform pressure pushes it by {push:?}"
                );
            }
        }
    }

    /// Positive pressure pushes particles off every wall, and only walls
    /// within the support radius act.
    #[test]
    fn walls_push_inward_and_only_nearby() {
        let kernel = Kernel::new_3d(KernelKind::Poly6, 0.04);
        let walls = BoxWalls::new(
            Vector::zeros(),
            Vector::new(1.0, 2.0, 3.0),
            0.02,
            0.008,
            &kernel,
            &Kernel::new_3d(KernelKind::Spiky, 0.04),
        );
        let a = walls.pressure_acceleration(&Vector::new(0.01, 1.0, 2.99), 100.0, 1000.0);
        assert!(a.x > 0.0 && a.z < 0.0 && a.y == 0.0, "{a:?}");
        let centre = Vector::new(0.5, 1.0, 1.5);
        assert_eq!(walls.density(&centre), 0.0);
        assert_eq!(
            walls.pressure_acceleration(&centre, 100.0, 1000.0),
            Vector::zeros()
        );
    }

    /// The friction tables stand in for the ghost lattice they integrate:
    /// a particle at distance `d` from the floor moving at `v`, against the
    /// same sum taken over explicit ghost particles (spacing `dx` along the
    /// wall, layers at `dx/2, 3dx/2, …` behind it, each moving at
    /// `-(d_g / d) v` relative to the wall, `d` bounded below by half a
    /// spacing), in 2D and 3D, along the wall and across it, with the wall
    /// itself moving, in Monaghan's pair form and in Morris's.
    #[test]
    fn friction_tables_match_the_ghost_lattice_they_integrate() {
        let spacing = 0.02;
        for (dim, model) in [2, 3]
            .into_iter()
            .flat_map(|d| [(d, ViscosityModel::Monaghan), (d, ViscosityModel::Morris)])
        {
            let kernel = Kernel::new(KernelKind::CubicSpline, dim, 2.0 * spacing);
            let mass = FluidParams::lattice_mass(spacing, &kernel, 1000.0);
            let lid = Vector::new(0.3, 0.0, 0.0);
            let walls = BoxWalls::new(
                Vector::zeros(),
                Vector::repeat(1.0),
                spacing,
                mass,
                &kernel,
                &kernel,
            )
            .with_friction(
                spacing,
                mass,
                &kernel,
                model,
                [
                    [Vector::zeros(); 2],
                    [lid, Vector::zeros()],
                    [Vector::zeros(); 2],
                ],
            );
            let h = kernel.support();
            let eta2 = 0.01 * h * h;
            let projected = 2.0 * (dim as Real + 2.0);
            for d in [0.3 * spacing, 0.5 * spacing, 1.2 * spacing] {
                for v in [Vector::new(1.0, 0.0, 0.0), Vector::new(0.2, -0.5, 0.0)] {
                    let x = Vector::new(0.5, d, 0.5);
                    let relative = v - lid;
                    let reach = (h / spacing).ceil() as i64 + 1;
                    // Sub-lattices along the wall (the tables integrate
                    // along it exactly), the ghost layers as they are.
                    let fine = 8;
                    let depth_range = if dim == 2 {
                        0..=0
                    } else {
                        -reach * fine..=reach * fine
                    };
                    let cell = spacing.powi(dim as i32) / (fine as Real).powi(dim as i32 - 1);
                    let mut sum = Vector::zeros();
                    for k in 0..reach {
                        let depth = (k as Real + 0.5) * spacing;
                        let beta = extrapolation(depth, d, spacing);
                        for i in -reach * fine..=reach * fine {
                            for j in depth_range.clone() {
                                let ghost = Vector::new(
                                    x.x + i as Real * spacing / fine as Real,
                                    -depth,
                                    x.z + j as Real * spacing / fine as Real,
                                );
                                let r = x - ghost;
                                let rn = r.norm();
                                if rn >= h {
                                    continue;
                                }
                                let grad = kernel.gradient(&r, rn);
                                let pair = relative * beta;
                                sum += match model {
                                    ViscosityModel::Monaghan => {
                                        grad * (projected * pair.dot(&r) / (rn * rn + eta2))
                                    }
                                    _ => pair * (2.0 * r.dot(&grad) / (rn * rn + eta2)),
                                } * cell;
                            }
                        }
                    }
                    let lattice = sum * (mass / spacing.powi(dim as i32));
                    let table = walls.friction(&x, &v);
                    let scale = lattice.norm();
                    assert!(
                        (table - lattice).norm() < 0.03 * scale,
                        "{model:?} in {dim}D, d = {d}, v = {v:?}: table {table:?} against lattice {lattice:?}"
                    );
                    assert!(
                        table.dot(&relative) < 0.0,
                        "friction opposes the relative motion"
                    );
                }
            }
        }
    }
}
