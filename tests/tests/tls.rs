//! TLS on both planes, end to end with the real server and certificates
//! made by each test (`meshless_tests::pki`): gRPC over `https://` with
//! the server's certificate (and, with `--tls-client-ca`, the client's),
//! zenoh over `tls/` endpoints with the same CA. A client that speaks
//! plain text, trusts another CA or shows no certificate where one is
//! asked for gets nothing; files that are not what their flag says stop
//! the server at start, naming the flag; an expired certificate starts
//! the server with a warning naming it.

use meshless_client::{Client, ClientError, Identity, Tls, ZenohLink};
use meshless_tests::pki::TestPki;
use meshless_tests::{ServerProcess, binary, failed_start, make_fifo, small_scene, within};
use std::path::Path;

/// `https://localhost:PORT` of a server started with TLS.
fn https_url(server: &ServerProcess) -> String {
    let port = server
        .grpc_url
        .rsplit_once(':')
        .map(|(_, port)| port.to_owned())
        .expect("a port");
    format!("https://localhost:{port}")
}

/// A server whose gRPC endpoint and only zenoh endpoint (`tls/`) show
/// the PKI's server certificate; `mutual` asks clients of both for a
/// certificate of its CA. Returns it with its `https://localhost` URL.
async fn tls_server(pki: &TestPki, mutual: bool) -> (ServerProcess, String) {
    let mut entries = vec![
        ("listen_certificate", pki.server_cert.as_path()),
        ("listen_private_key", pki.server_key.as_path()),
    ];
    if mutual {
        entries.push(("root_ca_certificate", pki.ca.as_path()));
    }
    let zenoh_config = pki
        .zenoh_config("zenoh-server.json5", &entries, mutual)
        .expect("config");
    let path = |p: &Path| p.display().to_string();
    let (cert, key, ca, config) = (
        path(&pki.server_cert),
        path(&pki.server_key),
        path(&pki.ca),
        path(&zenoh_config),
    );
    let mut args = vec![
        "--tls-cert",
        &cert,
        "--tls-key",
        &key,
        "--zenoh-config",
        &config,
    ];
    if mutual {
        args.extend(["--tls-client-ca", ca.as_str()]);
    }
    let server = ServerProcess::spawn_listening("tls/127.0.0.1:0", &args)
        .await
        .expect("server starts");
    let url = https_url(&server);
    (server, url)
}

/// TLS settings trusting `ca`, with a client certificate when given.
fn tls(ca: &Path, client: Option<(&Path, &Path)>) -> Tls {
    let read = |path: &Path| std::fs::read(path).expect("a PEM file");
    Tls {
        ca: Some(read(ca)),
        client: client.map(|(cert, key)| (read(cert), read(key))),
        domain: None,
    }
}

/// Connects and asks for the server's information: the first call is
/// where a refused handshake shows when the connection itself is lazy.
async fn info(url: &str, tls: &Tls) -> Result<meshless_client::v1::ServerInfo, ClientError> {
    let client = within(
        "connect",
        Client::connect_with(url, &Identity::default(), tls),
    )
    .await?;
    within("server info", client.server_info()).await
}

/// A zenoh link whose configuration file is `config`.
async fn zenoh_link(endpoints: &[String], config: &Path) -> Result<ZenohLink, ClientError> {
    let config = zenoh::Config::from_file(config).expect("a valid zenoh configuration");
    within("zenoh connect", ZenohLink::connect_with(endpoints, config)).await
}

