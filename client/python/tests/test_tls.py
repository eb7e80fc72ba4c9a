"""TLS from Python: the server's certificate on gRPC and zenoh, made by
trustme for each test; a client that does not trust the CA is refused."""

from __future__ import annotations

import grpc
import pytest
import trustme

from conftest import fixture, running_server
from meshless import Client, Frames

SCENE = fixture("python_tank")


def test_grpc_and_zenoh_over_tls(tmp_path):
    ca = trustme.CA()
    issued = ca.issue_cert("localhost", "127.0.0.1")
    cert, key, ca_pem = tmp_path / "cert.pem", tmp_path / "key.pem", tmp_path / "ca.pem"
    issued.cert_chain_pems[0].write_to_path(cert)
    issued.private_key_pem.write_to_path(key)
    ca.cert_pem.write_to_path(ca_pem)
    server_zenoh = tmp_path / "zenoh-server.json5"
    server_zenoh.write_text(
        f'{{ transport: {{ link: {{ tls: {{ listen_certificate: "{cert}", '
        f'listen_private_key: "{key}" }} }} }} }}'
    )
    client_zenoh = tmp_path / "zenoh-client.json5"
    client_zenoh.write_text(
        f'{{ transport: {{ link: {{ tls: {{ root_ca_certificate: "{ca_pem}" }} }} }} }}'
    )
    with running_server(
        "--tls-cert", str(cert), "--tls-key", str(key),
        "--zenoh-listen", "tls/127.0.0.1:0", "--zenoh-config", str(server_zenoh),
    ) as server:
        port = server.grpc_target.rsplit(":", 1)[1]
        target = f"localhost:{port}"
        with Client(target, tls_ca=ca_pem.read_bytes()) as client:
            session = client.create_session(SCENE)
            tls_endpoints = [e for e in server.zenoh_endpoints if e.startswith("tls/")]
            assert tls_endpoints, server.zenoh_endpoints
            with Frames(tls_endpoints, session.id, zenoh_config=str(client_zenoh)) as frames:
                client.step(session.id, 1)
                assert frames.next().step == 1

        stranger = trustme.CA()
        with pytest.raises(grpc.FutureTimeoutError):
            Client(target, timeout=2, tls_ca=stranger.cert_pem.bytes())
        with pytest.raises(grpc.FutureTimeoutError):
            Client(server.grpc_target, timeout=2)  # plain text


def test_half_a_client_identity_is_refused():
    with pytest.raises(ValueError, match="tls_cert and tls_key"):
        Client("localhost:1", tls_cert=b"x")
