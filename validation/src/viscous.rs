//! Analytic solutions of unsteady viscous flows, the references of the
//! viscous term and of no-slip walls (tests/tests/validation_viscous.rs).
//!
//! - Start-up Poiseuille flow between plates `y = 0` and `y = L`, driven
//!   from rest by a body force `F` along x (Morris, Fox & Zhu 1997, Eq. 21):
//!
//!   ```text
//!   u(y, t) = F / (2 nu) y (L - y)
//!           - sum_n 4 F L^2 / (nu pi^3 (2n+1)^3) sin((2n+1) pi y / L)
//!             exp(-(2n+1)^2 pi^2 nu t / L^2)
//!   ```
//!
//! - Start-up Couette flow, the plate at `y = L` set moving at `V` along x
//!   at `t = 0` (Morris et al. 1997, Eq. 22):
//!
//!   ```text
//!   u(y, t) = V y / L + sum_n 2 V (-1)^n / (n pi) sin(n pi y / L)
//!             exp(-n^2 pi^2 nu t / L^2)
//!   ```
//!
//! - Spin-down of a fluid in rigid rotation `u = Omega r` inside a circular
//!   container of radius `R` stopped at `t = 0` (the Bessel-series solution
//!   of `u_t = nu (u_rr + u_r / r - u / r^2)` with `u(R) = 0`; e.g. Batchelor
//!   1967, Section 4.3), with `j_n` the positive zeros of `J_1`:
//!
//!   ```text
//!   u(r, t) = sum_n -2 Omega R / (j_n J_0(j_n)) J_1(j_n r / R) exp(-nu j_n^2 t / R^2)
//!   L(t) / L(0) = sum_n 8 / j_n^2 exp(-nu j_n^2 t / R^2)
//!   ```
//!
//!   (the angular momentum per unit depth; `sum_n 1 / j_n^2 = 1 / 8`).
//!
//! The series run until their terms fall below 1e-15 of the leading one,
//! at most [`MAX_TERMS`].

use meshless_engine::math::Real;
use std::f64::consts::PI;

/// Most terms of any series here: enough for 1e-12 at `t = 0` only in the
/// Poiseuille sum; at `t > 0` the exponentials end every sum far sooner.
pub const MAX_TERMS: usize = 2000;

/// Start-up Poiseuille flow: the velocity along the plates at height `y`
/// (`0 <= y <= l`) and time `t`, for body force `force` (m/s^2) and
/// kinematic viscosity `nu`.
pub fn poiseuille(y: Real, t: Real, l: Real, force: Real, nu: Real) -> Real {
    let steady = force / (2.0 * nu) * y * (l - y);
    let mut transient = 0.0;
    for n in 0..MAX_TERMS {
        let k = (2 * n + 1) as Real;
        let decay = (-k * k * PI * PI * nu * t / (l * l)).exp();
        let term = 4.0 * force * l * l / (nu * PI.powi(3) * k.powi(3)) * decay;
        transient += term * (k * PI * y / l).sin();
        if term.abs() < 1e-15 * steady.abs().max(Real::MIN_POSITIVE) {
            break;
        }
    }
    steady - transient
}

/// Start-up Couette flow: the velocity at height `y` and time `t` with the
/// upper plate moving at `speed`.
pub fn couette(y: Real, t: Real, l: Real, speed: Real, nu: Real) -> Real {
    let mut sum = speed * y / l;
    for n in 1..=MAX_TERMS {
        let k = n as Real;
        let term = 2.0 * speed / (k * PI) * (-k * k * PI * PI * nu * t / (l * l)).exp();
        let sign = if n % 2 == 0 { 1.0 } else { -1.0 };
        sum += sign * term * (k * PI * y / l).sin();
        if term < 1e-15 * speed.abs() {
            break;
        }
    }
    sum
}

/// `J_n(x)` for `n = 0, 1` from Bessel's integral
/// `(1 / pi) int_0^pi cos(n tau - x sin tau) d tau`, whose periodic
/// integrand the trapezoidal rule integrates to round-off with a few more
/// points than `|x|`.
pub fn bessel_j(n: u32, x: Real) -> Real {
    let points = 64 + 2 * x.abs().ceil() as usize;
    let h = PI / points as Real;
    // Trapezoid over [0, pi]: the ends count half.
    let f = |tau: Real| (n as Real * tau - x * tau.sin()).cos();
    let inner: Real = (1..points).map(|k| f(k as Real * h)).sum();
    (inner + 0.5 * (f(0.0) + f(PI))) * h / PI
}

