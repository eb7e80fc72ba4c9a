//! The gRPC side: session control.

use crate::{ClientError, Design, OptimizeEvent};
use meshless_proto::v1::{self, simulation_client::SimulationClient};
use tokio_stream::{Stream, StreamExt};
use tonic::metadata::{AsciiMetadataValue, MetadataKey};
use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Endpoint};
use tonic_health::pb::health_check_response::ServingStatus;
use tonic_health::pb::{HealthCheckRequest, health_client::HealthClient};

/// Who a client is to the server, sent with every call.
#[derive(Clone, Default, PartialEq, Eq)]
pub struct Identity {
    /// The bearer token of a server with tokens (`--tokens-file`).
    pub token: Option<String>,
    /// Names this client instance (1 to 64 letters, digits, `.`, `_`,
    /// `-`): one instance drives a session at a time. Unset: the token's
    /// principal as a whole drives (as each `meshless session` command
    /// does).
    pub client_id: Option<String>,
    /// Takes control of sessions another instance of the same principal
    /// drives, instead of being refused with ABORTED.
    pub take_over: bool,
}

/// The token is a secret: debug output shows only whether there is one.
impl std::fmt::Debug for Identity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Identity")
            .field("token", &self.token.as_ref().map(|_| "<set>"))
            .field("client_id", &self.client_id)
            .field("take_over", &self.take_over)
            .finish()
    }
}

/// How a client checks a server it reaches over `https://` and, where the
/// server asks for one (mutual TLS), the certificate it shows. The
/// default trusts the public web CAs and shows none.
#[derive(Clone, Default, PartialEq, Eq)]
pub struct Tls {
    /// The CA (PEM) that signed the server's certificate, in place of the
    /// public web CAs.
    pub ca: Option<Vec<u8>>,
    /// The certificate chain and private key (PEM) this client presents.
    pub client: Option<(Vec<u8>, Vec<u8>)>,
    /// The name the server's certificate must carry when it is not the
    /// URL's host (a server reached by an address or through a tunnel).
    pub domain: Option<String>,
}

/// The private key is a secret: debug output shows only whether there is one.
impl std::fmt::Debug for Tls {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tls")
            .field("ca", &self.ca.as_ref().map(|_| "<set>"))
            .field("client", &self.client.as_ref().map(|_| "<set>"))
            .field("domain", &self.domain)
            .finish()
    }
}

impl Tls {
    fn client_config(&self) -> ClientTlsConfig {
        let mut config = match &self.ca {
            Some(ca) => ClientTlsConfig::new().ca_certificate(Certificate::from_pem(ca)),
            None => ClientTlsConfig::new().with_webpki_roots(),
        };
        if let Some((cert, key)) = &self.client {
            config = config.identity(tonic::transport::Identity::from_pem(cert, key));
        }
        if let Some(domain) = &self.domain {
            config = config.domain_name(domain.clone());
        }
        config
    }
}

/// The metadata an [`Identity`] puts on every call, checked once.
#[derive(Clone)]
struct Stamp {
    headers: Vec<(MetadataKey<tonic::metadata::Ascii>, AsciiMetadataValue)>,
}

impl std::fmt::Debug for Stamp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let keys: Vec<&str> = self.headers.iter().map(|(k, _)| k.as_str()).collect();
        f.debug_struct("Stamp").field("keys", &keys).finish()
    }
}

impl Stamp {
    fn new(identity: &Identity) -> std::result::Result<Self, String> {
        let value = |what: &str, text: &str| {
            AsciiMetadataValue::try_from(text)
                .map_err(|_| format!("the {what} must be visible ASCII text"))
        };
        let mut headers = Vec::new();
        if let Some(token) = &identity.token {
            let mut bearer = value("token", &format!("Bearer {token}"))?;
            bearer.set_sensitive(true);
            headers.push((MetadataKey::from_static("authorization"), bearer));
        }
        if let Some(id) = &identity.client_id {
            headers.push((
                MetadataKey::from_static("meshless-client"),
                value("client id", id)?,
            ));
        }
        if identity.take_over {
            headers.push((
                MetadataKey::from_static("meshless-take-over"),
                AsciiMetadataValue::from_static("true"),
            ));
        }
        Ok(Self { headers })
    }
}

