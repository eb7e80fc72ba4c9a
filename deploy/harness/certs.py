"""Throwaway credentials for the compose harness, written to a volume
before the router and the servers start: a CA, one certificate naming
every host given (the router and the replicas, and 127.0.0.1 for the
containers' own health checks), a tokens file for the servers and the
harness's token.

    python3 deploy/harness/certs.py DIR NAME...

Files, named as Kubernetes secrets name them: ca.crt, tls.crt, tls.key,
tokens, harness.token. The local topology (topology.py) writes the same
with :func:`write_credentials`. Never for production: operators bring
their own PKI (docs/deploy.md).
"""

import secrets
import sys
from pathlib import Path

import trustme


def write_credentials(out: Path, names: list[str]) -> str:
    """Writes the files above to ``out``, the certificate naming ``names``
    besides localhost and 127.0.0.1, and returns the harness's token."""
    out.mkdir(parents=True, exist_ok=True)
    ca = trustme.CA()
    cert = ca.issue_cert(*names, "localhost", "127.0.0.1")
    ca.cert_pem.write_to_path(str(out / "ca.crt"))
    cert.cert_chain_pems[0].write_to_path(str(out / "tls.crt"))
    cert.private_key_pem.write_to_path(str(out / "tls.key"))
    token = secrets.token_hex(16)
    (out / "tokens").write_text(f"harness {token}\n")
    (out / "harness.token").write_text(token + "\n")
    return token


def main() -> None:
    out, names = Path(sys.argv[1]), sys.argv[2:]
    if not names:
        raise SystemExit("usage: certs.py DIR NAME...")
    write_credentials(out, names)
    print(f"certs.py: CA, a certificate for {', '.join(names)} and a token in {out}")


if __name__ == "__main__":
    main()
