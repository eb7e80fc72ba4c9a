//! `meshless-server`: parse configuration, start logging, serve.

use clap::Parser;
use meshless_server::ServerConfig;
use std::process::ExitCode;

/// The meshless simulation server: gRPC control, zenoh frame streams.
#[derive(Debug, Parser)]
#[command(name = "meshless-server", version)]
struct Cli {
    #[command(flatten)]
    config: ServerConfig,
    /// Log filter, e.g. `info` or `meshless_server=debug`.
    #[arg(long, env = "MESHLESS_LOG", default_value = "info")]
    log: String,
}

#[tokio::main]
async fn main() -> ExitCode {
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::new(&cli.log))
        .with_writer(std::io::stderr)
        .init();
    match meshless_server::serve_until_signal(cli.config).await {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("meshless-server: {e:#}");
            ExitCode::FAILURE
        }
    }
}