impl tonic::service::Interceptor for Stamp {
    fn call(
        &mut self,
        mut request: tonic::Request<()>,
    ) -> std::result::Result<tonic::Request<()>, tonic::Status> {
        for (key, value) in &self.headers {
            request.metadata_mut().insert(key.clone(), value.clone());
        }
        Ok(request)
    }
}

type Grpc = SimulationClient<InterceptedService<Channel, Stamp>>;

/// A connection to a meshless server. Cheap to clone; calls may run
/// concurrently.
#[derive(Debug, Clone)]
pub struct Client {
    grpc: Grpc,
    /// The gRPC health service beside it (open: no token needed).
    health: HealthClient<Channel>,
}

type Result<T> = std::result::Result<T, ClientError>;

fn session_ref(id: &str) -> v1::SessionRef {
    v1::SessionRef {
        session_id: id.to_owned(),
    }
}

impl Client {
    /// Connects to a server at `url`, e.g. `http://127.0.0.1:50051`.
    ///
    /// # Errors
    /// [`ClientError::Connect`] when the URL is malformed or unreachable.
    pub async fn connect(url: &str) -> Result<Self> {
        Self::connect_as(url, &Identity::default()).await
    }

    /// Connects to a server at `url` as `identity` (a token, a client
    /// instance).
    ///
    /// # Errors
    /// [`ClientError::Connect`] when the URL is malformed or unreachable,
    /// or the token or client id is not visible ASCII.
    pub async fn connect_as(url: &str, identity: &Identity) -> Result<Self> {
        Self::connect_with(url, identity, &Tls::default()).await
    }

    /// Connects to a server at `url` as `identity`; an `https://` URL
    /// checks the server's certificate and shows the client's as `tls`
    /// says.
    ///
    /// # Errors
    /// As [`Client::connect_as`]; a TLS setting on an `http://` URL, and
    /// a certificate the server or this client refuses (the message says
    /// which).
    pub async fn connect_with(url: &str, identity: &Identity, tls: &Tls) -> Result<Self> {
        let stamp = Stamp::new(identity).map_err(|message| ClientError::Connect {
            url: url.to_owned(),
            message,
        })?;
        let connect_error = |e: tonic::transport::Error| {
            // The useful part ("Connection refused") sits deep in the chain.
            let mut message = e.to_string();
            let mut source = std::error::Error::source(&e);
            while let Some(cause) = source {
                let cause_text = cause.to_string();
                if !message.ends_with(&cause_text) {
                    message = format!("{message}: {cause_text}");
                }
                source = cause.source();
            }
            ClientError::Connect {
                url: url.to_owned(),
                message,
            }
        };
        let mut endpoint = Endpoint::from_shared(url.to_owned()).map_err(connect_error)?;
        if url.starts_with("https://") {
            endpoint = endpoint
                .tls_config(tls.client_config())
                .map_err(connect_error)?;
        } else if *tls != Tls::default() {
            return Err(ClientError::Connect {
                url: url.to_owned(),
                message: "TLS settings (a CA, a client certificate, a domain) need an \
                          https:// URL"
                    .into(),
            });
        }
        let channel = endpoint.connect().await.map_err(connect_error)?;
        let health = HealthClient::new(channel.clone());
        let grpc = SimulationClient::with_interceptor(channel, stamp)
            .max_decoding_message_size(usize::MAX)
            // A Restore request carries a whole snapshot; the server has
            // its own limit (`ServerInfo.max_snapshot_bytes`).
            .max_encoding_message_size(usize::MAX);
        Ok(Self { grpc, health })
    }

    fn grpc(&self) -> Grpc {
        self.grpc.clone()
    }

