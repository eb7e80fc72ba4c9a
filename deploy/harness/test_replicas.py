"""Two replicas behind one zenoh router, seen by clients that know the
servers' gRPC targets and the router alone: frames from both, a server
stopped, the router restarted, a server cut off from the router and
healed, a server killed and restored from its checkpoints, calls routed
by session id. The Python client drives; the ``meshless`` command line
(the Rust client) checks routing and watches frames through the router.
"""

from __future__ import annotations

import os
import subprocess
import threading
import time
import urllib.request

import pytest
import zenoh

import meshless
from meshless.subscriber import zenoh_client_config
from topology import HERE, NAMES, TIMEOUT, Topology, connect, eventually

#: 96 particles that run for minutes without faulting.
SCENE = (HERE / "tank.toml").read_text()

#: Paced to real time, so frames keep coming for as long as a test needs.
REALTIME = 1.0


class Presence:
    """Liveliness of the servers (``meshless/v1/servers/*``) through the
    router: which replicas the router reaches now."""

    def __init__(self, topology: Topology):
        self._session = zenoh.open(
            zenoh_client_config([topology.router], str(topology.zenoh_config))
        )
        self._changed = threading.Condition()
        self._state: dict[str, str] = {}
        self.history: list[tuple[str, str]] = []

        def on_sample(sample: zenoh.Sample) -> None:
            name = str(sample.key_expr).rsplit("/", 1)[-1]
            state = "gone" if sample.kind == zenoh.SampleKind.DELETE else "alive"
            with self._changed:
                self._state[name] = state
                self.history.append((state, name))
                self._changed.notify_all()

        self._subscriber = self._session.liveliness().declare_subscriber(
            "meshless/v1/servers/*", on_sample, history=True
        )

    def expect(self, state: str, name: str) -> None:
        """Waits until ``name``'s token is ``state`` (alive or gone)."""
        with self._changed:
            reached = self._changed.wait_for(lambda: self._state.get(name) == state, TIMEOUT)
            if not reached:
                raise AssertionError(
                    f"{name}'s liveliness not {state} within {TIMEOUT} s; saw {self.history}"
                )

    def close(self) -> None:
        self._subscriber.undeclare()
        self._session.close()


def _frames(topology: Topology, session) -> meshless.Frames:
    return meshless.Frames(
        [topology.router], session, zenoh_config=str(topology.zenoh_config), timeout=TIMEOUT
    )


def _next_step_after(frames: meshless.Frames, step: int) -> int:
    """The step of the first frame past ``step`` (older ones still queued
    are skipped)."""
    while True:
        frame = frames.next(timeout=TIMEOUT)
        if frame.step > step:
            return frame.step


def _routers(client: meshless.Client) -> int:
    return client.server_info().zenoh_routers


def _cli(topology: Topology, cli: str, name: str, *args: str) -> str:
    """Runs ``meshless ARGS`` against replica ``name``: by ``--route`` where
    replica names resolve, else by its ``--server`` address."""
    c = topology.credentials
    flags = ["--tls-ca", str(c.ca)]
    if c.domain:
        flags += ["--tls-domain", c.domain]
    if topology.route_template is not None:
        flags += ["--route", topology.route_template]
    else:
        flags += ["--server", f"https://{topology.servers[name].target}"]
    done = subprocess.run(
        [cli, *args, *flags],
        env={**os.environ, "MESHLESS_TOKEN": c.token},
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
    )
    assert done.returncode == 0, f"meshless {' '.join(args)}: {done.stderr}"
    return done.stdout


def test_ids_name_their_server_and_calls_are_routed_to_it(topology, clients, cli):
    for name, client in clients.items():
        info = client.server_info()
        assert info.server_name == name
        eventually(f"{name} to reach the router", lambda c=client: _routers(c) == 1)
        session = client.create_session(SCENE)
        assert meshless.server_of(session.id) == name
        # The other replica does not hold it: a client must be routed.
        other = clients[next(n for n in NAMES if n != name)]
        with pytest.raises(meshless.MeshlessError) as missing:
            other.get_session(session)
        assert missing.value.code.name == "NOT_FOUND"
        if topology.route_template is not None:
            target = meshless.route(topology.route_template.removeprefix("https://"), session.id)
            assert target == topology.servers[name].target
        shown = _cli(topology, cli, name, "session", "step", session.id, "-n", "3")
        assert session.id in shown and "step 3" in shown, shown


