//! `meshless session …`: one subcommand per gRPC call.

use crate::server_arg::ServerArg;
use anyhow::{Context, Result};
use clap::Subcommand;
use indicatif::{ProgressBar, ProgressStyle};
use meshless_client::{Client, v1};
use std::path::PathBuf;
use tokio_stream::StreamExt;

#[derive(Debug, clap::Args)]
pub struct SessionArgs {
    #[command(subcommand)]
    action: Action,
    #[command(flatten)]
    server: ServerArg,
}

#[derive(Debug, Subcommand)]
enum Action {
    /// Create a session from a TOML scene file.
    Create {
        scene: PathBuf,
        /// A principal that may see the session read-only (repeat it;
        /// "*" for every caller).
        #[arg(long = "observer")]
        observers: Vec<String>,
    },
    /// List the server's sessions.
    List,
    /// Show one session.
    Get { id: String },
    /// Advance an idle or paused session and wait for the steps.
    Step {
        id: String,
        #[arg(short = 'n', long, default_value_t = 1)]
        steps: u64,
    },
    /// Start a background run.
    Run {
        id: String,
        /// Simulated time to stop at, in seconds.
        #[arg(long, conflicts_with = "forever", required_unless_present = "forever")]
        until: Option<f64>,
        /// Run until paused.
        #[arg(long)]
        forever: bool,
        /// Simulated seconds per wall-clock second (default: as fast as possible).
        #[arg(long)]
        realtime: Option<f64>,
    },
    /// Pause a run.
    Pause { id: String },
    /// Resume a paused run.
    Resume { id: String },
    /// Rebuild the world from its scene.
    Reset { id: String },
    /// Delete a session.
    Delete { id: String },
    /// Take many steps with a progress bar (SimulateSteps); Ctrl-C stops
    /// at the last completed step.
    Simulate {
        id: String,
        #[arg(short = 'n', long)]
        steps: u64,
        /// Seconds between progress reports.
        #[arg(long, default_value_t = 0.2)]
        interval: f64,
    },
    /// Save a snapshot of the session's state to a file.
    Snapshot {
        id: String,
        /// Where to write it (replaced whole: written beside it, then
        /// renamed).
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Restore a snapshot file into a new session, or into `--into`.
    Restore {
        file: PathBuf,
        /// An existing session of the same scene to restore into.
        #[arg(long)]
        into: Option<String>,
        /// Who else may see a new session (repeat it; "*" for every
        /// caller); unset keeps the snapshot's observers.
        #[arg(long = "observer")]
        observers: Vec<String>,
    },
}

fn state(status: Option<&v1::SessionStatus>) -> String {
    status.map_or_else(
        || "unknown".into(),
        |s| {
            let name = v1::SessionState::try_from(s.state)
                .map_or("unknown", |st| st.as_str_name())
                .trim_start_matches("SESSION_STATE_")
                .to_lowercase();
            format!(
                "{name} at step {} (t = {:.4} s): {}",
                s.step, s.time, s.reason
            )
        },
    )
}

fn print_session(session: &v1::Session) -> std::io::Result<()> {
    outln!(
        "{}  {:<20} {} particles  {}",
        session.id,
        if session.name.is_empty() {
            "-"
        } else {
            &session.name
        },
        session.particle_count,
        state(session.status.as_ref())
    )?;
    Ok(())
}

impl Action {
    /// The session the action names, which `--route` routes by.
    fn session_id(&self) -> Option<&str> {
        match self {
            Self::Create { .. } | Self::List | Self::Restore { into: None, .. } => None,
            Self::Restore { into: Some(id), .. }
            | Self::Get { id }
            | Self::Step { id, .. }
            | Self::Run { id, .. }
            | Self::Pause { id }
            | Self::Resume { id }
            | Self::Reset { id }
            | Self::Delete { id }
            | Self::Simulate { id, .. }
            | Self::Snapshot { id, .. } => Some(id),
        }
    }
}

pub async fn session(args: SessionArgs) -> Result<()> {
    let client = match args.action.session_id() {
        Some(id) => args.server.connect_for(id).await?,
        None => args.server.connect().await?,
    };
    match args.action {
        Action::Create { scene, observers } => {
            // Mesh files the scene names travel inline: the server reads
            // none of the client's.
            let text = meshless_client::read_scene_file(&scene)?;
            let session = client
                .create_session_toml_with_observers(&text, observers)
                .await?;
            print_session(&session)?;
            outln!("frames on zenoh: {}/frames", session.zenoh_key_prefix)?;
        }
        Action::List => {
            let sessions = client.list_sessions().await?;
            if sessions.is_empty() {
                outln!("no sessions")?;
            }
            for session in &sessions {
                print_session(session)?;
            }
        }
        Action::Get { id } => print_session(&client.get_session(&id).await?)?,
        Action::Step { id, steps } => print_session(&client.step(&id, steps).await?)?,
        Action::Run {
            id,
            until,
            forever: _,
            realtime,
        } => {
            let session = match until {
                Some(t) => client.run_until(&id, t, realtime).await?,
                None => client.run_forever(&id, realtime).await?,
            };
            print_session(&session)?;
        }
        Action::Pause { id } => print_session(&client.pause(&id).await?)?,
        Action::Resume { id } => print_session(&client.resume(&id).await?)?,
        Action::Reset { id } => print_session(&client.reset(&id).await?)?,
        Action::Delete { id } => {
            client.delete_session(&id).await?;
            outln!("deleted {id}")?;
        }
        Action::Simulate {
            id,
            steps,
            interval,
        } => simulate(&client, &id, steps, interval).await?,
        Action::Snapshot { id, output } => {
            let snapshot = client.snapshot(&id).await?;
            write_whole(&output, &snapshot.data)
                .with_context(|| format!("cannot write {}", output.display()))?;
            outln!(
                "{}: snapshot of {id} at step {} (t = {:.4} s), {} bytes",
                output.display(),
                snapshot.step,
                snapshot.time,
                snapshot.data.len()
            )?;
        }
        Action::Restore {
            file,
            into,
            observers,
        } => {
            let data =
                std::fs::read(&file).with_context(|| format!("cannot read {}", file.display()))?;
            let observers = (!observers.is_empty()).then_some(observers);
            let session = client.restore(data, into.as_deref(), observers).await?;
            print_session(&session)?;
        }
    }
    Ok(())
}

/// `data` written to `path` whole or not at all: a temporary file beside
/// it, flushed, then renamed over it.
fn write_whole(path: &std::path::Path, data: &[u8]) -> std::io::Result<()> {
    let mut temporary = path.as_os_str().to_owned();
    temporary.push(".tmp");
    let temporary = PathBuf::from(temporary);
    let mut file = std::fs::File::create(&temporary)?;
    std::io::Write::write_all(&mut file, data)?;
    file.sync_all()?;
    std::fs::rename(&temporary, path)
}

/// Steps with a progress bar; Ctrl-C drops the stream, which stops the
/// session at its last completed step.
async fn simulate(client: &Client, id: &str, steps: u64, interval: f64) -> Result<()> {
    let mut stream = client.simulate_steps(id, steps, interval).await?;
    let bar = ProgressBar::new(steps).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} steps  {msg}  [{elapsed} < {eta}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut last = None;
    loop {
        let next = tokio::select! {
            next = stream.next() => next,
            _ = tokio::signal::ctrl_c() => {
                bar.abandon_with_message("interrupted");
                drop(stream);
                let session = client.get_session(id).await?;
                return print_session(&session).map_err(Into::into);
            }
        };
        let Some(progress) = next else { break };
        let progress = progress?;
        bar.set_position(progress.steps_done);
        bar.set_message(format!("{:.3}x real time", progress.realtime_factor));
        last = Some(progress);
    }
    bar.finish();
    let Some(last) = last else {
        anyhow::bail!("the server ended the call without a report");
    };
    if let Some(status) = &last.status {
        outln!("{} steps; {}", last.steps_done, state(Some(status)))?;
    }
    if !last.done {
        anyhow::bail!("stopped after {} of {steps} steps", last.steps_done);
    }
    Ok(())
}
