//! `meshless study --knob solid-*`: sweep one knob of the elastic solids
//! on the cantilever under its own weight and report, against
//! Euler–Bernoulli, the static tip deflection error (spacing, order,
//! hourglass weight) or the
//! first-period error of the released beam (integrator, step), with the
//! wall time of each setting, as CSV and a PNG chart.

use crate::sweep::{report, sweep};
use anyhow::{Context, Result, bail};
use meshless_engine::approx::mls::Order;
use meshless_engine::scene::IntegratorKind;
use meshless_validation::cantilever::{Cantilever, Quantity};
use meshless_wire::WireEnum;
use std::fmt::Write as _;
use std::path::Path;

/// The cantilever for one value of knob `name`.
fn setting(name: &str, value: &str) -> Result<(Cantilever, Quantity)> {
    let number = || -> Result<f64> {
        value
            .parse()
            .with_context(|| format!("{name}: {value:?} is not a number"))
    };
    let base = Cantilever::default();
    Ok(match name {
        "solid_spacing" => (
            Cantilever {
                spacing: number()?,
                ..base
            },
            Quantity::Deflection,
        ),
        "solid_order" => {
            let (order, support) = match value {
                "linear" => (Order::Linear, 2.0),
                "quadratic" => (Order::Quadratic, 3.0),
                other => bail!("solid_order: {other:?}; use linear or quadratic"),
            };
            (
                Cantilever {
                    order,
                    support,
                    ..base
                },
                Quantity::Deflection,
            )
        }
        "solid_integrator" => {
            let integrator = IntegratorKind::from_name(value).with_context(|| {
                format!(
                    "solid_integrator: {value:?}; use {}",
                    IntegratorKind::choices()
                )
            })?;
            (Cantilever { integrator, ..base }, Quantity::Period)
        }
        "solid_hourglass" => (
            Cantilever {
                hourglass: number()?,
                ..base
            },
            Quantity::Deflection,
        ),
        "solid_dt" => (
            Cantilever {
                integrator: IntegratorKind::Implicit,
                dt: number()?,
                ..base
            },
            Quantity::Period,
        ),
        other => bail!("{other} is not a solid knob"),
    })
}

pub fn study(name: &str, presets: &[&str], values: &[String], output: &Path) -> Result<()> {
    let rows = sweep(
        name,
        presets,
        values,
        output,
        |v| setting(name, v),
        |(cantilever, quantity)| {
            (
                quantity,
                cantilever.measure(quantity).map_err(|e| e.to_string()),
            )
        },
    )?;

    let measured = |q: Quantity| match q {
        Quantity::Deflection => "static tip deflection",
        Quantity::Period => "first bending period",
    };
    let what = rows.first().map_or("", |r| measured(r.outcome.0));
    outln!("meshless study: cantilever against Euler-Bernoulli ({what}), sweeping {name}")?;
    outln!("  value        particles  world steps  wall [s]      error  first peak / 2 static")?;
    let mut csv = String::from(
        "knob,value,quantity,particles,steps,wall_seconds,value_measured,error,peak_over_twice_static,status\n",
    );
    for r in &rows {
        let (quantity, outcome) = &r.outcome;
        match outcome {
            Ok(m) => {
                writeln!(
                    csv,
                    "{name},{},{},{},{},{:.3},{:.6e},{:.5},{:.4},ok",
                    r.value,
                    measured(*quantity).replace(' ', "_"),
                    m.particles,
                    m.steps,
                    r.seconds,
                    m.value,
                    m.error,
                    m.amplitude
                )?;
                let peak = match quantity {
                    Quantity::Period => format!("{:>8.3}", m.amplitude),
                    Quantity::Deflection => String::new(),
                };
                outln!(
                    "  {:<12} {:>9}  {:>11}  {:>8.2}  {:>+8.1} %  {peak}",
                    r.value,
                    m.particles,
                    m.steps,
                    r.seconds,
                    100.0 * m.error
                )?;
            }
            Err(e) => {
                writeln!(
                    csv,
                    "{name},{},,,,{:.3},,,{}",
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
        |(_, outcome)| outcome.as_ref().ok().map(|m| 100.0 * m.error.abs()),
        (
            &format!("cantilever: {what} error against cost, sweeping {name}"),
            &format!("|{what} error| [%]"),
        ),
    )?;
    Ok(())
}