/// The server's certificate on gRPC and zenoh: a client trusting the CA
/// drives a session and receives its frames over `tls/`; plain text, a
/// stranger's CA and the public web CAs get nothing on either plane.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn both_planes_speak_tls_and_refuse_clients_that_do_not_trust_the_server() {
    let pki = TestPki::new("tls-server").expect("certificates");
    let (server, url) = tls_server(&pki, false).await;
    assert!(
        server.zenoh.iter().all(|e| e.starts_with("tls/")),
        "{:?}",
        server.zenoh
    );

    let trusted = tls(&pki.ca, None);
    let client = within(
        "connect",
        Client::connect_with(&url, &Identity::default(), &trusted),
    )
    .await
    .expect("a client trusting the CA connects");
    let session = within("create", client.create_session_toml(&small_scene()))
        .await
        .expect("session");
    let zenoh_client = pki
        .zenoh_config(
            "zenoh-client.json5",
            &[("root_ca_certificate", &pki.ca)],
            false,
        )
        .expect("config");
    let link = zenoh_link(&server.zenoh, &zenoh_client)
        .await
        .expect("zenoh over TLS");
    let frames = within("subscribe", link.frames(&session.id))
        .await
        .expect("frames");
    within("step", client.step(&session.id, 1))
        .await
        .expect("steps");
    let frame = within("frame over TLS", frames.recv())
        .await
        .expect("frame");
    assert_eq!(
        (frame.session_id.as_str(), frame.step),
        (session.id.as_str(), 1)
    );
    link.close().await;

    // gRPC: plain text, a stranger's CA, the public CAs.
    let plain = server.grpc_url.clone();
    let refused = [
        (plain.as_str(), Tls::default()),
        (url.as_str(), tls(&pki.stranger_ca, None)),
        (url.as_str(), Tls::default()),
    ];
    for (url, tls) in refused {
        let e = info(url, &tls).await.expect_err("refused");
        assert!(
            !matches!(e, ClientError::Rpc(ref s) if s.code() == tonic::Code::Ok),
            "{url}: {e}"
        );
    }
    // The certificate is checked against the name the client expects.
    let elsewhere = Tls {
        domain: Some("not-the-server.example".into()),
        ..trusted.clone()
    };
    let e = info(&url, &elsewhere)
        .await
        .expect_err("the certificate does not name not-the-server.example");
    assert!(e.to_string().contains("certificate"), "{e}");

    // zenoh: no TLS configuration at all, and a stranger's CA.
    let no_tls = pki
        .zenoh_config("zenoh-plain.json5", &[], false)
        .expect("config");
    let stranger = pki
        .zenoh_config(
            "zenoh-stranger.json5",
            &[("root_ca_certificate", &pki.stranger_ca)],
            false,
        )
        .expect("config");
    for config in [no_tls, stranger] {
        assert!(
            zenoh_link(&server.zenoh, &config).await.is_err(),
            "{} connected",
            config.display()
        );
    }
}

/// Mutual TLS on both planes: the server asks for a certificate its CA
/// signed; a client without one is refused, a client with one is served.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mutual_tls_refuses_clients_without_a_certificate() {
    let pki = TestPki::new("tls-mutual").expect("certificates");
    let ca = pki.ca.as_path();
    let (server, url) = tls_server(&pki, true).await;

    assert!(
        info(&url, &tls(ca, None)).await.is_err(),
        "no client certificate"
    );
    let served = info(&url, &tls(ca, Some((&pki.client_cert, &pki.client_key))))
        .await
        .expect("a client with a certificate of the CA is served");
    assert_eq!(served.zenoh_locators, server.zenoh);

    let without = pki
        .zenoh_config(
            "zenoh-anonymous.json5",
            &[("root_ca_certificate", ca)],
            false,
        )
        .expect("config");
    assert!(zenoh_link(&server.zenoh, &without).await.is_err());
    let with = pki
        .zenoh_config(
            "zenoh-client.json5",
            &[
                ("root_ca_certificate", ca),
                ("connect_certificate", &pki.client_cert),
                ("connect_private_key", &pki.client_key),
            ],
            true,
        )
        .expect("config");
    let link = zenoh_link(&server.zenoh, &with)
        .await
        .expect("zenoh with a client certificate");
    link.close().await;
}

