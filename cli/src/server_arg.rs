//! `--server` and the flags that go with it, shared by every networked
//! command. A leaf: it imports no command module, so any of them can use
//! it without closing a loop through `command.rs`, which dispatches to them.

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
