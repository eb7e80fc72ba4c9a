//! `meshless study`: sweep one speed-against-accuracy knob on the dam break
//! and report the surge-front error against Martin & Moyce (1952) and the
//! cost of each setting, as CSV and a PNG chart. The `solid-*` knobs sweep
//! the cantilever instead (`study_solid.rs`), the `modal-*` knobs the
//! modal EFG cantilever (`study_modal.rs`), the `shell-*` knobs the
//! thin-shell cantilever plate (`study_shell.rs`), the `design-*` knobs the
//! shape and motion optimiser's experiments (`study_design.rs`), the
//! `fracture-*` knobs Griffith's plate (`study_fracture.rs`).

use crate::chart;
use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use meshless_engine::Scene;
use meshless_engine::approx::KernelKind;
use meshless_engine::scene::{FluidSpec, SolverKind, SystemSpec};
use meshless_validation::dam_break::{FrontRun, RunStatus, column_width, run_front};
use meshless_wire::WireEnum;
use std::fmt::Write as _;
use std::path::PathBuf;

/// The built-in dam break.
const DAM_BREAK: &str = include_str!("../../scenes/dam_break.toml");

/// Knobs that trade speed for accuracy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Knob {
    /// Particle spacing in m (support radius kept at twice the spacing).
    Spacing,
    /// Kernel pair: poly6 (with spiky gradients), cubic_spline, wendland_c2.
    Kernel,
    /// Courant number of the sub-step limit.
    Cfl,
    /// Pressure solver: wcsph or dfsph.
    Solver,
    /// DFSPH density tolerance (fraction of the rest density).
    DensityTolerance,
    /// Kernel support radius, in spacings.
    Support,
    /// XSPH factor (0: no XSPH pass).
    Xsph,
    /// Elastic solid: particle spacing of the cantilever, m.
    SolidSpacing,
    /// Elastic solid: MLS basis order (linear with support 2 spacings,
    /// quadratic with 3).
    SolidOrder,
    /// Elastic solid: integrator, explicit or implicit.
    SolidIntegrator,
    /// Elastic solid: implicit step, s.
    SolidDt,
    /// Elastic solid: hourglass-control weight relative to Young's modulus.
    SolidHourglass,
    /// Modal solid: octant side of the cantilever, m (the node count).
    ModalCell,
    /// Modal solid: support side over octant side.
    ModalAlpha,
    /// Modal solid: Gauss points per axis of an integration cell.
    ModalQuadrature,
    /// Modal solid: MLS basis, linear or quadratic.
    ModalBasis,
    /// Modal solid: modes kept.
    ModalModes,
    /// Modal solid: modal warping, on or off (released beam).
    ModalWarping,
    /// Modal solid: time step of the released beam, s.
    ModalDt,
    /// Modal solid: dynamics, modal or nonlinear (released beam; also
    /// draws the bent beam's length against its tip rotation).
    ModalDynamics,
    /// Shell: largest quadtree cell of the cantilever plate, m (the node
    /// count).
    ShellResolution,
    /// Shell: support side in quadtree leaf sides.
    ShellEta,
    /// Shell: Gauss points per axis of an integration cell.
    ShellQuadrature,
    /// Shell: MLS basis, linear or quadratic.
    ShellBasis,
    /// Shell: Newmark time step of the released plate, s.
    ShellDt,
    /// Design: particles of the Figure 13 stretch with the volume energy
    /// (`stretch:N`) and of the cube passing a ball (`passage:N`).
    DesignParticles,
    /// Design: solver tolerance of the Figure 13 stretch.
    DesignTolerance,
    /// Design: adaptive-sampling tolerance of the cube passing a ball
    /// (`off`: the keyframes alone).
    DesignAdaptive,
    /// Fracture: spacings per critical distance of a toughness threshold
    /// (Griffith's plate, the toughness fixed).
    FractureResolution,
    /// Fracture: transparency's kappa in spacings, or `visibility`
    /// (Griffith's plate).
    FractureKappa,
    /// Fracture: resampling's `Q_min` (tutorial Eq. 71), or `off`
    /// (Griffith's plate, split beside its crack).
    FractureQMin,
    /// Fracture: resampling's smallest radius over the support radius
    /// (Griffith's plate).
    FractureRadiusRatio,
}

