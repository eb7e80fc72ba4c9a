//! TLS for the gRPC endpoint: the server's certificate chain and key, and
//! optionally a CA whose certificates clients must present (mutual TLS),
//! all PEM files named in the configuration.
//!
//! A file that is missing, unreadable or not PEM stops the server at
//! start with a message naming the flag, never at the first handshake.

use std::path::Path;
use std::time::Duration;
use tonic::transport::{Certificate, Identity, ServerTlsConfig};

/// Largest PEM file read: a chain of a few certificates is a few kB, so
/// anything near this is the wrong file.
const MAX_PEM_BYTES: u64 = 1 << 20;

/// Where the gRPC endpoint's TLS material lives.
#[derive(Debug, Clone, Copy)]
pub struct TlsFiles<'a> {
    /// The server's certificate chain (PEM), leaf first.
    pub cert: &'a Path,
    /// The private key of the leaf certificate (PEM: PKCS#8, PKCS#1 or SEC1).
    pub key: &'a Path,
    /// Clients must present a certificate this CA signed (PEM); `None`
    /// accepts any client, as tokens then identify them.
    pub client_ca: Option<&'a Path>,
}

/// Reads and checks the files into tonic's server configuration.
///
/// # Errors
/// A message naming the flag whose file is missing, unreadable, too large
/// or holds no PEM block of the kind expected.
/// A client has `handshake` (`--handshake-timeout`, which bounds the
/// whole connection until its first authenticated call too) to finish
/// the TLS handshake.
pub fn server_config(files: TlsFiles<'_>, handshake: Duration) -> Result<ServerTlsConfig, String> {
    let cert = read_pem(files.cert, "--tls-cert", "CERTIFICATE")?;
    warn_on_validity(&cert, files.cert);
    let key = read_pem(files.key, "--tls-key", "PRIVATE KEY")?;
    let mut config = ServerTlsConfig::new()
        .identity(Identity::from_pem(cert, key))
        .timeout(handshake);
    if let Some(ca) = files.client_ca {
        let ca = read_pem(ca, "--tls-client-ca", "CERTIFICATE")?;
        config = config.client_ca_root(Certificate::from_pem(ca));
    }
    Ok(config)
}

/// The bytes of a PEM file that holds at least one `label` block (`PRIVATE
/// KEY` also matches `RSA PRIVATE KEY` and `EC PRIVATE KEY`). Only a
/// regular file is read ([`crate::files`]): a FIFO or `/dev/zero` named
/// by mistake fails the start at once.
fn read_pem(path: &Path, flag: &str, label: &str) -> Result<Vec<u8>, String> {
    let bytes = crate::files::read_regular(path, MAX_PEM_BYTES).map_err(|e| match e {
        crate::files::FileError::TooLarge { .. } => format!(
            "{flag} {}: {e}; no PEM certificate or key is that large (at most {MAX_PEM_BYTES})",
            path.display()
        ),
        crate::files::FileError::Io(_) | crate::files::FileError::NotRegular { .. } => {
            format!("{flag} {}: {e}", path.display())
        }
    })?;
    let text = String::from_utf8_lossy(&bytes);
    let has_block = text
        .lines()
        .any(|line| line.starts_with("-----BEGIN ") && line.contains(label));
    if !has_block {
        return Err(format!(
            "{flag} {}: no PEM `{label}` block; give a PEM file (-----BEGIN {label}-----)",
            path.display()
        ));
    }
    Ok(bytes)
}

/// Why the leaf certificate of `chain` (PEM) is not valid at `now`, if it
/// is not: expired, or not yet valid. The server still starts (an
/// operator may be mid-renewal, and a clock may be wrong), but every
/// client will refuse the handshake, so the start says so. A chain that
/// does not parse says nothing here: rustls reports it at the handshake.
fn validity_problem(chain: &[u8], now: x509_parser::time::ASN1Time) -> Option<String> {
    let leaf = x509_parser::pem::Pem::iter_from_buffer(chain)
        .filter_map(Result::ok)
        .find(|pem| pem.label == "CERTIFICATE")?;
    let certificate = leaf.parse_x509().ok()?;
    let validity = certificate.validity();
    if now > validity.not_after {
        Some(format!(
            "expired on {}; clients will refuse the handshake until it is renewed",
            validity.not_after
        ))
    } else if now < validity.not_before {
        Some(format!(
            "is not valid before {}; clients will refuse the handshake until then (or check \
             this host's clock)",
            validity.not_before
        ))
    } else {
        None
    }
}

/// Logs a warning naming `path` when its leaf certificate is expired or
/// not yet valid ([`validity_problem`]).
fn warn_on_validity(chain: &[u8], path: &Path) {
    if let Some(problem) = validity_problem(chain, x509_parser::time::ASN1Time::now()) {
        tracing::warn!(file = %path.display(), "--tls-cert {}: the certificate {problem}", path.display());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A handshake timeout for the checks, which never reach a handshake.
    const WAIT: Duration = Duration::from_secs(10);

    fn temp_file(name: &str, content: &[u8]) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("meshless-tls-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join(name);
        std::fs::write(&path, content).expect("write");
        path
    }

    #[test]
    fn each_bad_file_is_told_by_its_flag() {
        let cert = temp_file(
            "cert.pem",
            b"-----BEGIN CERTIFICATE-----\nAA==\n-----END CERTIFICATE-----\n",
        );
        let key = temp_file(
            "key.pem",
            b"-----BEGIN EC PRIVATE KEY-----\nAA==\n-----END EC PRIVATE KEY-----\n",
        );
        let not_pem = temp_file("not.pem", b"hello");
        let missing = Path::new("/nonexistent/meshless/cert.pem");
        let error = |files| server_config(files, WAIT).expect_err("refused");

        let e = error(TlsFiles {
            cert: missing,
            key: &key,
            client_ca: None,
        });
        assert!(e.starts_with("--tls-cert /nonexistent"), "{e}");
        let e = error(TlsFiles {
            cert: &cert,
            key: &not_pem,
            client_ca: None,
        });
        assert!(
            e.starts_with("--tls-key") && e.contains("PRIVATE KEY"),
            "{e}"
        );
        let e = error(TlsFiles {
            cert: &cert,
            key: &key,
            client_ca: Some(&not_pem),
        });
        assert!(e.starts_with("--tls-client-ca"), "{e}");
        // A key where the certificate belongs is refused too.
        let e = error(TlsFiles {
            cert: &key,
            key: &key,
            client_ca: None,
        });
        assert!(
            e.starts_with("--tls-cert") && e.contains("CERTIFICATE"),
            "{e}"
        );
        assert!(
            server_config(
                TlsFiles {
                    cert: &cert,
                    key: &key,
                    client_ca: Some(&cert),
                },
                WAIT
            )
            .is_ok(),
            "well-formed PEM files pass this check; rustls judges their content"
        );
    }
}
