//! `meshless session …`: one subcommand per gRPC call.

use crate::command::ServerArg;
use anyhow::Result;
use clap::Subcommand;
use meshless_client::v1;
use std::path::PathBuf;

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

pub async fn session(args: SessionArgs) -> Result<()> {
    let client = args.server.connect().await?;
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
    }
    Ok(())
}
