"""Tokens, owners and observers over a real server (issue 13): a caller
without a valid token is UNAUTHENTICATED, a stranger PERMISSION_DENIED,
an observer reads but does not drive, and a second client instance of the
owner is ABORTED until it takes over."""

from __future__ import annotations

import grpc
import pytest
from conftest import fixture, running_server

from meshless import Client, MeshlessError

ALICE = "alice-token-0123456789"
BOB = "bob-token-0123456789ab"
CAROL = "carol-token-0123456789"


@pytest.fixture()
def guarded(tmp_path):
    tokens = tmp_path / "tokens"
    tokens.write_text(f"alice {ALICE}\nbob {BOB}\ncarol {CAROL}\n")
    with running_server("--tokens-file", str(tokens)) as running:
        yield running


def code_of(call) -> grpc.StatusCode:
    with pytest.raises(MeshlessError) as refused:
        call()
    return refused.value.code


def test_tokens_owners_observers_and_one_controller(guarded):
    target = guarded.grpc_target
    with Client(target) as nobody:
        assert code_of(nobody.server_info) == grpc.StatusCode.UNAUTHENTICATED
    with Client(target, token="alice-token-0000000000") as forger:
        assert code_of(forger.list_sessions) == grpc.StatusCode.UNAUTHENTICATED

    with Client(target, token=ALICE, client_id="laptop") as alice, Client(
        target, token=BOB
    ) as bob, Client(target, token=CAROL, take_over=True) as carol:
        session = alice.create_session(fixture("python_tank"), observers=["bob"])
        assert session.owner == "alice" and list(session.observers) == ["bob"]
        alice.step(session.id, 1)

        assert bob.get_session(session.id).status.step == 1
        assert [s.id for s in bob.list_sessions()] == [session.id]
        assert bob.latest_frame(session.id).step == 1
        assert code_of(lambda: bob.step(session.id)) == grpc.StatusCode.PERMISSION_DENIED
        assert code_of(lambda: bob.delete_session(session.id)) == grpc.StatusCode.PERMISSION_DENIED

        assert code_of(lambda: carol.get_session(session.id)) == grpc.StatusCode.PERMISSION_DENIED
        assert code_of(lambda: carol.step(session.id)) == grpc.StatusCode.PERMISSION_DENIED
        assert carol.list_sessions() == []

        with Client(target, token=ALICE, client_id="notebook") as notebook:
            with pytest.raises(MeshlessError) as refused:
                notebook.step(session.id)
            assert refused.value.code == grpc.StatusCode.ABORTED
            assert "alice/laptop" in refused.value.details
        with Client(target, token=ALICE, client_id="notebook", take_over=True) as taking:
            assert taking.step(session.id).status.step == 2
        assert code_of(lambda: alice.step(session.id)) == grpc.StatusCode.ABORTED
        assert alice.get_session(session.id).status.step == 2
