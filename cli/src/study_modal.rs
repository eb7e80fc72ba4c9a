//! `meshless study --knob modal-*`: sweep one speed-against-accuracy knob
//! of the modal EFG solids (Guo–Qin) on a cantilever under its own weight
//! and report, against Timoshenko, the tip deflection error and the cost
//! of each setting (precompute, and per step for the released beam), as
//! CSV and a PNG chart. The discretisation knobs (cell, alpha, quadrature
//! order, basis, modes) measure the modal static solution; warping and
//! the time step measure the released beam come to rest.

use crate::chart;
use crate::sweep::{Figures, figures_table, report, sweep};
use anyhow::{Context, Result, bail};
use meshless_engine::approx::mls::Order;
use meshless_engine::efg::Dynamics;
use meshless_validation::modal_cantilever::{Measure, ModalCantilever, bent_beam};
use std::fmt::Write as _;
use std::path::Path;

/// The cantilever for one value of knob `name`.
fn setting(name: &str, value: &str) -> Result<(ModalCantilever, Measure)> {
    let number = || -> Result<f64> {
        value
            .parse()
            .with_context(|| format!("{name}: {value:?} is not a number"))
    };
    let count = || -> Result<usize> {
        value
            .parse()
            .with_context(|| format!("{name}: {value:?} is not a whole number"))
    };
    let base = ModalCantilever::default();
    Ok(match name {
        "modal_cell" => (
            ModalCantilever {
                cell: number()?,
                ..base
            },
            Measure::Static,
        ),
        "modal_alpha" => (
            ModalCantilever {
                alpha: number()?,
                ..base
            },
            Measure::Static,
        ),
        "modal_quadrature" => (
            ModalCantilever {
                quadrature_order: count()?,
                ..base
            },
            Measure::Static,
        ),
        "modal_basis" => {
            let basis = match value {
                "linear" => Order::Linear,
                "quadratic" => Order::Quadratic,
                other => bail!("modal_basis: {other:?}; use linear or quadratic"),
            };
            (ModalCantilever { basis, ..base }, Measure::Static)
        }
        "modal_modes" => (
            ModalCantilever {
                modes: count()?,
                ..base
            },
            Measure::Static,
        ),
        "modal_warping" => {
            let warping = match value {
                "on" => true,
                "off" => false,
                other => bail!("modal_warping: {other:?}; use on or off"),
            };
            (ModalCantilever { warping, ..base }, Measure::Released)
        }
        "modal_dynamics" => {
            let dynamics = match value {
                "modal" => Dynamics::Modal,
                "nonlinear" => Dynamics::Nonlinear,
                other => bail!("modal_dynamics: {other:?}; use modal or nonlinear"),
            };
            (ModalCantilever { dynamics, ..base }, Measure::Released)
        }
        "modal_dt" => (
            ModalCantilever {
                dt: number()?,
                ..base
            },
            Measure::Released,
        ),
        other => bail!("{other} is not a modal-solid knob"),
    })
}

pub fn study(name: &str, presets: &[&str], values: &[String], output: &Path) -> Result<()> {
    let rows = sweep(
        name,
        presets,
        values,
        output,
        |v| setting(name, v),
        |(beam, measure)| (measure, beam.measure(measure)),
    )?;

    let what = match rows.first().map(|r| r.outcome.0) {
        Some(Measure::Released) => "released tip deflection at rest",
        Some(Measure::Static) | None => "modal static tip deflection",
    };
    outln!("meshless study: modal EFG cantilever against Timoshenko ({what}), sweeping {name}")?;
    let csv = figures_table(name, "deflection", &rows, |(_, outcome)| {
        outcome
            .as_ref()
            .map(|m| Figures {
                nodes: m.nodes,
                precompute: m.precompute,
                step_ms: m.step_ms,
                measured: m.deflection,
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
            &format!("modal cantilever: {what} error against cost, sweeping {name}"),
            &format!("|{what} error| [%]"),
        ),
    )?;
    if name == "modal_dynamics" {
        bend(output)?;
    }
    Ok(())
}

/// The bent beam's centreline length against its tip rotation, modal
/// warping against the nonlinear EFG (`bent_beam`), as CSV and PNG.
fn bend(output: &Path) -> Result<()> {
    let loads = [1.0, 2.0, 4.0, 8.0, 16.0];
    let bends = bent_beam(&loads).map_err(|e| anyhow::anyhow!("the bent beam: {e}"))?;
    outln!("meshless study: a 10 x 1 x 1 m cantilever bent by its weight times 1 to 16")?;
    outln!("  load   warping: rotation, length    nonlinear EFG: rotation, length")?;
    let mut csv = String::from(
        "load,warping_rotation_deg,warping_length_change,nonlinear_rotation_deg,nonlinear_length_change\n",
    );
    for b in &bends {
        writeln!(
            csv,
            "{},{:.3},{:.6},{:.3},{:.6}",
            b.load, b.warping.0, b.warping.1, b.nonlinear.0, b.nonlinear.1
        )?;
        outln!(
            "  {:>4}   {:>8.1} deg {:>+7.2} %      {:>8.1} deg {:>+7.2} %",
            b.load,
            b.warping.0,
            100.0 * b.warping.1,
            b.nonlinear.0,
            100.0 * b.nonlinear.1
        )?;
    }
    chart::write_table(&output.join("study_modal_dynamics_bend.csv"), &csv)?;
    let series = [
        (
            "modal warping (24 modes)",
            bends
                .iter()
                .map(|b| (b.warping.0, 100.0 * b.warping.1))
                .collect::<Vec<_>>(),
        ),
        (
            "nonlinear EFG (Guo-Qin 5.1)",
            bends
                .iter()
                .map(|b| (b.nonlinear.0, 100.0 * b.nonlinear.1))
                .collect(),
        ),
    ];
    chart::lines_and_report(
        &output.join("study_modal_dynamics_bend.png"),
        "bent cantilever: centreline length against tip rotation",
        "tip rotation [deg]",
        "centreline length change [%]",
        &series,
    )
}
