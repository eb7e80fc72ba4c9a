//! `meshless study --knob fracture-*`: sweep one knob of the fracturing
//! solids on Griffith's plate (a central crack under tension,
//! `validation/src/griffith.rs`) and report the measured failure stress
//! against the point method's prediction on the crack's exact field, with
//! the wall time of each setting, as CSV and a PNG chart.

use crate::sweep::{report, sweep};
use anyhow::{Context, Result, bail};
use meshless_engine::math::Real;
use meshless_engine::solid::fracture::{Discontinuity, Resampling};
use meshless_validation::griffith::Griffith;
use std::fmt::Write as _;
use std::path::Path;

/// The crack's half-length, m: three critical distances of the default
/// plate's material.
const HALF_LENGTH: f64 = 0.09;

/// The plate for one value of knob `name`: 0.6 m x 0.9 m, the default
/// material (critical distance 3 cm), one knob changed.
fn setting(name: &str, value: &str) -> Result<Griffith> {
    let number = || -> Result<f64> {
        value
            .parse()
            .with_context(|| format!("{name}: {value:?} is not a number"))
    };
    let base = Griffith {
        width: 0.6,
        height: 0.9,
        resolution: 5e-3,
        ..Griffith::default()
    };
    Ok(match name {
        "fracture_resolution" => {
            let spacings = number()?;
            if !(spacings.is_finite() && (1.0..=12.0).contains(&spacings)) {
                bail!(
                    "fracture_resolution: {value} spacings per critical distance; use 1 to 12 \
                     (below 1 a scene is refused, above 12 the plate passes a million particles)"
                );
            }
            Griffith {
                spacing: base.critical_distance() / spacings,
                ..base
            }
        }
        "fracture_kappa" => {
            let discontinuity = match value {
                "visibility" => Discontinuity::Visibility,
                _ => {
                    let kappa: f64 = value.parse().ok().unwrap_or(Real::NAN);
                    if !(kappa.is_finite() && kappa > 0.0) {
                        bail!("fracture_kappa: {value}; use a positive number or visibility");
                    }
                    Discontinuity::Transparency { kappa }
                }
            };
            Griffith {
                discontinuity,
                ..base
            }
        }
        "fracture_q_min" => {
            let resample = match value {
                "off" => None,
                _ => {
                    let q_min: f64 = value.parse().ok().unwrap_or(Real::NAN);
                    if !(q_min.is_finite() && (1.0..=65.0).contains(&q_min)) {
                        bail!("fracture_q_min: {value}; use 1 to 65 neighbours or off");
                    }
                    Some(Resampling {
                        q_min,
                        ..Resampling::new()
                    })
                }
            };
            Griffith { resample, ..base }
        }
        "fracture_radius_ratio" => {
            let ratio = number()?;
            if !(ratio > 0.0 && ratio < 1.0) {
                bail!("fracture_radius_ratio: {value}; use a fraction of the support in (0, 1)");
            }
            Griffith {
                resample: Some(Resampling {
                    min_radius_ratio: ratio,
                    ..Resampling::new()
                }),
                ..base
            }
        }
        other => bail!("{other} is not a fracture knob"),
    })
}

pub fn study(name: &str, presets: &[&str], values: &[String], output: &Path) -> Result<()> {
    let rows = sweep(
        name,
        presets,
        values,
        output,
        |v| setting(name, v),
        |plate| plate.failure(HALF_LENGTH).map_err(|e| e.to_string()),
    )?;

    outln!(
        "meshless study: Griffith's plate (a = {HALF_LENGTH} m) against the point method, \
         sweeping {name}"
    )?;
    outln!("  value        particles  solves  wall [s]  failure [Pa]  point method [Pa]   error")?;
    let mut csv = String::from(
        "knob,value,particles,static_solves,wall_seconds,failure_stress,point_method_stress,griffith_stress,error,status\n",
    );
    for r in &rows {
        match &r.outcome {
            Ok(f) => {
                let error = f.stress / f.point_method - 1.0;
                writeln!(
                    csv,
                    "{name},{},{},{},{:.3},{:.6e},{:.6e},{:.6e},{error:.5},ok",
                    r.value, f.particles, f.solves, r.seconds, f.stress, f.point_method, f.griffith
                )?;
                outln!(
                    "  {:<12} {:>9}  {:>6}  {:>8.2}  {:>12.4e}  {:>17.4e}  {:>+6.1} %",
                    r.value,
                    f.particles,
                    f.solves,
                    r.seconds,
                    f.stress,
                    f.point_method,
                    100.0 * error
                )?;
            }
            Err(e) => {
                writeln!(
                    csv,
                    "{name},{},,,{:.3},,,,,{}",
                    r.value,
                    r.seconds,
                    e.replace(',', ";")
                )?;
                outln!("  {:<12} failed: {e}", r.value)?;
            }
        }
    }
    report(
        output,
        name,
        &csv,
        &rows,
        |outcome| {
            outcome
                .as_ref()
                .ok()
                .map(|f| 100.0 * (f.stress / f.point_method - 1.0).abs())
        },
        (
            &format!("Griffith's plate: failure stress error against cost, sweeping {name}"),
            "|failure stress / point method - 1| [%]",
        ),
    )?;
    Ok(())
}
