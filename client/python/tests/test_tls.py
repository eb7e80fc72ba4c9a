"""TLS from Python: the server's certificate on gRPC and zenoh, made by
trustme for each test; a client that does not trust the CA is refused."""

from __future__ import annotations

import grpc
import pytest
import trustme

from conftest import fixture, running_server
from meshless import Client, Frames, MeshlessError

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
        for refused in (
            lambda: Client(target, timeout=2, tls_ca=stranger.cert_pem.bytes()),
            lambda: Client(server.grpc_target, timeout=2),  # plain text
        ):
            with pytest.raises(MeshlessError) as error:
                refused()
            assert error.value.code == grpc.StatusCode.UNAVAILABLE


def test_half_a_client_identity_is_refused():
    with pytest.raises(ValueError, match="tls_cert and tls_key"):
        Client("localhost:1", tls_cert=b"x")


def test_asyncio_client_with_a_client_certificate(tmp_path):
    """A server with --tls-client-ca serves a client whose certificate its
    CA signed, over asyncio too, and refuses one without."""
    import asyncio

    from meshless import AsyncClient

    ca = trustme.CA()
    issued = ca.issue_cert("localhost", "127.0.0.1")
    client_ca = trustme.CA()
    identity = client_ca.issue_cert("laptop@example.org")
    files = {
        "cert.pem": issued.cert_chain_pems[0].bytes(),
        "key.pem": issued.private_key_pem.bytes(),
        "client-ca.pem": client_ca.cert_pem.bytes(),
        "client.pem": identity.cert_chain_pems[0].bytes(),
        "client-key.pem": identity.private_key_pem.bytes(),
    }
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    with running_server(
        "--tls-cert", str(tmp_path / "cert.pem"), "--tls-key", str(tmp_path / "key.pem"),
        "--tls-client-ca", str(tmp_path / "client-ca.pem"),
    ) as server:
        port = server.grpc_target.rsplit(":", 1)[1]

        async def main():
            # PEM given as bytes and as files.
            async with AsyncClient(
                f"127.0.0.1:{port}",
                tls_ca=ca.cert_pem.bytes(),
                tls_domain="localhost",
                tls_cert=tmp_path / "client.pem",
                tls_key=tmp_path / "client-key.pem",
            ) as client:
                session = await client.create_session(SCENE)
                assert (await client.step(session, 1)).status.step == 1
            with pytest.raises(MeshlessError) as refused:
                anonymous = AsyncClient(f"localhost:{port}", timeout=2, tls_ca=ca.cert_pem.bytes())
                async with anonymous:
                    await anonymous.server_info()
            assert refused.value.code == grpc.StatusCode.UNAVAILABLE

        asyncio.run(main())
