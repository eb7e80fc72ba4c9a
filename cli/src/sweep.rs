//! What every `meshless study` sweep shares: the values it runs (those
//! given, or the knob's presets), checked all before any runs, the output
//! folder, and a progress bar over the settings with each one timed.

use crate::chart;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::Path;
use std::time::Instant;

/// One setting's outcome and how long it took.
pub struct Timed<T> {
    /// The knob's value, as given.
    pub value: String,
    /// Wall time of the measurement, s.
    pub seconds: f64,
    /// What it measured.
    pub outcome: T,
}

/// Makes the setting of every value of knob `name` (the given `values`,
/// or the `presets` when none are), refusing a bad one before any runs;
/// then creates `output` and runs `measure` on each setting in turn
/// under a progress bar, timing each.
///
/// # Errors
/// A value `setting` refuses, or an output folder that cannot be made.
pub fn sweep<S, T>(
    name: &str,
    presets: &[&str],
    values: &[String],
    output: &Path,
    setting: impl Fn(&str) -> Result<S>,
    mut measure: impl FnMut(S) -> T,
) -> Result<Vec<Timed<T>>> {
    let values: Vec<String> = if values.is_empty() {
        presets.iter().map(|v| (*v).to_owned()).collect()
    } else {
        values.to_vec()
    };
    let settings = values
        .iter()
        .map(|v| setting(v))
        .collect::<Result<Vec<_>>>()?;
    std::fs::create_dir_all(output)
        .with_context(|| format!("cannot create {}", output.display()))?;
    let bar = ProgressBar::new(values.len() as u64).with_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} settings  {prefix}  [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut rows = Vec::with_capacity(values.len());
    for (value, setting) in values.into_iter().zip(settings) {
        bar.set_prefix(format!("{name} = {value}"));
        let start = Instant::now();
        let outcome = measure(setting);
        rows.push(Timed {
            value,
            seconds: start.elapsed().as_secs_f64(),
            outcome,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(rows)
}

/// Writes the sweep's table `csv` to `study_{name}.csv` in `output` and
/// charts each setting's `error` (percent; `None` for a setting that
/// failed, left out) against its wall time in `study_{name}.png`.
///
/// # Errors
/// When a file cannot be written.
pub fn report<T>(
    output: &Path,
    name: &str,
    csv: &str,
    rows: &[Timed<T>],
    error: impl Fn(&T) -> Option<f64>,
    (title, y_desc): (&str, &str),
) -> Result<()> {
    chart::write_table(&output.join(format!("study_{name}.csv")), csv)?;
    let points: Vec<chart::Point> = rows
        .iter()
        .filter_map(|r| {
            error(&r.outcome).map(|error| chart::Point {
                cost: r.seconds,
                error,
                label: r.value.clone(),
            })
        })
        .collect();
    chart::draw_and_report(
        &output.join(format!("study_{name}.png")),
        title,
        y_desc,
        &points,
    )
}

/// One setting's figures in the discretised solids' studies (modal EFG
/// solids, shells): the nodes, the precompute and per-step cost, and the
/// measured value against its reference.
pub struct Figures {
    /// Nodes of the discretisation.
    pub nodes: usize,
    /// Wall time of the precompute, s.
    pub precompute: f64,
    /// Mean wall time of a step, ms.
    pub step_ms: f64,
    /// What was measured.
    pub measured: f64,
    /// Its reference.
    pub reference: f64,
    /// `measured / reference - 1`.
    pub error: f64,
}

/// Prints the table of a sweep knob `name` over `rows` (value, nodes,
/// precompute, step, error; a failed setting with its reason) and returns
/// it as CSV, with `column` naming the measured value's column.
///
/// # Errors
/// When standard output cannot be written.
pub fn figures_table<T>(
    name: &str,
    column: &str,
    rows: &[Timed<T>],
    figures: impl Fn(&T) -> std::result::Result<Figures, &str>,
) -> Result<String> {
    use std::fmt::Write as _;
    outln!("  value        nodes  precompute [s]  step [ms]      error")?;
    let mut csv = format!(
        "knob,value,nodes,precompute_seconds,step_ms,wall_seconds,{column},reference,error,status\n"
    );
    for r in rows {
        match figures(&r.outcome) {
            Ok(m) => {
                writeln!(
                    csv,
                    "{name},{},{},{:.4},{:.4},{:.3},{:.6e},{:.6e},{:.5},ok",
                    r.value,
                    m.nodes,
                    m.precompute,
                    m.step_ms,
                    r.seconds,
                    m.measured,
                    m.reference,
                    m.error
                )?;
                outln!(
                    "  {:<12} {:>5}  {:>14.3}  {:>9.3}  {:>+8.2} %",
                    r.value,
                    m.nodes,
                    m.precompute,
                    m.step_ms,
                    100.0 * m.error
                )?;
            }
            Err(e) => {
                writeln!(
                    csv,
                    "{name},{},,,,{:.3},,,,{}",
                    r.value,
                    r.seconds,
                    e.replace(',', ";")
                )?;
                outln!("  {:<12} failed: {e}", r.value)?;
            }
        }
    }
    Ok(csv)
}
