//! A modal EFG cantilever (Guo–Qin's solids) under its own weight against
//! Timoshenko beam theory: what `meshless study --knob modal-*` sweeps.
//!
//! The beam is `L x H x H` with `L / H = 10`, clamped at `x = 0`, its
//! weight along `-y`. Timoshenko's static tip deflection under a uniform
//! load `q = rho g A` is `q L^4 / (8 E I) + q L^2 / (2 kappa G A)`, with
//! `I = H^4 / 12` and the shear coefficient `kappa = 10 (1 + nu) / (12 +
//! 11 nu)` of a rectangle (Cowper 1966). Two measurements:
//!
//! - **static**: the modal solution `u = sum_j Psi_j Psi_j^T f / lambda_j`
//!   of the kept modes (no time stepping): the discretisation's and the
//!   truncation's error;
//! - **released**: the beam released from rest and stepped with the
//!   modal integrator, damped, for `RELEASE_TIME`; its tip then (warping
//!   on or off, any step).

use meshless_engine::Cancel;
use meshless_engine::approx::mls::Order;
use meshless_engine::efg::{
    Dynamics, EfgParams, EfgSolid, FixedSurface, Material, ModalParams, ModalSolid,
    NonlinearSolver, NonlinearState,
};
use meshless_engine::geometry::{MeshSdf, TriMesh};
use meshless_engine::math::{Real, Vector};
use meshless_engine::modal::{Damping, Stabilization};
use std::time::Instant;

/// Seconds a released beam is stepped. Its mass damping `2 omega_1`
/// damps the first bending mode critically (`omega_1 = 32 rad/s` for the
/// default beam), so by then its motion has decayed by `e^(-omega_1 T)`,
/// about 1e-7, and every higher mode faster.
pub const RELEASE_TIME: Real = 0.5;

/// What a setting measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Measure {
    /// The modal static solution.
    Static,
    /// The released beam after [`RELEASE_TIME`].
    Released,
}

/// One cantilever and how it is discretised, reduced and stepped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModalCantilever {
    /// Length, m (the section is `length / 10` square).
    pub length: Real,
    /// Young's modulus, Pa.
    pub young: Real,
    /// Poisson's ratio.
    pub poisson: Real,
    /// kg/m^3.
    pub density: Real,
    /// Octant side, m.
    pub cell: Real,
    /// Support side over octant side.
    pub alpha: Real,
    /// Gauss points per axis of an integration cell.
    pub quadrature_order: usize,
    /// MLS basis.
    pub basis: Order,
    /// Modes kept.
    pub modes: usize,
    /// Modal warping.
    pub warping: bool,
    /// Reduced modes or the full nonlinear EFG (released beam only).
    pub dynamics: Dynamics,
    /// Time step of the released beam, s.
    pub dt: Real,
}

impl Default for ModalCantilever {
    /// A 1 m beam of a rubber-stiff solid (E = 100 MPa, nu = 0.3: it
    /// sags 1.5 % of its length, where linear theory holds) on 2.5 cm
    /// cells (4 across), 32 modes, warping, 60 steps per second.
    fn default() -> Self {
        Self {
            length: 1.0,
            young: 1e8,
            poisson: 0.3,
            density: 1000.0,
            cell: 0.025,
            alpha: 3.0,
            quadrature_order: 2,
            basis: Order::Linear,
            modes: 32,
            warping: true,
            dynamics: Dynamics::Modal,
            dt: 1.0 / 60.0,
        }
    }
}

/// What one run measured.
#[derive(Debug, Clone, PartialEq)]
pub struct ModalMeasured {
    /// Nodes of the octree.
    pub nodes: usize,
    /// Seconds to discretise, assemble and find the modes.
    pub precompute: Real,
    /// Milliseconds per step of the released beam (0 for the static
    /// measure).
    pub step_ms: Real,
    /// The tip's deflection, m (positive downward).
    pub deflection: Real,
    /// Timoshenko's.
    pub reference: Real,
    /// `deflection / reference - 1`.
    pub error: Real,
}

impl ModalCantilever {
    /// Timoshenko's static tip deflection under the beam's weight, m.
    pub fn timoshenko(&self) -> Real {
        let h = self.length / 10.0;
        let area = h * h;
        let q = self.density * 9.81 * area;
        let inertia = h.powi(4) / 12.0;
        let shear = self.young / (2.0 * (1.0 + self.poisson));
        let kappa = 10.0 * (1.0 + self.poisson) / (12.0 + 11.0 * self.poisson);
        q * self.length.powi(4) / (8.0 * self.young * inertia)
            + q * self.length.powi(2) / (2.0 * kappa * shear * area)
    }

