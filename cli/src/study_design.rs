//! `meshless study --knob design-*`: sweep one knob of the shape and
//! motion optimiser on its reference experiments and report accuracy
//! against solve time, as CSV and PNG charts.
//!
//! - the Figure 13 stretch with the volume energy: how far the surface's
//!   volume drifts and how closely the handles are met;
//! - the passage: how deep the cube's particle spheres enter the ball
//!   between frames, and how closely the keyframes are met.

use crate::chart;
use crate::sweep::sweep;
use anyhow::{Context, Result, bail};
use meshless_engine::design::{DesignParams, MotionParams};
use meshless_validation::design::{Passage, PassageResult, Stretch, StretchResult, stretch_params};
use std::fmt::Write as _;
use std::path::Path;

/// The two reference experiments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Experiment {
    Stretch,
    Passage,
}

impl Experiment {
    fn name(self) -> &'static str {
        match self {
            Self::Stretch => "stretch",
            Self::Passage => "passage",
        }
    }
}

/// One solve to run.
enum Setting {
    Stretch(Stretch, DesignParams),
    Passage(Passage, DesignParams, MotionParams),
}

impl Setting {
    fn experiment(&self) -> Experiment {
        match self {
            Self::Stretch(..) => Experiment::Stretch,
            Self::Passage(..) => Experiment::Passage,
        }
    }
}

/// The experiments knob `name` sweeps.
fn experiments(name: &str) -> &'static [Experiment] {
    match name {
        "design_particles" => &[Experiment::Stretch, Experiment::Passage],
        "design_tolerance" => &[Experiment::Stretch],
        _ => &[Experiment::Passage],
    }
}

/// The solve for one value of knob `name`.
fn setting(name: &str, value: &str) -> Result<Setting> {
    let number = |text: &str| -> Result<f64> {
        text.parse()
            .with_context(|| format!("{name}: {text:?} is not a number"))
    };
    Ok(match name {
        "design_particles" => {
            let Some((experiment, count)) = value.split_once(':') else {
                bail!("design_particles: {value:?}; write stretch:N or passage:N");
            };
            let particles: u32 = count
                .parse()
                .with_context(|| format!("design_particles: {count:?} is not a particle count"))?;
            match experiment {
                "stretch" => Setting::Stretch(
                    Stretch {
                        particles,
                        ..Stretch::default()
                    },
                    stretch_params(true),
                ),
                "passage" => Setting::Passage(
                    Passage {
                        particles,
                        ..Passage::default()
                    },
                    DesignParams::default(),
                    MotionParams::default(),
                ),
                other => bail!("design_particles: {other:?}; use stretch or passage"),
            }
        }
        "design_tolerance" => {
            let mut params = stretch_params(true);
            params.solver.tolerance = number(value)?;
            Setting::Stretch(Stretch::default(), params)
        }
        "design_adaptive" => {
            let motion = match value {
                "off" => MotionParams {
                    adaptive: false,
                    ..MotionParams::default()
                },
                _ => MotionParams {
                    tolerance: number(value)?,
                    ..MotionParams::default()
                },
            };
            Setting::Passage(Passage::default(), DesignParams::default(), motion)
        }
        other => bail!("{other} is not a design knob"),
    })
}

/// What one solve gave.
enum Outcome {
    Stretch(StretchResult),
    Passage(PassageResult),
}

/// One setting's outcome.
struct Row {
    value: String,
    experiment: Experiment,
    outcome: Result<Outcome, String>,
}

impl Row {
    /// Seconds the solve took, without building the body or measuring.
    fn seconds(&self) -> Option<f64> {
        match &self.outcome {
            Ok(Outcome::Stretch(r)) => Some(r.elapsed.as_secs_f64()),
            Ok(Outcome::Passage(r)) => Some(r.elapsed.as_secs_f64()),
            Err(_) => None,
        }
    }
}

pub fn study(name: &str, presets: &[&str], values: &[String], output: &Path) -> Result<()> {
    let rows: Vec<Row> = sweep(
        name,
        presets,
        values,
        output,
        |v| setting(name, v),
        |setting| {
            let experiment = setting.experiment();
            let outcome = match setting {
                Setting::Stretch(stretch, params) => stretch.solve(&params).map(Outcome::Stretch),
                Setting::Passage(passage, params, motion) => {
                    passage.solve(&params, &motion).map(Outcome::Passage)
                }
            }
            .map_err(|e| e.to_string());
            (experiment, outcome)
        },
    )?
    .into_iter()
    .map(|t| Row {
        value: t.value,
        experiment: t.outcome.0,
        outcome: t.outcome.1,
    })
    .collect();

    let csv_path = output.join(format!("study_{name}.csv"));
    std::fs::write(&csv_path, csv(name, &rows)?)
        .with_context(|| format!("cannot write {}", csv_path.display()))?;
    print_tables(name, &rows)?;
    outln!("  table             {}", csv_path.display())?;

    let charted = experiments(name);
    for &experiment in charted {
        let file = if charted.len() == 1 {
            format!("study_{name}.png")
        } else {
            format!("study_{name}_{}.png", experiment.name())
        };
        chart_of(name, experiment, &rows, &output.join(file))?;
    }
    Ok(())
}

