//! `meshless optimise PROBLEM.toml`: shape or motion design (tutorial
//! Section 8) of a scene's elastic solid, over gRPC like any client: an
//! embedded server by default, or `--server URL`. Writes the designed
//! surface and the design particles per frame and prints the energies.
//!
//! The problem file names a scene (`scene = "path.toml"`, relative to the
//! problem file, or an inline `[scene]` table), the solid (`system`), the
//! problem (`"shape"` or `"motion"`), the optimiser's `[design]` and
//! `[motion]` settings and its `[[constraints]]`, all in the engine's
//! serde format (`meshless_engine::design`).

use crate::output::SurfaceFormat;
use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use meshless_client::{Client, Design, v1};
use meshless_engine::design::{
    Constraint, Derivative, DesignParams, DesignTarget, MotionParams, TemporalBasis, blend,
};
use meshless_engine::io::{MeshFormat, write_mesh_ply, write_obj, write_vtk};
use meshless_engine::math::Vector;
use meshless_engine::scene::{DEFAULT_MAX_MESH_BYTES, MeshFiles};
use meshless_engine::{BuildOptions, FieldData, FieldKind, Frame, Scene};
use meshless_server::ServerConfig;
use meshless_wire::design::{
    constraint_to_proto, design_settings_to_proto, motion_settings_to_proto,
};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Debug, clap::Args)]
pub struct OptimiseArgs {
    /// A TOML design problem, e.g. scenes/design_stretch.toml.
    problem: PathBuf,
    /// gRPC URL of a meshless server; without it an embedded one runs.
    #[arg(long)]
    server: Option<String>,
    /// Folder for design_FRAME.EXT (the surface) and
    /// design_particles_FRAME.vtk.
    #[arg(long, default_value = "out/optimise")]
    out: PathBuf,
    #[arg(long, value_enum, default_value = "obj")]
    format: SurfaceFormat,
}

/// A design problem file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ProblemFile {
    scene: SceneSource,
    #[serde(default)]
    system: u32,
    problem: ProblemKind,
    /// Playback frames per second of design time (motion).
    playback_rate: Option<f64>,
    #[serde(default)]
    design: DesignParams,
    #[serde(default)]
    motion: MotionParams,
    #[serde(default)]
    constraints: Vec<Constraint>,
}

#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum SceneSource {
    File(PathBuf),
    Inline(toml::Table),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
enum ProblemKind {
    Shape,
    Motion,
}

impl ProblemFile {
    fn read(path: &Path) -> Result<(Self, String)> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let mut problem: Self =
            toml::from_str(&text).with_context(|| format!("{}", path.display()))?;
        let base = path.parent().unwrap_or(Path::new("."));
        // Meshes travel inline: a server reads none of the client's files.
        let scene = match &problem.scene {
            SceneSource::File(scene) => meshless_client::read_scene_file(&base.join(scene))?,
            SceneSource::Inline(table) => {
                let text = toml::to_string(table).context("the inline [scene]")?;
                meshless_client::inline_meshes(&text, base)
                    .map_err(|e| anyhow::anyhow!("the inline [scene]: {e}"))?
            }
        };
        for constraint in &mut problem.constraints {
            constraint
                .load_mesh(&MeshFiles::Host, DEFAULT_MAX_MESH_BYTES)
                .with_context(|| format!("{}", path.display()))?;
        }
        Ok((problem, scene))
    }

    fn request(&self, session_id: &str) -> v1::OptimizeRequest {
        let problem = match self.problem {
            ProblemKind::Shape => v1::optimize_request::Problem::Shape(v1::ShapeProblem {}),
            ProblemKind::Motion => v1::optimize_request::Problem::Motion(v1::MotionProblem {
                settings: Some(motion_settings_to_proto(&self.motion)),
                playback_rate: self.playback_rate,
            }),
        };
        v1::OptimizeRequest {
            session_id: session_id.to_owned(),
            system: self.system,
            design: Some(design_settings_to_proto(&self.design)),
            problem: Some(problem),
            playback: false,
        }
    }
}