    /// Whether the server's `meshless.v1.Simulation` service is serving,
    /// by the gRPC health service (what probes and container health
    /// checks ask).
    ///
    /// # Errors
    /// [`ClientError::Rpc`] when the health service does not answer.
    pub async fn health(&self) -> Result<bool> {
        let reply = self
            .health
            .clone()
            .check(HealthCheckRequest {
                service: "meshless.v1.Simulation".into(),
            })
            .await?
            .into_inner();
        Ok(reply.status == ServingStatus::Serving as i32)
    }

    /// Version, limits and zenoh endpoints of the server.
    ///
    /// # Errors
    /// [`ClientError::Rpc`] with the server's status.
    pub async fn server_info(&self) -> Result<v1::ServerInfo> {
        Ok(self
            .grpc()
            .get_server_info(v1::GetServerInfoRequest {})
            .await?
            .into_inner())
    }

    /// Creates a session from a scene message.
    ///
    /// # Errors
    /// `INVALID_ARGUMENT` naming the bad field, `RESOURCE_EXHAUSTED` at a limit.
    pub async fn create_session(&self, scene: v1::SceneSpec) -> Result<v1::Session> {
        self.create(v1::create_session_request::Source::Scene(scene), Vec::new())
            .await
    }

    /// Creates a session from the text of a TOML scene file.
    ///
    /// # Errors
    /// As [`Client::create_session`]; parse errors give the line.
    pub async fn create_session_toml(&self, toml: &str) -> Result<v1::Session> {
        self.create_session_toml_with_observers(toml, Vec::new())
            .await
    }

    /// Creates a session from the text of a TOML scene file that the
    /// principals in `observers` (or `"*"`, everyone) may see read-only.
    ///
    /// # Errors
    /// As [`Client::create_session_toml`]; `INVALID_ARGUMENT` naming a bad
    /// observer.
    pub async fn create_session_toml_with_observers(
        &self,
        toml: &str,
        observers: Vec<String>,
    ) -> Result<v1::Session> {
        self.create(
            v1::create_session_request::Source::SceneToml(toml.to_owned()),
            observers,
        )
        .await
    }

    async fn create(
        &self,
        source: v1::create_session_request::Source,
        observers: Vec<String>,
    ) -> Result<v1::Session> {
        let request = v1::CreateSessionRequest {
            source: Some(source),
            observers,
        };
        Ok(self.grpc().create_session(request).await?.into_inner())
    }

    /// # Errors
    /// `NOT_FOUND` for an unknown id.
    pub async fn get_session(&self, id: &str) -> Result<v1::Session> {
        Ok(self.grpc().get_session(session_ref(id)).await?.into_inner())
    }

    /// Every session the caller may see, oldest first, without their
    /// scenes ([`Client::get_session`] has them).
    ///
    /// # Errors
    /// [`ClientError::Rpc`] with the server's status.
    pub async fn list_sessions(&self) -> Result<Vec<v1::Session>> {
        Ok(self
            .grpc()
            .list_sessions(v1::ListSessionsRequest {})
            .await?
            .into_inner()
            .sessions)
    }

    /// # Errors
    /// `NOT_FOUND` for an unknown id.
    pub async fn delete_session(&self, id: &str) -> Result<()> {
        self.grpc().delete_session(session_ref(id)).await?;
        Ok(())
    }

    /// Advances a session by `steps` steps and returns once they are done.
    ///
    /// # Errors
    /// `FAILED_PRECONDITION` while running or faulted.
    pub async fn step(&self, id: &str, steps: u64) -> Result<v1::Session> {
        let request = v1::StepRequest {
            session_id: id.to_owned(),
            steps,
        };
        Ok(self.grpc().step(request).await?.into_inner())
    }

