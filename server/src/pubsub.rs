//! The server's zenoh session: opened once, shared by every session's
//! publishers and queryables.

use crate::config::{ServerConfig, ZenohMode, ZenohPublishers};
use anyhow::{Context, Result};

/// Zenoh access control that lets no other peer publish through the
/// server's session: every put, delete, queryable declaration and reply
/// that arrives from another peer is dropped, on every key (a put on
/// `**` would reach the session keys' subscribers too). What is left to
/// peers is what a client needs: declaring subscribers and sending
/// queries. zenoh checks a message against a deny rule by inclusion, so
/// the rule's `**` covers every key and every wildcard.
const SERVER_ONLY_ACL: &str = r#"{
  enabled: true,
  default_permission: "allow",
  rules: [{
    id: "peers-never-publish",
    messages: ["put", "delete", "declare_queryable", "reply", "liveliness_token"],
    flows: ["ingress"],
    permission: "deny",
    key_exprs: ["**"],
  }],
  subjects: [{ id: "every-peer" }],
  policies: [{ rules: ["peers-never-publish"], subjects: ["every-peer"] }],
}"#;

/// Opens the zenoh session and returns it with the endpoints it listens on.
///
/// Multicast scouting is off: peers find the server through explicit
/// endpoints (and gossip), never by flooding the network. The handshake
/// limits are the server's own (`--zenoh-accept-pending`,
/// `--zenoh-accept-timeout-ms`): at zenoh's defaults 100 silent TCP
/// connections refuse every new subscriber for 10 s at a time
/// (docs/operations.md, "Zenoh limits").
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
    let mut zconfig = match &config.zenoh_config {
        Some(path) => zenoh::Config::from_file(path)
            .map_err(|e| anyhow::anyhow!("--zenoh-config {}: {e}", path.display()))?,
        None => zenoh::Config::default(),
    };
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
    set(
        &mut zconfig,
        "transport/unicast/accept_pending",
        config.zenoh_accept_pending.into(),
    )?;
    set(
        &mut zconfig,
        "transport/unicast/accept_timeout",
        config.zenoh_accept_timeout_ms.into(),
    )?;
    if config.zenoh_publishers == ZenohPublishers::Server {
        let own_acl = zconfig
            .get_json("access_control/enabled")
            .is_ok_and(|enabled| enabled == "true");
        if own_acl {
            anyhow::bail!(
                "the --zenoh-config file enables its own access_control; keep it and pass \
                 --zenoh-publishers any, or remove it and let the server install its rule"
            );
        }
        zconfig
            .insert_json5("access_control", SERVER_ONLY_ACL)
            .map_err(|e| anyhow::anyhow!("zenoh access control: {e}"))?;
    }
    let session = zenoh::open(zconfig)
        .await
        .map_err(|e| anyhow::anyhow!("cannot open zenoh session (listen {listen:?}): {e}"))?;
    Ok((session, listen))
}

/// Replaces a port 0 of a TCP or TLS endpoint with a free port, so the
/// server can report the endpoint it really listens on.
fn resolve_port(endpoint: &str) -> Result<String> {
    let Some((protocol, addr)) = endpoint.split_once('/') else {
        return Ok(endpoint.to_owned());
    };
    if protocol != "tcp" && protocol != "tls" {
        return Ok(endpoint.to_owned());
    }
    let Some((host, "0")) = addr.rsplit_once(':') else {
        return Ok(endpoint.to_owned());
    };
    let bind_host = host.trim_start_matches('[').trim_end_matches(']');
    let listener = std::net::TcpListener::bind((bind_host, 0))
        .with_context(|| format!("cannot bind {endpoint} to find a free port"))?;
    let port = listener.local_addr()?.port();
    Ok(format!("{protocol}/{host}:{port}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_server_only_rule_is_a_valid_zenoh_access_control() {
        let mut config = zenoh::Config::default();
        config
            .insert_json5("access_control", SERVER_ONLY_ACL)
            .expect("zenoh accepts the rule");
        assert_eq!(
            config
                .get_json("access_control/default_permission")
                .expect("set"),
            "\"allow\""
        );
    }

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
        assert!(
            resolve_port("tls/127.0.0.1:0")
                .expect("free port")
                .starts_with("tls/127.0.0.1:")
        );
        assert_eq!(
            resolve_port("udp/1.2.3.4:0").expect("as is"),
            "udp/1.2.3.4:0"
        );
    }
}
