//! The server's zenoh session: opened once, shared by every session's
//! publishers and queryables.

use crate::config::{ServerConfig, ZenohMode};
use anyhow::{Context, Result};

/// Opens the zenoh session and returns it with the endpoints it listens on.
///
/// Multicast scouting is off: peers find the server through explicit
/// endpoints (and gossip), never by flooding the network.
///
/// # Errors
/// A bad endpoint, or a port that cannot be bound.
pub async fn open(config: &ServerConfig) -> Result<(zenoh::Session, Vec<String>)> {
    let listen = match config.zenoh_mode {
        ZenohMode::Peer => config
            .zenoh_listen
            .iter()
            .map(|e| resolve_port(e))
            .collect::<Result<Vec<_>>>()?,
        ZenohMode::Client => Vec::new(),
    };
    let mut zconfig = zenoh::Config::default();
    let set = |zconfig: &mut zenoh::Config, key: &str, value: serde_json::Value| {
        zconfig
            .insert_json5(key, &value.to_string())
            .map_err(|e| anyhow::anyhow!("zenoh config {key} = {value}: {e}"))
    };
    set(&mut zconfig, "mode", config.zenoh_mode.as_str().into())?;
    set(&mut zconfig, "listen/endpoints", listen.clone().into())?;
    set(
        &mut zconfig,
        "connect/endpoints",
        config.zenoh_connect.clone().into(),
    )?;
    set(&mut zconfig, "scouting/multicast/enabled", false.into())?;
    let session = zenoh::open(zconfig)
        .await
        .map_err(|e| anyhow::anyhow!("cannot open zenoh session (listen {listen:?}): {e}"))?;
    Ok((session, listen))
}

/// Replaces a TCP port 0 with a free port, so the server can report the
/// endpoint it really listens on.
fn resolve_port(endpoint: &str) -> Result<String> {
    let Some(addr) = endpoint.strip_prefix("tcp/") else {
        return Ok(endpoint.to_owned());
    };
    let Some((host, "0")) = addr.rsplit_once(':') else {
        return Ok(endpoint.to_owned());
    };
    let bind_host = host.trim_start_matches('[').trim_end_matches(']');
    let listener = std::net::TcpListener::bind((bind_host, 0))
        .with_context(|| format!("cannot bind {endpoint} to find a free port"))?;
    let port = listener.local_addr()?.port();
    Ok(format!("tcp/{host}:{port}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn port_zero_is_replaced_by_a_free_port() {
        let resolved = resolve_port("tcp/127.0.0.1:0").expect("free port");
        let port: u16 = resolved
            .rsplit_once(':')
            .and_then(|(_, p)| p.parse().ok())
            .expect("a port");
        assert_ne!(port, 0);
        assert_eq!(
            resolve_port("tcp/127.0.0.1:7447").expect("as is"),
            "tcp/127.0.0.1:7447"
        );
        assert_eq!(
            resolve_port("udp/1.2.3.4:0").expect("as is"),
            "udp/1.2.3.4:0"
        );
    }
}