    /// Runs a session in the background until simulated time `until`;
    /// `realtime_factor` paces it against the wall clock.
    ///
    /// # Errors
    /// `INVALID_ARGUMENT` for a time not after the session's time.
    pub async fn run_until(
        &self,
        id: &str,
        until: f64,
        realtime_factor: Option<f64>,
    ) -> Result<v1::Session> {
        self.run(
            id,
            v1::run_request::Until::UntilTime(until),
            realtime_factor,
        )
        .await
    }

    /// Runs a session in the background until paused.
    ///
    /// # Errors
    /// `FAILED_PRECONDITION` while running or faulted.
    pub async fn run_forever(&self, id: &str, realtime_factor: Option<f64>) -> Result<v1::Session> {
        self.run(id, v1::run_request::Until::Forever(true), realtime_factor)
            .await
    }

    async fn run(
        &self,
        id: &str,
        until: v1::run_request::Until,
        realtime_factor: Option<f64>,
    ) -> Result<v1::Session> {
        let request = v1::RunRequest {
            session_id: id.to_owned(),
            until: Some(until),
            realtime_factor,
        };
        Ok(self.grpc().run(request).await?.into_inner())
    }

    /// # Errors
    /// `NOT_FOUND` for an unknown id.
    pub async fn pause(&self, id: &str) -> Result<v1::Session> {
        Ok(self.grpc().pause(session_ref(id)).await?.into_inner())
    }

    /// # Errors
    /// `FAILED_PRECONDITION` unless a run is paused.
    pub async fn resume(&self, id: &str) -> Result<v1::Session> {
        Ok(self.grpc().resume(session_ref(id)).await?.into_inner())
    }

    /// # Errors
    /// `NOT_FOUND` for an unknown id.
    pub async fn reset(&self, id: &str) -> Result<v1::Session> {
        Ok(self.grpc().reset(session_ref(id)).await?.into_inner())
    }

    /// The session's current status, then each state change until it is
    /// deleted (state `CLOSED`).
    ///
    /// # Errors
    /// `NOT_FOUND` for an unknown id.
    pub async fn watch_status(
        &self,
        id: &str,
    ) -> Result<impl Stream<Item = Result<v1::SessionStatus>> + Send + Unpin + use<>> {
        let stream = self
            .grpc()
            .watch_status(session_ref(id))
            .await?
            .into_inner();
        Ok(stream.map(|item| item.map_err(ClientError::from)))
    }

    /// The latest frame over gRPC (no zenoh needed).
    ///
    /// # Errors
    /// `NOT_FOUND` for an unknown id; [`ClientError::Decode`] for a bad frame.
    pub async fn latest_frame(&self, id: &str) -> Result<crate::FrameView> {
        let frame = self
            .grpc()
            .get_latest_frame(session_ref(id))
            .await?
            .into_inner();
        crate::FrameView::from_proto(frame)
    }

    /// The latest frame once it is newer than frame number `after` (0:
    /// any), waiting up to `wait` (at most a minute) on the server; with
    /// its number, which the next poll passes as `after`. `None` when no
    /// newer frame came in time. One poll at a time is a subscription
    /// that skips the frames a slow reader would not keep up with.
    ///
    /// # Errors
    /// `NOT_FOUND`, `PERMISSION_DENIED`, `INVALID_ARGUMENT` for a wait
    /// over a minute, or a frame that does not decode.
    pub async fn next_frame(
        &self,
        id: &str,
        after: u64,
        wait: std::time::Duration,
    ) -> Result<Option<(u64, crate::FrameView)>> {
        let request = v1::NextFrameRequest {
            session_id: id.to_owned(),
            after,
            wait_ms: u32::try_from(wait.as_millis()).unwrap_or(u32::MAX),
        };
        let reply = self.grpc().next_frame(request).await?.into_inner();
        if reply.frame.is_empty() {
            return Ok(None);
        }
        let frame = <v1::Frame as prost::Message>::decode(reply.frame)
            .map_err(|e| ClientError::Decode(format!("NextFrame's frame: {e}")))?;
        Ok(Some((reply.number, crate::FrameView::from_proto(frame)?)))
    }

