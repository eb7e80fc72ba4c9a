//! `meshless study --knob shell-*`: sweep one speed-against-accuracy knob
//! of the thin shells (Guo–Qin) on a cantilever plate and report, against
//! Euler–Bernoulli, the error and the cost of each setting (precompute,
//! and per step), as CSV and a PNG chart. The discretisation knobs
//! (resolution, eta, quadrature order, basis) measure the static sag;
//! the time step measures the released plate's first half period under
//! Newmark's average acceleration.

use crate::sweep::{Figures, figures_table, report, sweep};
use anyhow::{Context, Result, bail};
use meshless_engine::approx::mls::Order;
use meshless_validation::shell_cantilever::{ShellCantilever, ShellMeasure};
use std::path::Path;

/// The plate for one value of knob `name`.
fn setting(name: &str, value: &str) -> Result<(ShellCantilever, ShellMeasure)> {
    let number = || -> Result<f64> {
        value
            .parse()
            .with_context(|| format!("{name}: {value:?} is not a number"))
    };
    let base = ShellCantilever::default();
    Ok(match name {
        "shell_resolution" => (
            ShellCantilever {
                resolution: number()?,
                ..base
            },
            ShellMeasure::Static,
        ),
        "shell_eta" => (
            ShellCantilever {
                eta: number()?,
                ..base
            },
            ShellMeasure::Static,
        ),
        "shell_quadrature" => (
            ShellCantilever {
                quadrature_order: value
                    .parse()
                    .with_context(|| format!("{name}: {value:?} is not a whole number"))?,
                ..base
            },
            ShellMeasure::Static,
        ),
        "shell_basis" => {
            let basis = match value {
                "linear" => Order::Linear,
                "quadratic" => Order::Quadratic,
                other => bail!("shell_basis: {other:?}; use linear or quadratic"),
            };
            (ShellCantilever { basis, ..base }, ShellMeasure::Static)
        }
        "shell_dt" => (
            ShellCantilever {
                dt: number()?,
                ..base
            },
            ShellMeasure::Period,
        ),
        other => bail!("{other} is not a shell knob"),
    })
}

pub fn study(name: &str, presets: &[&str], values: &[String], output: &Path) -> Result<()> {
    let rows = sweep(
        name,
        presets,
        values,
        output,
        |v| setting(name, v),
        |(plate, measure)| (measure, plate.measure(measure)),
    )?;
    let what = match rows.first().map(|r| r.outcome.0) {
        Some(ShellMeasure::Period) => "first half period (Newmark)",
        Some(ShellMeasure::Static) | None => "static tip sag",
    };
    outln!(
        "meshless study: thin-shell cantilever plate against Euler-Bernoulli ({what}), sweeping \
         {name}"
    )?;
    let csv = figures_table(name, "measured", &rows, |(_, outcome)| {
        outcome
            .as_ref()
            .map(|m| Figures {
                nodes: m.nodes,
                precompute: m.precompute,
                step_ms: m.step_ms,
                measured: m.value,
                reference: m.reference,
                error: m.error,
            })
            .map_err(String::as_str)
    })?;
    report(
        output,
        name,
        &csv,
        &rows,
        |(_, outcome)| outcome.as_ref().ok().map(|m| 100.0 * m.error.abs()),
        (
            &format!("shell cantilever: {what} error against cost, sweeping {name}"),
            &format!("|{what} error| [%]"),
        ),
    )
}
