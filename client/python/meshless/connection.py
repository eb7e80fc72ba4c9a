"""What the sync and asyncio clients share: how to reach a server (TLS,
channel options), who the caller is (token, client instance, take-over
metadata) and the requests of every call of ``meshless.v1.Simulation``."""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Union

import grpc

from .design import constraint
from .scene import scene_text

DEFAULT_TARGET = "127.0.0.1:50051"
DEFAULT_TIMEOUT = 30.0

# PEM bytes, PEM text or a file holding them.
Pem = Union[bytes, str, "os.PathLike[str]"]
# A scene: TOML text (a str), a TOML file (a path object), a dict, or a
# SceneSpec message.
Scene = Union[str, "os.PathLike[str]", Mapping[str, Any], Any]

# The largest message either side sends: a snapshot of a big session.
MAX_MESSAGE_BYTES = 1 << 30


def read_pem(value: Pem | None) -> bytes | None:
    """PEM bytes from bytes, text that holds a PEM block, or a file path."""
    if value is None or isinstance(value, bytes):
        return value
    if isinstance(value, str) and "-----BEGIN" in value:
        return value.encode()
    return Path(value).read_bytes()


@dataclass(frozen=True)
class Connection:
    """Where a server is and how to speak to it: plain text, or TLS with
    ``tls_ca`` (PEM; default: the system's CAs) checked against the name
    ``tls_domain`` (default: the target's host) and a client identity
    ``tls_cert`` and ``tls_key`` for a server that asks for one. The
    metadata names the caller on every call."""

    target: str
    credentials: grpc.ChannelCredentials | None
    options: tuple[tuple[str, Any], ...]
    metadata: tuple[tuple[str, str], ...]

    @classmethod
    def make(
        cls,
        target: str,
        token: str | None = None,
        client_id: str | None = None,
        take_over: bool = False,
        tls: bool = False,
        tls_ca: Pem | None = None,
        tls_cert: Pem | None = None,
        tls_key: Pem | None = None,
        tls_domain: str | None = None,
    ) -> "Connection":
        """Checks and gathers the clients' connection arguments."""
        if (tls_cert is None) != (tls_key is None):
            raise ValueError("tls_cert and tls_key go together: give both or neither")
        options: list[tuple[str, Any]] = [
            ("grpc.max_receive_message_length", MAX_MESSAGE_BYTES),
            ("grpc.max_send_message_length", MAX_MESSAGE_BYTES),
        ]
        credentials = None
        if tls or any(x is not None for x in (tls_ca, tls_cert, tls_key, tls_domain)):
            credentials = grpc.ssl_channel_credentials(
                root_certificates=read_pem(tls_ca),
                private_key=read_pem(tls_key),
                certificate_chain=read_pem(tls_cert),
            )
            if tls_domain is not None:
                options.append(("grpc.ssl_target_name_override", tls_domain))
        metadata: list[tuple[str, str]] = []
        if token is not None:
            metadata.append(("authorization", f"Bearer {token}"))
        if client_id is not None:
            metadata.append(("meshless-client", client_id))
        if take_over:
            metadata.append(("meshless-take-over", "true"))
        return cls(target, credentials, tuple(options), tuple(metadata))


def deadline(default: float | None, timeout: float | None) -> float | None:
    """A call's deadline in seconds: its own ``timeout``, else the client's."""
    return default if timeout is None else timeout


def create_session_request(scene: Scene, observers: Iterable[str] = ()) -> Any:
    """A ``CreateSessionRequest`` for a scene given as TOML text (``str``),
    a TOML file (a path object), a dict or a ``SceneSpec`` message."""
    from .v1 import scene_pb2
    from .v1 import simulation_pb2 as pb

    if isinstance(scene, scene_pb2.SceneSpec):
        return pb.CreateSessionRequest(scene=scene, observers=list(observers))
    return pb.CreateSessionRequest(scene_toml=scene_text(scene), observers=list(observers))


def run_request(
    session_id: str,
    until: float | None = None,
    forever: bool = False,
    realtime_factor: float | None = None,
) -> Any:
    """A ``RunRequest``: to simulated time ``until``, or ``forever``."""
    from .v1 import simulation_pb2 as pb

    if (until is None) == (not forever):
        raise ValueError("give `until` (a time, s) or `forever=True`, not both")
    request = pb.RunRequest(session_id=session_id)
    if until is not None:
        request.until_time = until
    else:
        request.forever = True
    if realtime_factor is not None:
        request.realtime_factor = realtime_factor
    return request


def constraint_edits(
    session_id: str,
    edits: Iterable[Any] = (),
    *,
    clear: bool = False,
    remove: Iterable[str] = (),
    replace: Iterable[Any] = (),
    add: Iterable[Any] = (),
) -> Any:
    """An ``EditConstraintsRequest``: ``edits`` (``ConstraintEdit``
    messages) in order, then ``clear``, ``remove`` (names), ``replace`` and
    ``add`` (``Constraint`` messages or dicts in the TOML form)."""
    from .v1 import design_pb2 as d

    def message(c: Any) -> Any:
        return c if isinstance(c, d.Constraint) else constraint(c)

    out = list(edits)
    if clear:
        out.append(d.ConstraintEdit(clear=d.ClearConstraints()))
    out += [d.ConstraintEdit(remove=name) for name in remove]
    out += [d.ConstraintEdit(replace=message(c)) for c in replace]
    out += [d.ConstraintEdit(add=message(c)) for c in add]
    return d.EditConstraintsRequest(session_id=session_id, edits=out)


def simulate_steps_request(
    session_id: str, steps: int, progress_interval: float | None = None
) -> Any:
    """A ``SimulateStepsRequest``."""
    from .v1 import simulation_pb2 as pb

    request = pb.SimulateStepsRequest(session_id=session_id, steps=steps)
    if progress_interval is not None:
        request.progress_interval = progress_interval
    return request


def restore_request(
    snapshot: Any, session_id: str = "", observers: Iterable[str] | None = None
) -> Any:
    """A ``RestoreRequest`` of a ``SessionSnapshot`` or its ``data`` bytes."""
    from .v1 import simulation_pb2 as pb

    data = snapshot if isinstance(snapshot, (bytes, bytearray, memoryview)) else snapshot.data
    request = pb.RestoreRequest(data=bytes(data), session_id=session_id)
    if observers is not None:
        request.observers.principals.extend(observers)
    return request


def change_particles_request(
    session_id: str,
    system: int,
    remove: Iterable[int] = (),
    positions: Iterable[Iterable[float]] = (),
    velocities: Iterable[Iterable[float]] = (),
) -> Any:
    """A ``ChangeParticlesRequest``: ids to remove, and new particles'
    positions and velocities as ``[x, y, z]`` rows (numpy arrays work)."""
    from .v1 import scene_pb2
    from .v1 import simulation_pb2 as pb

    def vec3s(rows: Iterable[Iterable[float]]) -> list[Any]:
        out = []
        for row in rows:
            x, y, z = (float(c) for c in row)
            out.append(scene_pb2.Vec3(x=x, y=y, z=z))
        return out

    return pb.ChangeParticlesRequest(
        session_id=session_id,
        system=system,
        remove=[int(i) for i in remove],
        insert_positions=vec3s(positions),
        insert_velocities=vec3s(velocities),
    )


def session_id_of(session: Any) -> str:
    """A session id from an id or a ``Session`` message."""
    return session if isinstance(session, str) else session.id