    /// Applies constraint edits, all or nothing; returns the session's
    /// constraints in name order.
    ///
    /// # Errors
    /// `INVALID_ARGUMENT` naming the constraint at fault (nothing changed).
    pub async fn edit_constraints(
        &self,
        id: &str,
        edits: Vec<v1::ConstraintEdit>,
    ) -> Result<Vec<v1::Constraint>> {
        let request = v1::EditConstraintsRequest {
            session_id: id.to_owned(),
            edits,
        };
        Ok(self
            .grpc()
            .edit_constraints(request)
            .await?
            .into_inner()
            .constraints)
    }

    /// The session's constraints in name order.
    ///
    /// # Errors
    /// `NOT_FOUND` for an unknown id.
    pub async fn list_constraints(&self, id: &str) -> Result<Vec<v1::Constraint>> {
        Ok(self
            .grpc()
            .list_constraints(session_ref(id))
            .await?
            .into_inner()
            .constraints)
    }

    /// Starts an optimisation: progress events, then the design. Dropping
    /// the stream cancels it.
    ///
    /// # Errors
    /// `INVALID_ARGUMENT` for bad settings, at the call or as the stream's
    /// error; `CANCELLED`, `ABORTED` (an energy diverged) on the stream.
    pub async fn optimize(
        &self,
        request: v1::OptimizeRequest,
    ) -> Result<impl Stream<Item = Result<OptimizeEvent>> + Send + Unpin + use<>> {
        let stream = self.grpc().optimize(request).await?.into_inner();
        Ok(stream.map(|item| {
            let v1::OptimizeEvent { event } = item?;
            match event {
                Some(v1::optimize_event::Event::Progress(p)) => Ok(OptimizeEvent::Progress(p)),
                Some(v1::optimize_event::Event::Result(r)) => {
                    Design::from_proto(r).map(OptimizeEvent::Done)
                }
                None => Err(ClientError::Decode(
                    "an optimisation event without a kind".into(),
                )),
            }
        }))
    }

    /// Optimises to the end, calling `on_progress` for each report.
    ///
    /// # Errors
    /// As [`Client::optimize`]; [`ClientError::Closed`] when the stream
    /// ends without a design.
    pub async fn optimize_with(
        &self,
        request: v1::OptimizeRequest,
        mut on_progress: impl FnMut(&v1::DesignProgress),
    ) -> Result<Design> {
        let mut events = self.optimize(request).await?;
        while let Some(event) = events.next().await {
            match event? {
                OptimizeEvent::Progress(p) => on_progress(&p),
                OptimizeEvent::Done(design) => return Ok(design),
            }
        }
        Err(ClientError::Closed)
    }

    /// Cancels the session's optimisation; returns whether one was
    /// running. Its stream then ends with `CANCELLED`.
    ///
    /// # Errors
    /// `NOT_FOUND` for an unknown id.
    pub async fn cancel_optimize(&self, id: &str) -> Result<bool> {
        Ok(self
            .grpc()
            .cancel_optimize(session_ref(id))
            .await?
            .into_inner()
            .cancelled)
    }

    /// The session's last successful design.
    ///
    /// # Errors
    /// `NOT_FOUND` before the first; [`ClientError::Decode`] for a
    /// malformed one.
    pub async fn get_design(&self, id: &str) -> Result<Design> {
        Design::from_proto(self.grpc().get_design(session_ref(id)).await?.into_inner())
    }

    /// Steps `steps` times with progress about every `interval` seconds
    /// (0: the server's default), the last message marked `done`.
    /// Dropping the stream stops the steps at the last completed one.
    ///
    /// # Errors
    /// `INVALID_ARGUMENT` for a bad count or interval,
    /// `FAILED_PRECONDITION` while running or faulted, at the call or on
    /// the stream.
    pub async fn simulate_steps(
        &self,
        id: &str,
        steps: u64,
        interval: f64,
    ) -> Result<impl Stream<Item = Result<v1::SimulateProgress>> + Send + Unpin + use<>> {
        let stream = self
            .grpc()
            .simulate_steps(v1::SimulateStepsRequest {
                session_id: id.to_owned(),
                steps,
                progress_interval: interval,
            })
            .await?
            .into_inner();
        Ok(stream.map(|item| item.map_err(ClientError::from)))
    }