    /// Builds the beam and measures its tip deflection.
    ///
    /// # Errors
    /// The engine's message when the discretisation or the modes fail.
    pub fn measure(&self, measure: Measure) -> Result<ModalMeasured, String> {
        let h = self.length / 10.0;
        let max = Vector::new(self.length, h / 2.0, h / 2.0);
        let min = Vector::new(0.0, -h / 2.0, -h / 2.0);
        let mesh = TriMesh::cuboid(min, max);
        let sdf = MeshSdf::new(&mesh).map_err(|e| e.to_string())?;
        let slack = Vector::repeat(1e-9 * self.length);
        let fixed = FixedSurface::of_mesh_in_box(
            &mesh.subdivided(3),
            &(min - slack),
            &Vector::new(slack.x, max.y + slack.y, max.z + slack.z),
        );
        let mut efg = EfgParams::new(self.cell);
        efg.alpha = self.alpha;
        efg.quadrature_order = self.quadrature_order;
        efg.basis = self.basis;
        // Euler–Bernoulli's first bending frequency, damped critically.
        let omega = 1.875_f64.powi(2) / self.length.powi(2)
            * (self.young * h.powi(2) / (12.0 * self.density)).sqrt();
        let params = ModalParams {
            dynamics: self.dynamics,
            efg,
            modes: self.modes,
            tolerance: 1e-10,
            warping: self.warping,
            damping: Damping::new(2.0 * omega, 0.0).map_err(|e| e.to_string())?,
            stabilization: Stabilization::new(0.0, 0.0).map_err(|e| e.to_string())?,
        };
        let material = Material {
            density: self.density,
            young: self.young,
            poisson: self.poisson,
        };
        let clock = Instant::now();
        let mut solid = ModalSolid::build(&sdf, &fixed, material, &params, None, &Cancel::new())
            .map_err(|e| e.to_string())?;
        let precompute = clock.elapsed().as_secs_f64();
        let tip = Vector::new(self.length, 0.0, 0.0);
        let g = Vector::new(0.0, -9.81, 0.0);
        let (deflection, step_ms) = match measure {
            Measure::Static if self.dynamics == Dynamics::Nonlinear => {
                return Err(
                    "the static measure reads the modes, which nonlinear dynamics has \
                            none of; measure the released beam"
                        .into(),
                );
            }
            Measure::Static => (-static_tip(&solid, &tip, &g)?, 0.0),
            Measure::Released => {
                let steps = (RELEASE_TIME / self.dt).ceil() as usize;
                let clock = Instant::now();
                for _ in 0..steps {
                    solid.step(self.dt, &g).map_err(|e| e.to_string())?;
                }
                let ms = clock.elapsed().as_secs_f64() * 1e3 / steps as Real;
                (
                    -tip_displacement(&solid, &tip, solid.displacements())?.y,
                    ms,
                )
            }
        };
        let reference = self.timoshenko();
        Ok(ModalMeasured {
            nodes: solid.len(),
            precompute,
            step_ms,
            deflection,
            reference,
            error: deflection / reference - 1.0,
        })
    }
}

/// The modal static solution's y displacement at `tip`.
fn static_tip(solid: &ModalSolid, tip: &Vector, g: &Vector) -> Result<Real, String> {
    let mut at_rest = solid.clone();
    at_rest
        .set_state(&solid.static_state(g))
        .map_err(|e| e.to_string())?;
    Ok(tip_displacement(&at_rest, tip, at_rest.displacements())?.y)
}

/// The displacement field at `tip`.
fn tip_displacement(solid: &ModalSolid, tip: &Vector, u: &[Vector]) -> Result<Vector, String> {
    let table = solid
        .efg()
        .shape_table(std::slice::from_ref(tip))
        .map_err(|e| e.to_string())?;
    let mut at = Vec::new();
    table.interpolate(u, &mut at);
    Ok(at[0])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The figure's data (`meshless study --knob modal-dynamics`): at 1 and
    /// 4 times its weight the nonlinear EFG keeps the bent beam's length
    /// to 0.1 % while warping shortens it, by over 3 % at the larger load,
    /// and the tip turns further under the heavier load.
    #[test]
    fn the_bent_beam_keeps_its_length_only_under_nonlinear_dynamics() {
        let bends = bent_beam(&[1.0, 4.0]).expect("solves");
        for b in &bends {
            assert!(b.nonlinear.1.abs() < 1e-3, "{b:?}");
            assert!(b.warping.1 < 0.0, "{b:?}");
        }
        assert!(bends[1].warping.1 < -0.03, "{:?}", bends[1]);
        assert!(
            bends[1].nonlinear.0 > bends[0].nonlinear.0 + 20.0,
            "{bends:?}"
        );
    }

    /// A beam two cells deep sags within 30 % of Timoshenko statically
    /// (it measures 23 % stiff) and, released and damped, comes to rest
    /// within 5 % of its static sag; four cells deep is closer, and
    /// Timoshenko's formula is checked against its
    /// Euler–Bernoulli part for a slender beam.
    #[test]
    fn the_modal_cantilever_sags_as_timoshenko_says() {
        let beam = ModalCantilever {
            cell: 0.05,
            modes: 12,
            ..ModalCantilever::default()
        };
        let eb = {
            let h: Real = 0.1;
            1000.0 * 9.81 * h * h / (8.0 * 1e8 * h.powi(4) / 12.0)
        };
        // Shear over bending: (E / G) (H / L)^2 / (3 kappa) = 1.02 %.
        let t = beam.timoshenko();
        assert!(
            (t / eb - 1.0 - 0.0102).abs() < 1e-4,
            "shear adds 1.02 %: {t} vs {eb}"
        );
        let coarse = beam.measure(Measure::Static).expect("builds");
        assert!(coarse.error.abs() < 0.3, "coarse static: {coarse:?}");
        let released = beam.measure(Measure::Released).expect("steps");
        assert!(
            (released.deflection - coarse.deflection).abs() < 0.05 * coarse.deflection,
            "released comes to rest at the static sag: {released:?} vs {coarse:?}"
        );
        let fine = ModalCantilever {
            cell: 0.025,
            modes: 12,
            warping: false,
            ..ModalCantilever::default()
        }
        .measure(Measure::Static)
        .expect("builds");
        assert!(
            fine.error.abs() < coarse.error.abs(),
            "refining converges: {fine:?} vs {coarse:?}"
        );
    }
}