impl Knob {
    fn name(self) -> &'static str {
        match self {
            Self::Spacing => "spacing",
            Self::Kernel => "kernel",
            Self::Cfl => "cfl",
            Self::Solver => "solver",
            Self::DensityTolerance => "density_tolerance",
            Self::Support => "support",
            Self::Xsph => "xsph",
            Self::SolidSpacing => "solid_spacing",
            Self::SolidOrder => "solid_order",
            Self::SolidIntegrator => "solid_integrator",
            Self::SolidDt => "solid_dt",
            Self::SolidHourglass => "solid_hourglass",
            Self::ModalCell => "modal_cell",
            Self::ModalAlpha => "modal_alpha",
            Self::ModalQuadrature => "modal_quadrature",
            Self::ModalBasis => "modal_basis",
            Self::ModalModes => "modal_modes",
            Self::ModalWarping => "modal_warping",
            Self::ModalDt => "modal_dt",
            Self::ModalDynamics => "modal_dynamics",
            Self::ShellResolution => "shell_resolution",
            Self::ShellEta => "shell_eta",
            Self::ShellQuadrature => "shell_quadrature",
            Self::ShellBasis => "shell_basis",
            Self::ShellDt => "shell_dt",
            Self::DesignParticles => "design_particles",
            Self::DesignTolerance => "design_tolerance",
            Self::DesignAdaptive => "design_adaptive",
            Self::FractureResolution => "fracture_resolution",
            Self::FractureKappa => "fracture_kappa",
            Self::FractureQMin => "fracture_q_min",
            Self::FractureRadiusRatio => "fracture_radius_ratio",
        }
    }

    /// Whether the knob belongs to the cantilever study.
    fn is_solid(self) -> bool {
        matches!(
            self,
            Self::SolidSpacing
                | Self::SolidOrder
                | Self::SolidIntegrator
                | Self::SolidDt
                | Self::SolidHourglass
        )
    }

    /// Whether the knob belongs to the modal cantilever study.
    fn is_modal(self) -> bool {
        matches!(
            self,
            Self::ModalCell
                | Self::ModalAlpha
                | Self::ModalQuadrature
                | Self::ModalBasis
                | Self::ModalModes
                | Self::ModalWarping
                | Self::ModalDt
                | Self::ModalDynamics
        )
    }

    /// Whether the knob belongs to the shell cantilever study.
    fn is_shell(self) -> bool {
        matches!(
            self,
            Self::ShellResolution
                | Self::ShellEta
                | Self::ShellQuadrature
                | Self::ShellBasis
                | Self::ShellDt
        )
    }

    /// Whether the knob belongs to the design study.
    fn is_design(self) -> bool {
        matches!(
            self,
            Self::DesignParticles | Self::DesignTolerance | Self::DesignAdaptive
        )
    }

    fn is_fracture(self) -> bool {
        matches!(
            self,
            Self::FractureResolution
                | Self::FractureKappa
                | Self::FractureQMin
                | Self::FractureRadiusRatio
        )
    }

    fn presets(self) -> &'static [&'static str] {
        match self {
            Self::Spacing => &["0.04", "0.03", "0.025", "0.02"],
            Self::Kernel => &["poly6", "cubic_spline", "wendland_c2"],
            Self::Cfl => &["0.2", "0.4", "0.6", "0.8"],
            Self::Solver => &["wcsph", "dfsph"],
            Self::DensityTolerance => &["0.01", "0.003", "0.001", "0.0003"],
            Self::Support => &["2", "2.5", "3"],
            Self::Xsph => &["0", "0.05", "0.1", "0.2"],
            Self::SolidSpacing => &["0.025", "0.0167", "0.0125", "0.01", "0.00833"],
            Self::SolidOrder => &["linear", "quadratic"],
            Self::SolidIntegrator => &["explicit", "implicit"],
            Self::SolidDt => &["0.0005", "0.001", "0.002", "0.005", "0.01"],
            Self::SolidHourglass => &["0", "0.1", "1"],
            Self::ModalCell => &["0.05", "0.0333", "0.025", "0.02"],
            Self::ModalAlpha => &["2.5", "3", "4"],
            Self::ModalQuadrature => &["1", "2", "3"],
            Self::ModalBasis => &["linear", "quadratic"],
            Self::ModalModes => &["6", "12", "32", "64"],
            Self::ModalWarping => &["on", "off"],
            Self::ModalDt => &["0.004", "0.0167", "0.05", "0.2"],
            Self::ModalDynamics => &["modal", "nonlinear"],
            Self::ShellResolution => &["0.125", "0.0625", "0.03125", "0.015625"],
            Self::ShellEta => &["3", "4", "5"],
            Self::ShellQuadrature => &["2", "3", "4"],
            Self::ShellBasis => &["linear", "quadratic"],
            // 5, 10, 20 and 40 steps a first period (49 ms).
            Self::ShellDt => &["0.0098", "0.0049", "0.00245", "0.001225"],
            Self::DesignParticles => &[
                "stretch:30",
                "stretch:60",
                "stretch:120",
                "stretch:250",
                "stretch:500",
                "passage:60",
                "passage:120",
                "passage:200",
            ],
            Self::DesignTolerance => &["1e-2", "1e-3", "1e-4", "1e-6"],
            Self::DesignAdaptive => &["1.0", "0.5", "0.2", "0.1", "0.05", "off"],
            Self::FractureResolution => &["1.5", "2", "3", "4", "6"],
            Self::FractureKappa => &["visibility", "0.5", "1", "2"],
            Self::FractureQMin => &["off", "4", "6", "8"],
            Self::FractureRadiusRatio => &["0.3", "0.4", "0.5", "0.55"],
        }
    }

    /// Applies one value of the knob to the scene.
    fn apply(self, value: &str, scene: &mut Scene) -> Result<()> {
        let number = || -> Result<f64> {
            value
                .parse()
                .with_context(|| format!("{}: {value:?} is not a number", self.name()))
        };
        let fluid = fluid(scene)?;
        match self {
            Self::Spacing => {
                fluid.spacing = number()?;
                fluid.support_radius = Some(2.0 * fluid.spacing);
            }
            Self::Kernel => {
                let (density, gradient) = match value {
                    "poly6" => (KernelKind::Poly6, KernelKind::Spiky),
                    "cubic_spline" => (KernelKind::CubicSpline, KernelKind::CubicSpline),
                    "wendland_c2" => (KernelKind::WendlandC2, KernelKind::WendlandC2),
                    other => bail!("kernel: {other:?}; use poly6, cubic_spline or wendland_c2"),
                };
                fluid.density_kernel = density;
                fluid.gradient_kernel = gradient;
            }
            Self::Cfl => scene.time.cfl = number()?,
            Self::Solver => {
                fluid.solver = SolverKind::from_name(value)
                    .with_context(|| format!("solver: {value:?}; use {}", SolverKind::choices()))?;
            }
            Self::DensityTolerance => {
                fluid.solver = SolverKind::Dfsph;
                fluid.density_tolerance = number()?;
            }
            Self::Support => fluid.support_radius = Some(number()? * fluid.spacing),
            Self::Xsph => fluid.xsph = number()?,
            Self::SolidSpacing
            | Self::SolidOrder
            | Self::SolidIntegrator
            | Self::SolidDt
            | Self::SolidHourglass => {
                bail!("{} is a cantilever knob, not a dam-break one", self.name())
            }
            Self::DesignParticles | Self::DesignTolerance | Self::DesignAdaptive => {
                bail!("{} is a design knob, not a dam-break one", self.name())
            }
            Self::FractureResolution
            | Self::FractureKappa
            | Self::FractureQMin
            | Self::FractureRadiusRatio => {
                bail!("{} is a fracture knob, not a dam-break one", self.name())
            }
            Self::ModalCell
            | Self::ModalAlpha
            | Self::ModalQuadrature
            | Self::ModalBasis
            | Self::ModalModes
            | Self::ModalWarping
            | Self::ModalDt
            | Self::ModalDynamics => {
                bail!("{} is a modal-solid knob, not a dam-break one", self.name())
            }
            Self::ShellResolution
            | Self::ShellEta
            | Self::ShellQuadrature
            | Self::ShellBasis
            | Self::ShellDt => {
                bail!("{} is a shell knob, not a dam-break one", self.name())
            }
        }
        Ok(())
    }
}

