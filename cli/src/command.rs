//! The commands of the `meshless` binary: the argument parser, the
//! dispatch to each command's module. What several commands share lives in
//! the leaves `server_arg.rs` and `summary.rs`, which import no command, so
//! that no command module imports this one back.

use crate::server_arg::ServerArg;
#[cfg(feature = "embedded")]
use crate::{demo, optimise, run, study};
use crate::{session, watch};
use clap::{Parser, Subcommand};

/// Meshless physics as a service: run scenes embedded, or drive a
/// meshless-server over gRPC and watch its frames over zenoh.
#[derive(Debug, Parser)]
#[command(name = "meshless", version)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Log filter, e.g. `info` or `meshless_server=debug`.
    #[arg(long, global = true, env = "MESHLESS_LOG", default_value = "warn")]
    pub log: String,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The main job: start an embedded server, run the dam break through
    /// it over gRPC and zenoh, write the frames, print a summary.
    #[cfg(feature = "embedded")]
    Demo(demo::DemoArgs),
    /// Shape or motion design of a scene's solid from a TOML problem file
    /// (embedded server unless --server): writes the designed surfaces.
    #[cfg(feature = "embedded")]
    Optimise(optimise::OptimiseArgs),
    /// Run a scene file in this process (no server) and write its frames.
    #[cfg(feature = "embedded")]
    Run(run::RunArgs),
    /// Sweep one speed-against-accuracy knob on the dam break: front error
    /// against Martin & Moyce and cost, as CSV and a PNG chart.
    #[cfg(feature = "embedded")]
    Study(study::StudyArgs),
    /// Create and drive sessions on a server.
    Session(session::SessionArgs),
    /// Print frame rates and particle counts of a session's zenoh stream.
    Watch(watch::WatchArgs),
    /// Ask the server's gRPC health service whether it serves: prints
    /// SERVING and exits 0, or says why not and exits 1 (a container's
    /// health check).
    Health(ServerArg),
}

/// Runs the parsed command.
///
/// # Errors
/// Whatever the command failed with, for printing.
pub async fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        #[cfg(feature = "embedded")]
        Command::Demo(args) => demo::demo(args).await,
        #[cfg(feature = "embedded")]
        Command::Optimise(args) => optimise::optimise(args).await,
        #[cfg(feature = "embedded")]
        Command::Run(args) => run::run(args),
        #[cfg(feature = "embedded")]
        Command::Study(args) => study::study(args),
        Command::Session(args) => session::session(args).await,
        Command::Watch(args) => watch::watch(args).await,
        Command::Health(server) => {
            if server.connect().await?.health().await? {
                outln!("SERVING")?;
                Ok(())
            } else {
                anyhow::bail!("{} is not serving", server.server)
            }
        }
    }
}
