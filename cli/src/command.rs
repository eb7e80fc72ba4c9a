//! The commands of the `meshless` binary: the argument parser, the
//! dispatch to each command's module, and what several commands share.

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

/// `--server` as every networked command spells it.
#[derive(Debug, Clone, clap::Args)]
pub struct ServerArg {
    /// gRPC URL of the meshless server.
    #[arg(
        long,
        global = true,
        env = "MESHLESS_SERVER",
        default_value = "http://127.0.0.1:50051"
    )]
    pub server: String,
    /// Where calls that name a session go, when sessions live on several
    /// replicas: a URL template whose `{server}` becomes the server name
    /// the session id starts with (`--server-name` of the server), e.g.
    /// `https://{server}.meshless-replicas:50051`. Calls that name no
    /// session (create, list, restore) still go to `--server`.
    #[arg(long, global = true, env = "MESHLESS_ROUTE")]
    pub route: Option<String>,
    /// Bearer token for a server with tokens (prefer the environment
    /// variable: a flag shows in the process list).
    #[arg(long, global = true, env = "MESHLESS_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Names this client instance; one instance drives a session at a
    /// time (unset: the token's principal as a whole).
    #[arg(long, global = true, env = "MESHLESS_CLIENT_ID")]
    pub client_id: Option<String>,
    /// Take control of a session another client instance drives.
    #[arg(long, global = true)]
    pub take_over: bool,
    /// The CA (PEM) that signed an `https://` server's certificate
    /// (default: the public web CAs).
    #[arg(long, global = true, env = "MESHLESS_TLS_CA")]
    pub tls_ca: Option<std::path::PathBuf>,
    /// This client's certificate (PEM), for a server that asks for one.
    #[arg(long, global = true, env = "MESHLESS_TLS_CERT", requires = "tls_key")]
    pub tls_cert: Option<std::path::PathBuf>,
    /// The private key of `--tls-cert` (PEM).
    #[arg(long, global = true, env = "MESHLESS_TLS_KEY", requires = "tls_cert")]
    pub tls_key: Option<std::path::PathBuf>,
    /// The name the server's certificate carries, when not the URL's host.
    #[arg(long, global = true, env = "MESHLESS_TLS_DOMAIN")]
    pub tls_domain: Option<String>,
}

impl ServerArg {
    /// Connects to `--server` with the token, client id and TLS files
    /// given.
    ///
    /// # Errors
    /// An unreadable TLS file, or as
    /// [`meshless_client::Client::connect_with`].
    pub async fn connect(&self) -> anyhow::Result<meshless_client::Client> {
        self.connect_to(&self.server).await
    }

    /// Connects to the replica that holds `session_id` by `--route`, or
    /// to `--server` without one.
    ///
    /// # Errors
    /// A route that cannot place the id, or as [`Self::connect`].
    pub async fn connect_for(&self, session_id: &str) -> anyhow::Result<meshless_client::Client> {
        match &self.route {
            Some(template) => {
                let url = meshless_client::Route::new(template)?.url_for(session_id)?;
                self.connect_to(&url).await
            }
            None => self.connect().await,
        }
    }

    async fn connect_to(&self, url: &str) -> anyhow::Result<meshless_client::Client> {
        let read = |path: &std::path::Path, flag: &str| {
            std::fs::read(path).map_err(|e| anyhow::anyhow!("{flag} {}: {e}", path.display()))
        };
        let tls = meshless_client::Tls {
            ca: self
                .tls_ca
                .as_deref()
                .map(|path| read(path, "--tls-ca"))
                .transpose()?,
            client: match (&self.tls_cert, &self.tls_key) {
                (Some(cert), Some(key)) => {
                    Some((read(cert, "--tls-cert")?, read(key, "--tls-key")?))
                }
                _ => None,
            },
            domain: self.tls_domain.clone(),
        };
        let identity = meshless_client::Identity {
            token: self.token.clone(),
            client_id: self.client_id.clone(),
            take_over: self.take_over,
        };
        Ok(meshless_client::Client::connect_with(url, &identity, &tls).await?)
    }
}

/// A particle count for the summaries of `run`, `demo` and `watch`,
/// split into fluid and solid particles when the scene has elastic solids
/// (`solids`: each solid's count), since the two move so differently.
pub(crate) fn particle_summary(total: u64, solids: &[u64]) -> String {
    if solids.is_empty() {
        return total.to_string();
    }
    let in_solids: u64 = solids.iter().sum();
    let plural = if solids.len() == 1 { "" } else { "s" };
    format!(
        "{total}  ({} fluid, {in_solids} in {} solid{plural})",
        total.saturating_sub(in_solids),
        solids.len()
    )
}

#[cfg(test)]
mod tests {
    use super::particle_summary;

    #[test]
    fn summaries_split_solid_particles_from_the_fluid() {
        assert_eq!(particle_summary(125, &[]), "125");
        assert_eq!(
            particle_summary(300, &[100, 50]),
            "300  (150 fluid, 150 in 2 solids)"
        );
        assert_eq!(particle_summary(40, &[40]), "40  (0 fluid, 40 in 1 solid)");
    }
}
