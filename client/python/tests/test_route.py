"""Routing by session id, the same rules as the Rust client's ``Route``."""

import pytest

import meshless


def test_ids_name_their_server():
    assert meshless.server_of("meshless-1-3f2a9c0d4b1e7a65") == "meshless-1"
    assert meshless.server_of("a-0123456789abcdef") == "a"
    unnamed_ids = ["3f2a9c0d4b1e7a65", "-3f2a9c0d4b1e7a65", "s-3f2a9c0d4b1e7a6", "s-3f2a9c0d4b1e7a6z", ""]
    for unnamed in unnamed_ids:
        assert meshless.server_of(unnamed) is None, unnamed


def test_route_fills_in_the_server():
    target = meshless.route("{server}.meshless-replicas:50051", "meshless-0-00000000000000ff")
    assert target == "meshless-0.meshless-replicas:50051"
    with pytest.raises(ValueError, match="names no server"):
        meshless.route("{server}:50051", "00000000000000ff")
    for bad in ["meshless:50051", "{server}.{server}:50051"]:
        with pytest.raises(ValueError, match="holds {server} once"):
            meshless.route(bad, "a-00000000000000ff")