pub async fn optimise(args: OptimiseArgs) -> Result<()> {
    let (problem, scene) = ProblemFile::read(&args.problem)?;
    match &args.server {
        Some(url) => drive(&args, &problem, &scene, url).await,
        None => {
            let server = meshless_server::start(ServerConfig::ephemeral()).await?;
            let result = drive(
                &args,
                &problem,
                &scene,
                &format!("http://{}", server.grpc_addr),
            )
            .await;
            server.stop().await?;
            result
        }
    }
}

async fn drive(args: &OptimiseArgs, problem: &ProblemFile, scene: &str, url: &str) -> Result<()> {
    let client = Client::connect(url).await?;
    let session = client.create_session_toml(scene).await?;
    let id = session.id.clone();
    let result = design(&client, &id, problem).await;
    client.delete_session(&id).await?;
    let (design, wall) = result?;

    // The surface is embedded in the design particles here, from the same
    // scene and settings the server designed with.
    let world = Scene::from_toml_str(scene)?.build(&BuildOptions::default())?;
    let target = DesignTarget::new(&world, problem.system as usize, &problem.design)?;
    if target.body().len() != design.rest_positions.len() {
        bail!(
            "the server designed {} particles, this build samples {}; are both the same version?",
            design.rest_positions.len(),
            target.body().len()
        );
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let format = MeshFormat::from(args.format);
    let mut surfaces = 0;
    let poses = poses(
        &design,
        problem.playback_rate.unwrap_or(DEFAULT_PLAYBACK_RATE),
    )?;
    for (k, (time, u)) in poses.iter().enumerate() {
        let time = *time;
        if let Some(surface) = target.surface(u) {
            let path = args
                .out
                .join(format!("design_{k:04}.{}", format.extension()));
            let comment = format!("meshless design, frame {k}, t = {time} s");
            let mut file = std::io::BufWriter::new(
                std::fs::File::create(&path)
                    .with_context(|| format!("cannot create {}", path.display()))?,
            );
            match format {
                MeshFormat::Obj => {
                    write_obj(&mut file, &surface.mesh, Some(&surface.normals), &comment)
                }
                MeshFormat::Ply => {
                    write_mesh_ply(&mut file, &surface.mesh, Some(&surface.normals), &comment)
                }
            }
            .with_context(|| format!("cannot write {}", path.display()))?;
            surfaces += 1;
        }
        let positions: Vec<[f64; 3]> = target
            .body()
            .rest()
            .iter()
            .zip(u)
            .map(|(x, u)| (x + u).into())
            .collect();
        let path = args.out.join(format!("design_particles_{k:04}.vtk"));
        let mut file = std::io::BufWriter::new(
            std::fs::File::create(&path)
                .with_context(|| format!("cannot create {}", path.display()))?,
        );
        write_vtk(&mut file, &particles_frame(k, time, &positions))
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    summary(args, &design, wall, surfaces, poses.len())?;
    Ok(())
}

/// Playback frames per second of design time when the problem names none.
const DEFAULT_PLAYBACK_RATE: f64 = 30.0;

/// The design's poses to write: a shape's one, or a motion sampled at
/// `rate` frames per second along the temporal MLS (Eq. 80), the same
/// frames the server plays back.
fn poses(design: &Design, rate: f64) -> Result<Vec<(f64, Vec<Vector>)>> {
    let frames: Vec<Vec<Vector>> = design
        .displacements
        .iter()
        .map(|f| f.iter().map(|&u| Vector::from(u)).collect())
        .collect();
    if design.times.len() < 2 {
        return Ok(design.times.iter().copied().zip(frames).collect());
    }
    if !(rate.is_finite() && rate > 0.0) {
        bail!("playback_rate is {rate}; give a positive number of frames per second");
    }
    let basis = TemporalBasis::new(&design.times)?;
    let (start, end) = (design.times[0], design.times[design.times.len() - 1]);
    let count = ((end - start) * rate).floor() as usize + 1;
    (0..count)
        .map(|k| {
            let t = (start + k as f64 / rate).min(end);
            Ok((t, blend(&basis, &frames, t, Derivative::Value)?))
        })
        .collect()
}

/// Sets the constraints and optimises, with a progress bar.
async fn design(client: &Client, id: &str, problem: &ProblemFile) -> Result<(Design, f64)> {
    let mut edits = vec![v1::ConstraintEdit {
        edit: Some(v1::constraint_edit::Edit::Clear(v1::ClearConstraints {})),
    }];
    edits.extend(problem.constraints.iter().map(|c| v1::ConstraintEdit {
        edit: Some(v1::constraint_edit::Edit::Add(constraint_to_proto(c))),
    }));
    client.edit_constraints(id, edits).await?;
    let bar = ProgressBar::new_spinner().with_style(
        ProgressStyle::with_template("{spinner} {msg}  [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    let start = Instant::now();
    let design = client
        .optimize_with(problem.request(id), |p| {
            let total = p.energies.as_ref().map_or(0.0, |e| {
                e.handle + e.rigidity + e.volume + e.velocity + e.acceleration + e.obstacle
            });
            bar.set_message(format!(
                "iteration {}  energy {total:.4e}  gradient {:.3e}  frames {}",
                p.iteration, p.gradient_norm, p.frames
            ));
            bar.tick();
        })
        .await;
    bar.finish_and_clear();
    Ok((design?, start.elapsed().as_secs_f64()))
}

/// The design particles as a frame, for the VTK writer.
fn particles_frame(k: usize, time: f64, positions: &[[f64; 3]]) -> Frame {
    Frame {
        step: k as u64,
        time,
        substeps: 0,
        substep_dt: 0.0,
        solver_iterations: 0,
        density_error: 0.0,
        capped: false,
        unconverged: 0,
        added: 0,
        particle_count: positions.len(),
        fields: vec![FieldData {
            kind: FieldKind::Position,
            components: 3,
            values: positions.iter().flatten().map(|&c| c as f32).collect(),
        }],
        bodies: Vec::new(),
        surface: None,
        solids: Vec::new(),
        solid_surfaces: Vec::new(),
        crack_surfaces: Vec::new(),
        ids: None,
    }
}

fn summary(
    args: &OptimiseArgs,
    design: &Design,
    wall: f64,
    surfaces: usize,
    poses: usize,
) -> std::io::Result<()> {
    let info = &design.info;
    outln!("meshless optimise: {}", args.problem.display())?;
    outln!(
        "  problem           {:?} of system {}, {} design particles",
        design.kind,
        design.system,
        design.rest_positions.len()
    )?;
    outln!(
        "  solver            {} iterations, {}, gradient {:.3e}",
        info.iterations,
        if info.converged {
            "converged"
        } else {
            "not converged"
        },
        info.gradient_norm
    )?;
    if design.times.len() > 1 {
        outln!(
            "  frames            {} ({} inserted), t in [{}, {}] s",
            design.times.len(),
            info.inserted,
            design.times[0],
            design.times[design.times.len() - 1]
        )?;
    }
    outln!("  wall time         {wall:.2} s")?;
    outln!("  energy            weighted, dimensionless")?;
    if let Some(e) = &info.energies {
        let terms = [
            ("handle", e.handle),
            ("rigidity", e.rigidity),
            ("volume", e.volume),
            ("velocity", e.velocity),
            ("acceleration", e.acceleration),
            ("obstacle", e.obstacle),
        ];
        for (name, value) in terms {
            outln!("    {name:<16} {value:.4e}")?;
        }
        let total: f64 = terms.iter().map(|(_, v)| v).sum();
        outln!("    {:<16} {total:.4e}", "total")?;
    }
    outln!(
        "  output            {}/design_*.{} ({surfaces} surfaces), design_particles_*.vtk ({poses})",
        args.out.display(),
        MeshFormat::from(args.format).extension()
    )?;
    Ok(())
}
