"""What the Python subscriber accepts. By default the server lets no other
zenoh peer publish through it; where one can (``--zenoh-publishers any``,
or a router without access control), ``decode_frame`` raises
``ValueError`` for every malformed payload and ``Frames`` keeps only the
server's frames of its session, counting the rest."""

from __future__ import annotations

import json
import random
import threading
import time

import pytest
import zenoh

from conftest import TIMEOUT, fixture, running_server
from meshless import Client, Frames, Seal, decode_frame, frames_key, latest_key

SCENE = fixture("python_tank")


def forged_frame(session_id: str, step: int = 999_999, data: bytes = bytes(12)) -> bytes:
    """A frame of one particle naming ``session_id``; consistent with the
    default ``data``."""
    from meshless.v1 import frame_pb2, scene_pb2

    message = frame_pb2.Frame()
    message.header.session_id = session_id
    message.header.step = step
    message.header.particle_count = 1
    field = message.fields.add()
    field.kind = scene_pb2.FIELD_KIND_POSITION
    field.components = 3
    field.scalar = frame_pb2.SCALAR_TYPE_F32
    field.data = data
    return message.SerializeToString()


def test_decode_frame_raises_value_error_for_every_malformed_payload():
    # Protobuf reads b"\x08\x01" as an unknown varint and "\x78\x01" as an
    # unknown field: both parse as a frame without a header.
    for payload in [b"\x08\x01", b"\x78\x01", b"", b"\xff" * 8, forged_frame("")]:
        with pytest.raises(ValueError):
            decode_frame(payload)
    with pytest.raises(ValueError, match="12 bytes|expected 12"):
        decode_frame(forged_frame("s", data=bytes(8)))
    assert decode_frame(forged_frame("s")).step == 999_999

    rng = random.Random(13)
    for _ in range(500):
        garbage = rng.randbytes(rng.randrange(1, 64))
        with pytest.raises(ValueError):
            decode_frame(garbage)


def hostile_peer(endpoints: list[str]) -> zenoh.Session:
    """A zenoh session in client mode, as any program on the network can
    open one."""
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps(endpoints))
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def until(condition, what: str) -> None:
    """Polls ``condition`` until it holds, failing after ``TIMEOUT``."""
    deadline = time.monotonic() + TIMEOUT
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


def test_frames_keep_only_the_sessions_frames_and_count_the_rest(open_server):
    server = open_server
    with Client(server.grpc_target) as client:
        session = client.create_session(SCENE)
        other = client.create_session(SCENE)
        with Frames(server.zenoh_endpoints, session.id) as frames, hostile_peer(
            server.zenoh_endpoints
        ) as peer:
            replayed = [r.ok.payload.to_bytes() for r in peer.get(latest_key(other.id)) if r.ok]
            assert len(replayed) == 1, "the other session's frame 0"
            key = frames_key(session.id)
            for put_key, payload in [
                (key, b"\xff" * 8),
                (key, b"\x08\x01"),
                (key, forged_frame("FAKE")),
                (key, replayed[0]),
                (key, forged_frame(session.id, data=bytes(8))),
                ("meshless/v1/sessions/*/frames", forged_frame(session.id)),
            ]:
                peer.put(put_key, payload)
            # The server answers the peer's query after forwarding its puts.
            assert [r for r in peer.get(latest_key(session.id)) if r.ok]

            client.step(session.id, 3)
            got = [frames.next() for _ in range(3)]
            assert [(f.session_id, f.step) for f in got] == [(session.id, s) for s in (1, 2, 3)]
            until(lambda: frames.dropped == 6, "six drops")
            assert dict(frames.drop_reasons) == {
                "undecodable": 1,
                "malformed": 2,
                "wrong_session": 2,
                "wrong_key": 1,
            }
            assert frames.last_drop is not None and frames.last_drop[0] == "wrong_key"


def test_frames_latest_skips_forged_replies(open_server):
    server = open_server
    with Client(server.grpc_target) as client:
        session = client.create_session(SCENE)
        client.step(session.id, 2)
        key = latest_key(session.id)
        asked = threading.Event()

        def answer(query) -> None:
            query.reply(key, b"\xff" * 8)
            query.reply(key, forged_frame("FAKE"))
            query.reply_err("forged error")
            asked.set()

        with hostile_peer(server.zenoh_endpoints) as peer:
            # Declared complete, so that by default only it would be asked.
            peer.declare_queryable(key, answer, complete=True)
            # The queryable reaches the server some time after it is
            # declared; open subscribers until one has asked it too.
            deadline = time.monotonic() + TIMEOUT
            while True:
                known = asked.is_set()
                with Frames(server.zenoh_endpoints, session.id) as frames:
                    assert frames.latest is not None
                    assert (frames.latest.session_id, frames.latest.step) == (session.id, 2)
                if known:
                    break
                assert time.monotonic() < deadline, "the peer's queryable was never asked"


