//! `meshless-server`: read the configuration (file, environment, flags),
//! start logging, serve.

use clap::{CommandFactory, FromArgMatches, Parser, ValueEnum};
use meshless_server::ServerConfig;
use meshless_server::config_file;
use std::process::ExitCode;

/// How log lines are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum LogFormat {
    /// One human-readable line per event.
    Text,
    /// One JSON object per line (for log collectors), with the span's
    /// fields (the session id) on every line.
    Json,
}

/// The meshless simulation server: gRPC control, zenoh frame streams.
#[derive(Debug, Parser)]
#[command(name = "meshless-server", version)]
struct Cli {
    #[command(flatten)]
    server: ServerConfig,
    /// Log filter, e.g. `info` or `meshless_server=debug`.
    #[arg(long, env = "MESHLESS_LOG", default_value = "info")]
    log: String,
    /// Log line format.
    #[arg(long, env = "MESHLESS_LOG_FORMAT", value_enum, default_value = "text")]
    log_format: LogFormat,
    /// A TOML file of settings, keyed by the flags' names
    /// (`grpc-addr = "0.0.0.0:50051"`); environment variables and flags
    /// override it.
    #[arg(long, env = "MESHLESS_CONFIG")]
    config: Option<std::path::PathBuf>,
    /// Print the resolved configuration (as a file this server reads,
    /// each value with where it came from) and exit.
    #[arg(long)]
    print_config: bool,
}

#[tokio::main]
async fn main() -> ExitCode {
    let args: Vec<_> = std::env::args_os().collect();
    let file = config_file::config_path(&args);
    let (command, from_file) = match &file {
        Some(path) => match config_file::with_file(Cli::command(), path) {
            Ok(loaded) => loaded,
            Err(e) => {
                eprintln!("meshless-server: {e}");
                return ExitCode::FAILURE;
            }
        },
        None => (Cli::command(), Vec::new()),
    };
    let matches = command.clone().get_matches_from(args);
    let cli = match Cli::from_arg_matches(&matches) {
        Ok(cli) => cli,
        Err(e) => e.exit(),
    };
    if cli.print_config {
        let file = file.as_deref().map(|path| (path, from_file.as_slice()));
        print!("{}", config_file::render(&command, &matches, file));
        return ExitCode::SUCCESS;
    }
    let filter = tracing_subscriber::EnvFilter::new(&cli.log);
    let logs = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr);
    match cli.log_format {
        LogFormat::Text => logs.init(),
        LogFormat::Json => logs.json().with_current_span(true).init(),
    }
    match meshless_server::serve_until_signal(cli.server).await {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("meshless-server: {e:#}");
            ExitCode::FAILURE
        }
    }
}
