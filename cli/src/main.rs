//! `meshless`: the command line of meshless. Parses the arguments, starts
//! logging and runs the command (`command.rs`). The commands that run the
//! engine or a server in this process need the `embedded` feature (on by
//! default); without it only `session` and `watch` remain.

#[cfg(feature = "embedded")]
mod chart;
mod command;
#[cfg(feature = "embedded")]
mod demo;
#[cfg(feature = "embedded")]
mod optimise;
#[cfg(feature = "embedded")]
mod output;
#[cfg(feature = "embedded")]
mod run;
mod session;
#[cfg(feature = "embedded")]
mod study;
#[cfg(feature = "embedded")]
mod study_design;
#[cfg(feature = "embedded")]
mod study_solid;
mod watch;

use clap::Parser;
use std::process::ExitCode;

#[tokio::main]
async fn main() -> ExitCode {
    let args = command::Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::new(&args.log))
        .with_writer(std::io::stderr)
        .init();
    match command::run(args).await {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("meshless: {e:#}");
            ExitCode::FAILURE
        }
    }
}
