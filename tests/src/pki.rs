//! Certificates for the TLS tests, made fresh by each test with rcgen: a
//! CA, a server certificate it signed for `localhost` and `127.0.0.1`, a
//! client certificate it signed, and an unrelated CA that trusts none of
//! them. Each is a PEM file in a temporary directory, as the server and
//! the clients read them.

use crate::TempDir;
use anyhow::Result;
use rcgen::{BasicConstraints, CertificateParams, DnType, IsCa, Issuer, KeyPair};
use std::path::PathBuf;

/// The PEM files of a test's public-key infrastructure.
#[derive(Debug)]
pub struct TestPki {
    /// The CA that signed the server's and the client's certificates.
    pub ca: PathBuf,
    /// The server's certificate, for `localhost` and `127.0.0.1`.
    pub server_cert: PathBuf,
    /// The server's private key.
    pub server_key: PathBuf,
    /// A client certificate with common name `client`.
    pub client_cert: PathBuf,
    /// The client's private key.
    pub client_key: PathBuf,
    /// A CA that signed nothing here: trusting it alone trusts no one.
    pub stranger_ca: PathBuf,
    /// Where the files live (removed on drop).
    pub dir: TempDir,
}

impl TestPki {
    /// Makes the CAs, keys and certificates in `meshless-{name}-{pid}`.
    ///
    /// # Errors
    /// When rcgen fails or a file cannot be written.
    pub fn new(name: &str) -> Result<Self> {
        let dir = TempDir::new(name);
        let write = |file: &str, pem: String| -> Result<PathBuf> {
            let path = dir.0.join(file);
            std::fs::write(&path, pem)?;
            Ok(path)
        };
        let (ca_pem, ca) = authority("meshless test CA")?;
        let (stranger_pem, _) = authority("a stranger's CA")?;
        let server_key = KeyPair::generate()?;
        let mut server = CertificateParams::new(vec!["localhost".into(), "127.0.0.1".into()])?;
        server
            .distinguished_name
            .push(DnType::CommonName, "meshless-server");
        let server_cert = server.signed_by(&server_key, &ca)?;
        let client_key = KeyPair::generate()?;
        let mut client = CertificateParams::new(Vec::<String>::new())?;
        client.distinguished_name.push(DnType::CommonName, "client");
        let client_cert = client.signed_by(&client_key, &ca)?;
        Ok(Self {
            ca: write("ca.pem", ca_pem)?,
            server_cert: write("server.pem", server_cert.pem())?,
            server_key: write("server-key.pem", server_key.serialize_pem())?,
            client_cert: write("client.pem", client_cert.pem())?,
            client_key: write("client-key.pem", client_key.serialize_pem())?,
            stranger_ca: write("stranger-ca.pem", stranger_pem)?,
            dir,
        })
    }

    /// Writes a zenoh configuration file (JSON5) named `file` that sets
    /// the `transport/link/tls` entries given, paths as strings, and
    /// `enable_mtls` (both sides of mutual TLS need it: a client shows its
    /// certificate only then).
    ///
    /// # Errors
    /// When the file cannot be written.
    pub fn zenoh_config(
        &self,
        file: &str,
        tls: &[(&str, &std::path::Path)],
        mutual: bool,
    ) -> Result<PathBuf> {
        let mut entries: Vec<String> = tls
            .iter()
            .map(|(key, path)| format!("{key}: {:?}", path.display().to_string()))
            .collect();
        entries.push(format!("enable_mtls: {mutual}"));
        let text = format!(
            "{{ transport: {{ link: {{ tls: {{ {} }} }} }} }}\n",
            entries.join(", ")
        );
        let path = self.dir.0.join(file);
        std::fs::write(&path, text)?;
        Ok(path)
    }
}

/// A self-signed CA: its certificate's PEM and the issuer that signs with it.
fn authority(name: &str) -> Result<(String, Issuer<'static, KeyPair>)> {
    let key = KeyPair::generate()?;
    let mut params = CertificateParams::new(Vec::<String>::new())?;
    params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    params.distinguished_name.push(DnType::CommonName, name);
    let cert = params.self_signed(&key)?;
    Ok((cert.pem(), Issuer::new(params, key)))
}