/// One line per setting; the other experiment's columns stay empty.
fn csv(name: &str, rows: &[Row]) -> Result<String> {
    let mut csv = String::from(
        "knob,value,experiment,particles,iterations,linear_iterations,converged,volume_change,\
         handle_error,frames,inserted,penetration,keyframe_error,solve_seconds,status\n",
    );
    for r in rows {
        let experiment = r.experiment.name();
        match &r.outcome {
            Ok(Outcome::Stretch(s)) => {
                let info = &s.solution.info;
                writeln!(
                    csv,
                    "{name},{},{experiment},{},{},{},{},{:.6},{:.5},,,,,{:.4},ok",
                    r.value,
                    s.particles,
                    info.iterations,
                    info.linear_iterations,
                    info.converged,
                    s.volume_change,
                    s.handle_error,
                    s.elapsed.as_secs_f64()
                )?;
            }
            Ok(Outcome::Passage(p)) => {
                let info = &p.solution.info;
                writeln!(
                    csv,
                    "{name},{},{experiment},{},{},{},{},,,{},{},{:.5},{:.5},{:.4},ok",
                    r.value,
                    p.particles,
                    info.iterations,
                    info.linear_iterations,
                    info.converged,
                    p.solution.times().len(),
                    info.inserted,
                    p.penetration,
                    p.keyframe_error,
                    p.elapsed.as_secs_f64()
                )?;
            }
            Err(e) => writeln!(
                csv,
                "{name},{},{experiment},,,,,,,,,,,,{}",
                r.value,
                e.replace(',', ";")
            )?,
        }
    }
    Ok(csv)
}

fn print_tables(name: &str, rows: &[Row]) -> std::io::Result<()> {
    for &experiment in experiments(name) {
        match experiment {
            Experiment::Stretch => {
                outln!(
                    "meshless study: Figure 13 stretch with the volume energy, sweeping {name}"
                )?;
                outln!(
                    "  value        particles  volume change  handle error  iterations  linear its  solve [ms]  converged"
                )?;
            }
            Experiment::Passage => {
                outln!("meshless study: cube passing a ball, sweeping {name}")?;
                outln!(
                    "  value        particles  frames  inserted  penetration  key error  last LM its  solve [s]"
                )?;
            }
        }
        for r in rows.iter().filter(|r| r.experiment == experiment) {
            match &r.outcome {
                Ok(Outcome::Stretch(s)) => outln!(
                    "  {:<12} {:>9}  {:>+11.2} %  {:>12.4}  {:>10}  {:>10}  {:>10.1}  {}",
                    r.value,
                    s.particles,
                    100.0 * s.volume_change,
                    s.handle_error,
                    s.solution.info.iterations,
                    s.solution.info.linear_iterations,
                    s.elapsed.as_secs_f64() * 1e3,
                    s.solution.info.converged
                ),
                Ok(Outcome::Passage(p)) => outln!(
                    "  {:<12} {:>9}  {:>6}  {:>8}  {:>11.3}  {:>9.3}  {:>11}  {:>9.3}",
                    r.value,
                    p.particles,
                    p.solution.times().len(),
                    p.solution.info.inserted,
                    p.penetration,
                    p.keyframe_error,
                    p.solution.info.iterations,
                    p.elapsed.as_secs_f64()
                ),
                Err(e) => outln!("  {:<12} failed: {e}", r.value),
            }?;
        }
    }
    outln!(
        "  handle error, penetration and key error in design spacings; a motion's last LM its \
         count its final solve only"
    )?;
    Ok(())
}

/// The experiment's error against solve time: the surface's volume
/// change for the stretch, the penetration for the passage.
fn chart_of(name: &str, experiment: Experiment, rows: &[Row], path: &Path) -> Result<()> {
    let points: Vec<chart::Point> = rows
        .iter()
        .filter_map(|r| {
            let error = match r.outcome.as_ref().ok()? {
                Outcome::Stretch(s) => 100.0 * s.volume_change.abs(),
                Outcome::Passage(p) => 100.0 * p.penetration,
            };
            (r.experiment == experiment).then(|| chart::Point {
                cost: r.seconds().unwrap_or(0.0),
                error,
                label: r.value.clone(),
            })
        })
        .collect();
    let (title, y) = match experiment {
        Experiment::Stretch => (
            format!("Figure 13 stretch: volume change against cost, sweeping {name}"),
            "|surface volume change| [%]",
        ),
        Experiment::Passage => (
            format!("passage: penetration against cost, sweeping {name}"),
            "deepest penetration [% of a spacing]",
        ),
    };
    chart::draw_and_report(path, &title, y, &points)?;
    Ok(())
}