def test_a_client_that_knows_only_the_router_gets_frames_from_both(topology, clients, cli):
    presence = Presence(topology)
    try:
        for name in NAMES:
            presence.expect("alive", name)
    finally:
        presence.close()
    sessions = {name: c.create_session(SCENE) for name, c in clients.items()}
    streams = {name: _frames(topology, s) for name, s in sessions.items()}
    try:
        for name, client in clients.items():
            client.run(sessions[name], forever=True, realtime_factor=REALTIME)
        for name, frames in streams.items():
            frame = frames.next(timeout=TIMEOUT)
            assert frame.session_id == sessions[name].id
            assert frame.particle_count == 96
        # The Rust client through the router alone.
        for name, session in sessions.items():
            shown = _cli(
                topology, cli, name,
                "watch", session.id, "--zenoh", topology.router, "--frames", "3",
                "--zenoh-config", str(topology.zenoh_config),
            )
            assert f"watching {session.id} through {topology.router}" in shown, shown
    finally:
        for frames in streams.values():
            frames.close()


def test_stopping_one_server_leaves_the_other_untouched(topology, clients):
    first, second = NAMES
    a = clients[first].create_session(SCENE)
    b = clients[second].create_session(SCENE)
    presence = Presence(topology)
    frames = _frames(topology, a)
    try:
        presence.expect("alive", second)
        clients[first].run(a, forever=True, realtime_factor=REALTIME)
        clients[second].run(b, forever=True, realtime_factor=REALTIME)
        step = frames.next(timeout=TIMEOUT).step
        topology.stop(second)
        presence.expect("gone", second)
        # The first server's stream goes on, frame after frame.
        for _ in range(5):
            step = _next_step_after(frames, step)
        assert meshless.state_name(clients[first].get_session(a).status.state) == "running"
        topology.start(second)
        presence.expect("alive", second)
        # Its session came back from its checkpoints, paused where it was.
        restarted = connect(topology, second)
        try:
            back = restarted.get_session(b)
            assert meshless.state_name(back.status.state) == "paused"
        finally:
            restarted.close()
        _next_step_after(frames, step)
    finally:
        frames.close()
        presence.close()


def test_streams_resume_after_the_router_restarts(topology, clients):
    first = NAMES[0]
    session = clients[first].create_session(SCENE)
    frames = _frames(topology, session)
    try:
        clients[first].run(session, forever=True, realtime_factor=REALTIME)
        step = frames.next(timeout=TIMEOUT).step
        topology.restart_router()
        # Same subscriber, same servers: both reconnect on their own.
        step = _next_step_after(frames, step)
        _next_step_after(frames, step)
        eventually("the server to reach the router again", lambda: _routers(clients[first]) == 1)
    finally:
        frames.close()


def test_a_partition_is_detected_and_heals(topology, clients):
    first = NAMES[0]
    client = clients[first]
    session = client.create_session(SCENE)
    presence = Presence(topology)
    frames = _frames(topology, session)
    try:
        presence.expect("alive", first)
        client.run(session, forever=True, realtime_factor=REALTIME)
        step = frames.next(timeout=TIMEOUT).step
        topology.partition(first)
        presence.expect("gone", first)
        eventually("the server to report no router", lambda: _routers(client) == 0)
        # gRPC still reaches it, and the session runs on unseen.
        running = client.get_session(session).status
        assert meshless.state_name(running.state) == "running"
        topology.heal(first)
        presence.expect("alive", first)
        eventually("the server to report its router", lambda: _routers(client) == 1)
        resumed = _next_step_after(frames, max(step, running.step))
        assert resumed > running.step
    finally:
        frames.close()
        presence.close()