/// The first `count` positive zeros of `J_1`, by Newton's method from
/// McMahon's asymptotic estimate `beta - 3 / (8 beta)`,
/// `beta = (n + 1/4) pi`.
pub fn bessel_j1_zeros(count: usize) -> Vec<Real> {
    (1..=count)
        .map(|n| {
            let beta = (n as Real + 0.25) * PI;
            let mut x = beta - 3.0 / (8.0 * beta);
            for _ in 0..50 {
                // J_1' = J_0 - J_1 / x.
                let j1 = bessel_j(1, x);
                let step = j1 / (bessel_j(0, x) - j1 / x);
                x -= step;
                if step.abs() < 1e-14 * x {
                    break;
                }
            }
            x
        })
        .collect()
}

/// The spin-down of a fluid in rigid rotation at `omega` in a container
/// of `radius`, evaluated with the zeros of `J_1` it was made with.
#[derive(Debug, Clone)]
pub struct SpinDown {
    omega: Real,
    radius: Real,
    nu: Real,
    /// Zeros `j_n` with `J_0(j_n)`.
    modes: Vec<(Real, Real)>,
}

impl SpinDown {
    /// The spin-down with `terms` Bessel modes (a hundred give the
    /// velocity to 1e-3 of `omega R` at `t = 0`, far better later).
    pub fn new(omega: Real, radius: Real, nu: Real, terms: usize) -> Self {
        let modes = bessel_j1_zeros(terms)
            .into_iter()
            .map(|j| (j, bessel_j(0, j)))
            .collect();
        Self {
            omega,
            radius,
            nu,
            modes,
        }
    }

    /// The azimuthal velocity at radius `r` and time `t`.
    pub fn velocity(&self, r: Real, t: Real) -> Real {
        let (omega, radius, nu) = (self.omega, self.radius, self.nu);
        self.modes
            .iter()
            .map(|&(j, j0)| {
                -2.0 * omega * radius / (j * j0)
                    * bessel_j(1, j * r / radius)
                    * (-nu * j * j * t / (radius * radius)).exp()
            })
            .sum()
    }

    /// The angular momentum left at time `t`, as a fraction of the start's.
    pub fn angular_momentum(&self, t: Real) -> Real {
        let decay = self.nu * t / (self.radius * self.radius);
        self.modes
            .iter()
            .map(|&(j, _)| 8.0 / (j * j) * (-decay * j * j).exp())
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bessel functions against Abramowitz & Stegun Table 9.1 and the
    /// zeros of `J_1` against Table 9.5.
    #[test]
    fn bessel_functions_match_the_tables() {
        assert!((bessel_j(0, 1.0) - 0.765_197_686_557_966_6).abs() < 1e-14);
        assert!((bessel_j(1, 1.0) - 0.440_050_585_744_933_5).abs() < 1e-14);
        assert!((bessel_j(0, 10.0) - -0.245_935_764_451_348_3).abs() < 1e-14);
        assert!((bessel_j(1, 10.0) - 0.043_472_746_168_861_44).abs() < 1e-14);
        let zeros = bessel_j1_zeros(5);
        let table = [
            3.831_705_970,
            7.015_586_670,
            10.173_468_135,
            13.323_691_936,
            16.470_630_051,
        ];
        for (z, t) in zeros.iter().zip(table) {
            assert!((z - t).abs() < 1e-8, "{z} against {t}");
        }
    }

    /// Each series starts from rest (or rigid rotation) and ends at its
    /// steady state, and the angular momentum series starts at exactly 1
    /// (`sum 1 / j_n^2 = 1 / 8`).
    #[test]
    fn series_meet_their_initial_and_final_states() {
        let (l, f, nu) = (1.0, 1.0, 1.0);
        for y in [0.1, 0.25, 0.5, 0.9] {
            assert!(poiseuille(y, 0.0, l, f, nu).abs() < 1e-6, "{y}");
            let steady = f / (2.0 * nu) * y * (l - y);
            assert!((poiseuille(y, 10.0, l, f, nu) - steady).abs() < 1e-12);
            assert!(couette(y, 0.0, l, 1.0, nu).abs() < 2e-3, "{y}");
            assert!((couette(y, 10.0, l, 1.0, nu) - y).abs() < 1e-12);
        }
        // 400 terms leave out `sum_(n > 400) 8 / j_n^2`, about
        // `8 / (pi^2 400)` = 2.0e-3.
        let spin = SpinDown::new(2.0, 0.2, 0.01, 400);
        assert!((spin.angular_momentum(0.0) - 1.0).abs() < 2.5e-3);
        for r in [0.02, 0.1, 0.18] {
            assert!((spin.velocity(r, 0.0) - 2.0 * r).abs() < 0.02 * 0.4, "{r}");
        }
        assert!(spin.angular_momentum(10.0) < 1e-6);
    }
}
