//! `meshless`: the command line of meshless. Parses the arguments, starts
//! logging and runs the command (`command.rs`). The commands that run the
//! engine or a server in this process need the `embedded` feature (on by
//! default); without it only `session` and `watch` remain.

/// `println!` that returns the write's `io::Result` instead of panicking:
/// output piped into a program that stops reading (`meshless run … |
/// head`) ends the command quietly (see [`closed_pipe`]) rather than with
/// a panic.
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), $($arg)*)
    }};
}

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
mod server_arg;
mod session;
#[cfg(feature = "embedded")]
mod study;
#[cfg(feature = "embedded")]
mod study_design;
#[cfg(feature = "embedded")]
mod study_fracture;
#[cfg(feature = "embedded")]
mod study_modal;
mod study_shell;
#[cfg(feature = "embedded")]
mod study_solid;
mod summary;
#[cfg(feature = "embedded")]
mod sweep;
mod watch;

use clap::Parser;
use std::process::ExitCode;

/// Whether `error` comes from writing to a pipe whose reader has gone,
/// which ends a command successfully, as it does `cat` or `ls`.
fn closed_pipe(error: &anyhow::Error) -> bool {
    error.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

#[tokio::main]
async fn main() -> ExitCode {
    let args = command::Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::new(&args.log))
        .with_writer(std::io::stderr)
        .init();
    match command::run(args).await {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if closed_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("meshless: {e:#}");
            ExitCode::FAILURE
        }
    }
}