    /// A snapshot of the session's state (scene, systems, clock,
    /// constraints, last design) as an opaque blob in `data`.
    ///
    /// # Errors
    /// `PERMISSION_DENIED` for anyone but the owner, `RESOURCE_EXHAUSTED`
    /// over the server's snapshot limit.
    pub async fn snapshot(&self, id: &str) -> Result<v1::SessionSnapshot> {
        Ok(self.grpc().snapshot(session_ref(id)).await?.into_inner())
    }

    /// Restores a snapshot's `data` into a new session (`into` unset),
    /// owned by this client, or into the session `into` names (same
    /// scene, not running). `observers` unset keeps the snapshot's.
    ///
    /// # Errors
    /// `INVALID_ARGUMENT` for a blob of another build, truncated,
    /// corrupted or of another scene; nothing changes then.
    pub async fn restore(
        &self,
        data: Vec<u8>,
        into: Option<&str>,
        observers: Option<Vec<String>>,
    ) -> Result<v1::Session> {
        Ok(self
            .grpc()
            .restore(v1::RestoreRequest {
                data,
                session_id: into.unwrap_or_default().to_owned(),
                observers: observers.map(|principals| v1::ObserverList { principals }),
            })
            .await?
            .into_inner())
    }

    /// Removes the particles of system `system` whose ids `remove` lists
    /// and adds new ones at `positions` moving at `velocities`, all or
    /// nothing, from the session's next step. Returns the session and the
    /// ids the new particles get (the next ids in order; a frame's `id`
    /// field names every particle, [`crate::FrameView::ids`]).
    ///
    /// # Errors
    /// `INVALID_ARGUMENT` naming what is wrong (an unknown system or id, a
    /// position outside the domain, a velocity that is not finite);
    /// `RESOURCE_EXHAUSTED` past the particles the session was created
    /// with. Nothing changes then.
    pub async fn change_particles(
        &self,
        id: &str,
        system: u32,
        remove: &[u32],
        positions: &[[f64; 3]],
        velocities: &[[f64; 3]],
    ) -> Result<(v1::Session, std::ops::Range<u32>)> {
        let vec3 = |&[x, y, z]: &[f64; 3]| v1::Vec3 { x, y, z };
        let answer = self
            .grpc()
            .change_particles(v1::ChangeParticlesRequest {
                session_id: id.to_owned(),
                system,
                remove: remove.to_vec(),
                insert_positions: positions.iter().map(vec3).collect(),
                insert_velocities: velocities.iter().map(vec3).collect(),
            })
            .await?
            .into_inner();
        let first = answer.first_inserted_id;
        let session = answer
            .session
            .ok_or_else(|| ClientError::Decode("ChangeParticles answered no session".into()))?;
        Ok((session, first..first.saturating_add(answer.inserted)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn tls_settings_on_a_plain_url_are_refused_before_connecting() {
        let tls = Tls {
            ca: Some(b"-----BEGIN CERTIFICATE-----".to_vec()),
            ..Tls::default()
        };
        // Port 9 (discard) is never dialled: the check comes first.
        let e = Client::connect_with("http://127.0.0.1:9", &Identity::default(), &tls)
            .await
            .expect_err("refused");
        assert!(e.to_string().contains("https://"), "{e}");
    }

    #[test]
    fn debug_output_hides_the_private_key() {
        let tls = Tls {
            client: Some((b"cert".to_vec(), b"SECRET KEY".to_vec())),
            ..Tls::default()
        };
        let shown = format!("{tls:?}");
        assert!(!shown.contains("SECRET"), "{shown}");
        assert!(shown.contains("<set>"), "{shown}");
    }
}