fn fluid(scene: &mut Scene) -> Result<&mut FluidSpec> {
    match scene.systems.first_mut().and_then(SystemSpec::as_fluid_mut) {
        Some(fluid) => Ok(fluid),
        None => bail!("the scene's first system is no fluid to study"),
    }
}

#[derive(Debug, clap::Args)]
pub struct StudyArgs {
    /// The knob to sweep.
    #[arg(long, value_enum)]
    knob: Knob,
    /// Values of the knob, comma separated (default: a preset per knob).
    #[arg(long, value_delimiter = ',')]
    values: Vec<String>,
    /// A dam-break scene (a column of width a and height 2a against the
    /// wall at x = min) instead of the built-in one.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Folder for `study_{knob}.csv` and `study_{knob}.png`.
    #[arg(long, short, default_value = "out/study")]
    output: PathBuf,
}

/// One setting's outcome.
#[derive(Debug, Clone)]
struct Row {
    value: String,
    run: FrontRun,
}

pub fn study(args: StudyArgs) -> Result<()> {
    if args.knob.is_solid() {
        return crate::study_solid::study(
            args.knob.name(),
            args.knob.presets(),
            &args.values,
            &args.output,
        );
    }
    if args.knob.is_modal() {
        return crate::study_modal::study(
            args.knob.name(),
            args.knob.presets(),
            &args.values,
            &args.output,
        );
    }
    if args.knob.is_shell() {
        return crate::study_shell::study(
            args.knob.name(),
            args.knob.presets(),
            &args.values,
            &args.output,
        );
    }
    if args.knob.is_fracture() {
        return crate::study_fracture::study(
            args.knob.name(),
            args.knob.presets(),
            &args.values,
            &args.output,
        );
    }
    if args.knob.is_design() {
        return crate::study_design::study(
            args.knob.name(),
            args.knob.presets(),
            &args.values,
            &args.output,
        );
    }
    let text = match &args.scene {
        Some(path) => std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?,
        None => DAM_BREAK.to_owned(),
    };
    let base = Scene::from_toml_str(&text)?;
    let values: Vec<String> = if args.values.is_empty() {
        args.knob
            .presets()
            .iter()
            .map(|v| (*v).to_owned())
            .collect()
    } else {
        args.values.clone()
    };
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("cannot create {}", args.output.display()))?;

    let bar = ProgressBar::new(values.len() as u64).with_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} settings  {prefix} {msg}  [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut rows = Vec::new();
    for value in &values {
        let mut scene = base.clone();
        args.knob.apply(value, &mut scene)?;
        let a = column_width(&scene)?;
        bar.set_prefix(format!("{} = {value}", args.knob.name()));
        let run = run_front(&scene, a, |t| bar.set_message(format!("T = {t:.2}")));
        rows.push(Row {
            value: value.clone(),
            run,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();

    let name = args.knob.name();
    let csv_path = args.output.join(format!("study_{name}.csv"));
    let mut csv = String::from(
        "knob,value,particles,substeps,solver_iterations,wall_seconds,particle_substeps_per_second,worst_front_error,rms_front_error,status\n",
    );
    outln!("meshless study: dam break against Martin & Moyce (1952), sweeping {name}")?;
    outln!("  value        particles  sub-steps  iterations  wall [s]  worst error  rms error")?;
    for Row { value, run } in &rows {
        let rate = run.particles as f64 * run.substeps as f64 / run.seconds.max(1e-9);
        let (worst, rms) = run.error.map_or((f64::NAN, f64::NAN), |e| e);
        let status = run.status.to_string();
        writeln!(
            csv,
            "{name},{value},{},{},{},{:.3},{rate:.4e},{worst:.5},{rms:.5},{}",
            run.particles,
            run.substeps,
            run.iterations,
            run.seconds,
            status.replace(',', ";")
        )?;
        outln!(
            "  {:<12} {:>9}  {:>9}  {:>10}  {:>8.2}  {:>10.1} %  {:>7.1} %  {}",
            value,
            run.particles,
            run.substeps,
            run.iterations,
            run.seconds,
            100.0 * worst,
            100.0 * rms,
            if matches!(run.status, RunStatus::Ok) {
                ""
            } else {
                &status
            }
        )?;
    }
    chart::write_table(&csv_path, &csv)?;

    let points: Vec<chart::Point> = rows
        .iter()
        .filter_map(|r| {
            r.run.error.map(|(_, rms)| chart::Point {
                cost: r.run.seconds,
                error: 100.0 * rms,
                label: r.value.clone(),
            })
        })
        .collect();
    let png_path = args.output.join(format!("study_{name}.png"));
    chart::draw_and_report(
        &png_path,
        &format!("dam break: front error against cost, sweeping {name}"),
        "rms front error, 1 <= T <= 3 [%]",
        &points,
    )?;
    Ok(())
}