def _metric(url: str, name: str) -> float | None:
    with urllib.request.urlopen(url, timeout=10) as answer:
        for line in answer.read().decode().splitlines():
            if line.startswith(name + " "):
                return float(line.split()[1])
    return None


def test_a_killed_server_restores_its_sessions_from_checkpoints(topology, clients):
    second = NAMES[1]
    metrics = topology.servers[second].metrics_url
    session = clients[second].create_session(SCENE)
    stepped = clients[second].step(session, 7)
    before = clients[second].latest_frame(session)
    done_at = time.time()
    # A round that finishes more than an interval (0.5 s) after the step
    # began after it, so the checkpoint on disk holds step 7.
    eventually(
        "a checkpoint round after the step",
        lambda: (age := _metric(metrics, "meshless_checkpoint_age_seconds")) is not None
        and time.time() - age > done_at + 0.75,
    )
    topology.kill(second)
    topology.start(second)
    restarted = connect(topology, second)
    try:
        back = restarted.get_session(session)
        assert back.id == session.id
        assert back.status.step == stepped.status.step == 7
        after = restarted.latest_frame(session)
        assert after.step == before.step
        assert (after.positions == before.positions).all()
        restarted.step(session, 1)
    finally:
        restarted.close()


def _grpc_web(topology: Topology, name: str, method: str, body: bytes, token: str | None):
    """One gRPC-web call to replica ``name``'s viewer listener, over HTTPS
    with the topology's CA: ``(grpc-status, [messages])``."""
    import http.client
    import ssl
    import struct

    host, port = topology.servers[name].viewer
    context = ssl.create_default_context(cafile=str(topology.credentials.ca))
    # Locally the certificate names `localhost`, the listener 127.0.0.1.
    connection = http.client.HTTPSConnection(
        topology.credentials.domain or host, port, timeout=TIMEOUT, context=context
    )
    headers = {"content-type": "application/grpc-web+proto", "x-grpc-web": "1"}
    if token:
        headers["authorization"] = f"Bearer {token}"
    try:
        connection.request(
            "POST", f"/meshless.v1.Simulation/{method}", struct.pack(">BI", 0, len(body)) + body, headers
        )
        answer = connection.getresponse()
        data = answer.read()
        status = answer.getheader("grpc-status")
    finally:
        connection.close()
    messages = []
    while data:
        flag, length = struct.unpack(">BI", data[:5])
        payload, data = data[5 : 5 + length], data[5 + length :]
        if flag & 0x80:
            for line in payload.decode().split("\r\n"):
                if line.startswith("grpc-status:"):
                    status = line.split(":", 1)[1].strip()
        else:
            messages.append(payload)
    return int(status), messages


def test_each_replica_serves_the_viewer_and_the_service_to_it(topology, clients):
    """The viewer of every replica over HTTPS: its page for anyone, the
    service as gRPC-web only with a token, frames by NextFrame."""
    import http.client
    import ssl

    from meshless.v1 import frame_pb2, simulation_pb2

    for name in NAMES:
        host, port = topology.servers[name].viewer
        context = ssl.create_default_context(cafile=str(topology.credentials.ca))
        connection = http.client.HTTPSConnection(
            topology.credentials.domain or host, port, timeout=TIMEOUT, context=context
        )
        try:
            connection.request("GET", "/")
            page = connection.getresponse()
            assert page.status == 200 and b"meshless viewer" in page.read()
        finally:
            connection.close()

        session = clients[name].create_session(SCENE)
        clients[name].step(session.id, 2)
        request = simulation_pb2.NextFrameRequest(session_id=session.id, after=0, wait_ms=0)
        status, _ = _grpc_web(topology, name, "NextFrame", request.SerializeToString(), token=None)
        assert status == 16, "no token: UNAUTHENTICATED"
        status, messages = _grpc_web(
            topology, name, "NextFrame", request.SerializeToString(), topology.credentials.token
        )
        assert status == 0 and len(messages) == 1
        reply = simulation_pb2.NextFrameResponse.FromString(messages[0])
        frame = frame_pb2.Frame.FromString(reply.frame)
        assert reply.number >= 1
        assert frame.header.session_id == session.id and frame.header.step == 2