/// One load of [`bent_beam`]: the centreline's tip rotation and length
/// under modal warping and under the nonlinear EFG.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bend {
    /// The beam's weight times this.
    pub load: Real,
    /// Modal warping: tip rotation (degrees) and centreline length over
    /// the beam's, less one.
    pub warping: (Real, Real),
    /// The nonlinear EFG's.
    pub nonlinear: (Real, Real),
}

/// The 10 x 1 x 1 m cantilever of the engine's warping tests (E = 5e7 Pa,
/// nu = 0.3, 1000 kg/m^3, octants of 0.5 m: 189 nodes) under its weight
/// times each of `loads`, at rest: modal warping (24 modes, settled by
/// 400 damped steps of 0.05 s) and the full nonlinear EFG (a static Newton
/// solve per load, each from the last). A bent rod keeps its length;
/// warping shortens it as the tip turns (issue 30, item 9).
///
/// # Errors
/// The engine's message when a build or a solve fails.
pub fn bent_beam(loads: &[Real]) -> Result<Vec<Bend>, String> {
    let (l, h) = (10.0, 1.0);
    let mesh = TriMesh::cuboid(Vector::zeros(), Vector::new(l, h, h)).subdivided(4);
    let sdf = MeshSdf::new(&mesh).map_err(|e| e.to_string())?;
    let fixed = FixedSurface::of_mesh_in_box(
        &mesh,
        &Vector::repeat(-1e-9),
        &Vector::new(1e-9, h + 1e-9, h + 1e-9),
    );
    let material = Material {
        density: 1000.0,
        young: 5e7,
        poisson: 0.3,
    };
    let centreline: Vec<Vector> = (0..=40)
        .map(|i| Vector::new(l * i as Real / 40.0, 0.5 * h, 0.5 * h))
        .collect();
    let shape = |efg: &EfgSolid, u: &[Vector]| -> Result<(Real, Real), String> {
        let table = efg.shape_table(&centreline).map_err(|e| e.to_string())?;
        let mut d = Vec::new();
        table.interpolate(u, &mut d);
        let line: Vec<Vector> = centreline.iter().zip(&d).map(|(x, d)| x + d).collect();
        let length: Real = line.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        let end = line[40] - line[39];
        Ok(((-end.z).atan2(end.x).to_degrees(), length / l - 1.0))
    };
    let params = ModalParams {
        dynamics: Dynamics::Modal,
        efg: EfgParams::new(0.5),
        modes: 24,
        tolerance: 1e-10,
        warping: true,
        damping: Damping::new(5.0, 0.0).map_err(|e| e.to_string())?,
        stabilization: Stabilization::new(0.0, 0.0).map_err(|e| e.to_string())?,
    };
    let modal = ModalSolid::build(&sdf, &fixed, material, &params, None, &Cancel::new())
        .map_err(|e| e.to_string())?;
    let efg = modal.efg();
    let mut solver = NonlinearSolver::new(efg);
    let mut state = NonlinearState::rest(efg.nodes().len());
    let mut bends = Vec::with_capacity(loads.len());
    for &load in loads {
        let g = Vector::new(0.0, 0.0, -9.81 * load);
        let mut warped = modal.clone();
        for _ in 0..400 {
            warped.step(0.05, &g).map_err(|e| e.to_string())?;
        }
        let warping = shape(efg, warped.displacements())?;
        let weight = efg.body_load(&g);
        let info = solver
            .solve_static(efg, &mut state, &weight, 60)
            .map_err(|e| e.to_string())?;
        if !info.converged {
            return Err(format!(
                "the nonlinear solve at load {load} did not converge: {info:?}"
            ));
        }
        let u: Vec<Vector> = state
            .displacements
            .chunks_exact(3)
            .map(|c| Vector::new(c[0], c[1], c[2]))
            .collect();
        bends.push(Bend {
            load,
            warping,
            nonlinear: shape(efg, &u)?,
        });
    }
    Ok(bends)
}