def test_no_peer_publishes_or_answers_through_the_server(server):
    """The server's access control drops a well-formed frame forged in the
    session's name and keeps a peer's queryable from being asked."""
    with Client(server.grpc_target) as client:
        session = client.create_session(SCENE)
        client.step(session.id, 2)
        key = latest_key(session.id)
        with hostile_peer(server.zenoh_endpoints) as peer:
            peer.declare_queryable(
                key, lambda query: query.reply(key, forged_frame(session.id)), complete=True
            )
            with Frames(server.zenoh_endpoints, session.id) as frames:
                peer.put(frames_key(session.id), forged_frame(session.id))
                # The server answers the peer's query after routing (here:
                # dropping) its declaration and its put; the peer's own
                # queryable answers too, and a peer that has only just
                # connected may not know the server's queryable yet.
                until(
                    lambda: 2
                    in [
                        decode_frame(r.ok.payload.to_bytes()).step
                        for r in peer.get(key, target=zenoh.QueryTarget.ALL)
                        if r.ok
                    ],
                    "the server's answer to the peer",
                )
                client.step(session.id, 1)
                got = frames.next()
                assert (got.session_id, got.step) == (session.id, 3)
                assert frames.dropped == 0, "the forgery never reached the subscriber"
            for _ in range(5):
                with Frames(server.zenoh_endpoints, session.id) as late:
                    assert late.latest is not None and late.latest.step == 3


def test_sealed_frames_open_only_for_those_who_may_see_the_session(tmp_path):
    """A server with tokens seals each session's frames with a key that only
    its owner and observers receive over gRPC: a stranger on the zenoh plane
    holds ciphertext, and a replayed or plain payload is dropped."""
    tokens = tmp_path / "tokens"
    tokens.write_text("alice alice-token-0123456789\nbob bob-token-0123456789ab\n")
    with running_server("--tokens-file", str(tokens), "--zenoh-publishers", "any") as server:
        with Client(server.grpc_target, token="alice-token-0123456789") as alice, Client(
            server.grpc_target, token="bob-token-0123456789ab"
        ) as bob:
            assert alice.server_info().zenoh_sealed
            session = alice.create_session(SCENE, observers=["bob"])
            assert len(session.seal_key) == 32
            seen_by_bob = bob.get_session(session.id)
            assert seen_by_bob.seal_key == session.seal_key

            captured: list[bytes] = []
            with hostile_peer(server.zenoh_endpoints) as stranger:
                stranger.declare_subscriber(
                    "meshless/v1/sessions/*/frames",
                    lambda sample: captured.append(sample.payload.to_bytes()),
                )
                with Frames(server.zenoh_endpoints, seen_by_bob) as frames, Frames(
                    server.zenoh_endpoints, session.id
                ) as keyless:
                    assert frames.latest is not None and frames.latest.step == 0
                    assert keyless.latest is None, "the latest reply is sealed too"
                    alice.step(session.id, 2)
                    assert [frames.next().step for _ in range(2)] == [1, 2]
                    until(lambda: len(captured) == 2, "the stranger's two payloads")
                    for payload in captured:
                        with pytest.raises(ValueError):
                            decode_frame(payload)
                        with pytest.raises(ValueError, match="does not open"):
                            Seal(bytes(32)).open(frames_key(session.id), payload)
                    until(lambda: keyless.dropped == 2, "the keyless subscriber's drops")

                    stranger.put(frames_key(session.id), captured[0])
                    stranger.put(frames_key(session.id), forged_frame(session.id))
                    until(lambda: frames.dropped == 2, "the replay and the plain frame dropped")
                    assert dict(frames.drop_reasons) == {"replayed": 1, "not_authentic": 1}
                    alice.step(session.id, 1)
                    assert frames.next().step == 3


def test_a_fresh_subscriber_refuses_a_frame_recorded_before_it_started(tmp_path):
    """A recorded sealed frame played to a subscription that started after
    the session moved on: the subscription learns the session's latest from
    the sealed answer to its latest-frame query and refuses anything sealed
    before it, though it has taken no frame yet."""
    tokens = tmp_path / "tokens"
    tokens.write_text("alice alice-token-0123456789\n")
    with running_server("--tokens-file", str(tokens), "--zenoh-publishers", "any") as server:
        with Client(server.grpc_target, token="alice-token-0123456789") as alice:
            session = alice.create_session(SCENE)
            key = frames_key(session.id)
            captured: list[bytes] = []
            with hostile_peer(server.zenoh_endpoints) as peer:
                peer.declare_subscriber(key, lambda sample: captured.append(sample.payload.to_bytes()))
                # The server answers the peer's query after it has learnt of
                # the peer's subscriber.
                assert [r for r in peer.get(latest_key(session.id)) if r.ok]
                alice.step(session.id, 1)
                until(lambda: len(captured) == 1, "the recorded frame of step 1")
                alice.step(session.id, 2)
                with Frames(server.zenoh_endpoints, session) as frames:
                    assert frames.latest is not None and frames.latest.step == 3
                    peer.put(key, captured[0])
                    # The server answers after forwarding the put.
                    assert [r for r in peer.get(latest_key(session.id)) if r.ok]
                    alice.step(session.id, 1)
                    assert frames.next().step == 4, "the recording of step 1 is refused"
                    until(lambda: frames.dropped == 1, "the replay counted")
                    assert dict(frames.drop_reasons) == {"replayed": 1}