/// Missing files, a key where the certificate belongs, PEM blocks that
/// hold no certificate, a lone `--tls-key`: the server does not start and
/// names the flag to change.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_tls_files_stop_the_server_naming_the_flag() {
    let pki = TestPki::new("tls-bad-files").expect("certificates");
    let junk = pki.dir.0.join("junk.pem");
    std::fs::write(
        &junk,
        "-----BEGIN CERTIFICATE-----\nbm90IGEgY2VydA==\n-----END CERTIFICATE-----\n",
    )
    .expect("write");
    let path = |p: &Path| p.display().to_string();
    let (cert, key, junk) = (path(&pki.server_cert), path(&pki.server_key), path(&junk));
    let cases: [(Vec<&str>, &str); 5] = [
        (
            vec!["--tls-cert", "/nonexistent/cert.pem", "--tls-key", &key],
            "--tls-cert /nonexistent/cert.pem",
        ),
        (vec!["--tls-cert", &key, "--tls-key", &key], "--tls-cert"),
        (vec!["--tls-cert", &cert, "--tls-key", &cert], "--tls-key"),
        (vec!["--tls-cert", &junk, "--tls-key", &key], "--tls-cert"),
        (vec!["--tls-key", &key], "--tls-cert"),
    ];
    for (args, expected) in cases {
        let output = within(
            "server refuses to start",
            tokio::process::Command::new(binary("meshless-server").expect("built"))
                .args([
                    "--grpc-addr",
                    "127.0.0.1:0",
                    "--zenoh-listen",
                    "tcp/127.0.0.1:0",
                ])
                .args(&args)
                .output(),
        )
        .await
        .expect("runs");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success(), "{args:?} started");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
}

/// `--tls-cert` naming a FIFO or `/dev/zero` stops the start at once,
/// naming the flag, the file and what it is.
#[tokio::test]
async fn a_certificate_that_is_no_regular_file_fails_fast() {
    let pki = TestPki::new("tls-special").expect("certificates");
    let fifo = pki.dir.0.join("fifo.pem");
    make_fifo(&fifo);
    let (fifo, key) = (
        fifo.display().to_string(),
        pki.server_key.display().to_string(),
    );
    for (special, kind) in [
        (fifo.as_str(), "a FIFO"),
        ("/dev/zero", "a character device"),
    ] {
        let (ok, stderr) = failed_start(&["--tls-cert", special, "--tls-key", &key]).await;
        assert!(!ok, "--tls-cert {special} started");
        assert!(
            stderr.contains(&format!("--tls-cert {special}")) && stderr.contains(kind),
            "{special}: {stderr}"
        );
    }
}

/// A certificate that expired is served (an operator may be renewing
/// it), but the start warns, naming the file and the date, since every
/// client will refuse the handshake.
#[tokio::test]
async fn an_expired_certificate_is_named_in_the_log_at_start() {
    let pki = TestPki::new("tls-expired").expect("certificates");
    let key = rcgen::KeyPair::generate().expect("key");
    let mut params = rcgen::CertificateParams::new(vec!["localhost".into()]).expect("parameters");
    params.not_before = rcgen::date_time_ymd(2019, 1, 1);
    params.not_after = rcgen::date_time_ymd(2020, 1, 1);
    let cert = params.self_signed(&key).expect("certificate");
    let (cert_file, key_file, log) = (
        pki.dir.0.join("expired.pem"),
        pki.dir.0.join("expired-key.pem"),
        pki.dir.0.join("server.log"),
    );
    std::fs::write(&cert_file, cert.pem()).expect("write");
    std::fs::write(&key_file, key.serialize_pem()).expect("write");
    let cert_path = cert_file.display().to_string();
    let server = ServerProcess::spawn_logging(
        &[
            "--tls-cert",
            &cert_path,
            "--tls-key",
            &key_file.display().to_string(),
        ],
        &log,
    )
    .await
    .expect("an expired certificate still starts the server");
    let warned = within("the warning", async {
        let mut ticks = tokio::time::interval(std::time::Duration::from_millis(20));
        loop {
            ticks.tick().await;
            let text = std::fs::read_to_string(&log).unwrap_or_default();
            if let Some(line) = text.lines().find(|l| l.contains("expired")) {
                return line.to_owned();
            }
        }
    })
    .await;
    assert!(
        warned.contains("WARN") && warned.contains(&cert_path) && warned.contains("2020"),
        "the warning names neither the file nor the date: {warned}"
    );
    drop(server);

    // A valid certificate says nothing of the kind.
    let log = pki.dir.0.join("valid.log");
    let server = ServerProcess::spawn_logging(
        &[
            "--tls-cert",
            &pki.server_cert.display().to_string(),
            "--tls-key",
            &pki.server_key.display().to_string(),
        ],
        &log,
    )
    .await
    .expect("server");
    drop(server);
    let text = std::fs::read_to_string(&log).expect("log");
    assert!(!text.contains("expired"), "{text}");
}
