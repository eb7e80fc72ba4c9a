"""A small synchronous client: gRPC control and zenoh frames."""

from __future__ import annotations

import collections
import json
import queue
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable

import grpc
import numpy as np
import zenoh

from .frames import Frame, decode_frame, frames_key, latest_key

DEFAULT_TIMEOUT = 30.0


@dataclass
class Design:
    """A solved design: the design particles' rest positions and their
    displacements per frame, as numpy arrays (lengths checked)."""

    session_id: str
    system: int
    kind: str
    info: object
    rest_positions: np.ndarray
    times: np.ndarray
    displacements: np.ndarray

    @classmethod
    def from_proto(cls, result) -> "Design":
        from .v1 import design_pb2

        rest = np.asarray(result.rest_positions, dtype=np.float64)
        times = np.asarray(result.times, dtype=np.float64)
        values = np.asarray(result.displacements, dtype=np.float64)
        if rest.size % 3 or times.size == 0 or values.size != rest.size * times.size:
            raise ValueError(
                f"malformed design: {rest.size} rest coordinates, {times.size} times, "
                f"{values.size} displacement values"
            )
        n = rest.size // 3
        kind = design_pb2.DesignKind.Name(result.kind).removeprefix("DESIGN_KIND_").lower()
        return cls(
            session_id=result.session_id,
            system=result.system,
            kind=kind,
            info=result.info,
            rest_positions=rest.reshape(n, 3),
            times=times,
            displacements=values.reshape(times.size, n, 3),
        )

    def positions(self, frame: int) -> np.ndarray:
        """The design particles' positions at ``frame``."""
        return self.rest_positions + self.displacements[frame]


class _CallDetails(
    collections.namedtuple(
        "_CallDetails",
        ("method", "timeout", "metadata", "credentials", "wait_for_ready", "compression"),
    ),
    grpc.ClientCallDetails,
):
    """A call's details with metadata added."""


class _Identity(grpc.UnaryUnaryClientInterceptor, grpc.UnaryStreamClientInterceptor):
    """Puts the token, client id and take-over flag on every call."""

    def __init__(self, metadata: list[tuple[str, str]]):
        self._metadata = metadata

    def _details(self, details):
        return _CallDetails(
            details.method,
            details.timeout,
            list(details.metadata or []) + self._metadata,
            details.credentials,
            details.wait_for_ready,
            details.compression,
        )

    def intercept_unary_unary(self, continuation, details, request):
        return continuation(self._details(details), request)

    def intercept_unary_stream(self, continuation, details, request):
        return continuation(self._details(details), request)


class Client:
    """Drives a meshless server over gRPC.

    ``token`` is the bearer token of a server with tokens; ``client_id``
    names this client instance (one instance drives a session at a time);
    ``take_over`` takes control of sessions another instance drives.
    Errors surface as ``grpc.RpcError`` with the server's status code and a
    message that names what to change.
    """

    def __init__(
        self,
        target: str = "127.0.0.1:50051",
        timeout: float = DEFAULT_TIMEOUT,
        token: str | None = None,
        client_id: str | None = None,
        take_over: bool = False,
    ):
        from .v1 import simulation_pb2 as pb
        from .v1 import simulation_pb2_grpc

        self._pb = pb
        self._timeout = timeout
        self._channel = grpc.insecure_channel(target)
        grpc.channel_ready_future(self._channel).result(timeout=timeout)
        metadata = []
        if token is not None:
            metadata.append(("authorization", f"Bearer {token}"))
        if client_id is not None:
            metadata.append(("meshless-client", client_id))
        if take_over:
            metadata.append(("meshless-take-over", "true"))
        channel = grpc.intercept_channel(self._channel, _Identity(metadata)) if metadata else self._channel
        self._stub = simulation_pb2_grpc.SimulationStub(channel)

    def close(self) -> None:
        self._channel.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *_exc) -> None:
        self.close()

    def server_info(self):
        return self._stub.GetServerInfo(self._pb.GetServerInfoRequest(), timeout=self._timeout)

    def create_session(self, scene: str | Path, observers: Iterable[str] = ()):
        """Creates a session from a TOML scene: a path or the text itself.
        ``observers`` names principals that may see it read-only (``"*"``:
        everyone). Mesh files must come from the server's mesh directory or
        travel in the scene (``data = { format, base64 }``)."""
        text = Path(scene).read_text() if isinstance(scene, Path) else scene
        request = self._pb.CreateSessionRequest(scene_toml=text, observers=list(observers))
        return self._stub.CreateSession(request, timeout=self._timeout)

    def _ref(self, session_id: str):
        return self._pb.SessionRef(session_id=session_id)

    def get_session(self, session_id: str):
        return self._stub.GetSession(self._ref(session_id), timeout=self._timeout)

    def list_sessions(self):
        return list(
            self._stub.ListSessions(self._pb.ListSessionsRequest(), timeout=self._timeout).sessions
        )

    def delete_session(self, session_id: str) -> None:
        self._stub.DeleteSession(self._ref(session_id), timeout=self._timeout)

    def step(self, session_id: str, steps: int = 1):
        request = self._pb.StepRequest(session_id=session_id, steps=steps)
        return self._stub.Step(request, timeout=self._timeout)

    def run_until(self, session_id: str, until: float, realtime_factor: float | None = None):
        request = self._pb.RunRequest(session_id=session_id, until_time=until)
        if realtime_factor is not None:
            request.realtime_factor = realtime_factor
        return self._stub.Run(request, timeout=self._timeout)

    def pause(self, session_id: str):
        return self._stub.Pause(self._ref(session_id), timeout=self._timeout)

    def resume(self, session_id: str):
        return self._stub.Resume(self._ref(session_id), timeout=self._timeout)

    def reset(self, session_id: str):
        return self._stub.Reset(self._ref(session_id), timeout=self._timeout)

    def latest_frame(self, session_id: str) -> Frame:
        """The latest frame over gRPC, decoded."""
        message = self._stub.GetLatestFrame(self._ref(session_id), timeout=self._timeout)
        return decode_frame(message.SerializeToString())

    def edit_constraints(self, session_id: str, edits: Iterable) -> list:
        """Applies ``ConstraintEdit`` messages all or nothing; returns the
        constraints in name order. INVALID_ARGUMENT names the bad one."""
        from .v1 import design_pb2

        request = design_pb2.EditConstraintsRequest(session_id=session_id, edits=list(edits))
        return list(self._stub.EditConstraints(request, timeout=self._timeout).constraints)

    def list_constraints(self, session_id: str) -> list:
        return list(self._stub.ListConstraints(self._ref(session_id), timeout=self._timeout).constraints)

    def optimize(
        self,
        request,
        on_progress: Callable[[object], None] | None = None,
        timeout: float | None = None,
    ) -> Design:
        """Runs an ``OptimizeRequest`` to its end, calling ``on_progress``
        with each ``DesignProgress``; returns the :class:`Design`. Raises
        ``grpc.RpcError`` (CANCELLED, INVALID_ARGUMENT, ABORTED) on failure."""
        for event in self._stub.Optimize(request, timeout=timeout):
            which = event.WhichOneof("event")
            if which == "progress":
                if on_progress is not None:
                    on_progress(event.progress)
            elif which == "result":
                return Design.from_proto(event.result)
        raise RuntimeError("the optimisation stream ended without a result")

    def cancel_optimize(self, session_id: str) -> bool:
        """Cancels the running optimisation; whether there was one."""
        return self._stub.CancelOptimize(self._ref(session_id), timeout=self._timeout).cancelled

    def get_design(self, session_id: str) -> Design:
        """The last successful design; NOT_FOUND before the first."""
        return Design.from_proto(self._stub.GetDesign(self._ref(session_id), timeout=self._timeout))


class Frames:
    """A session's frames from zenoh, decoded into numpy arrays.

    Opens zenoh in client mode against the given endpoints (the server's
    ``zenoh_locators`` or a router's). Once constructed, the server knows
    of the subscription: a latest-frame query has made the round trip, so
    no frame published afterwards is missed.
    """

    def __init__(self, endpoints: list[str], session_id: str):
        config = zenoh.Config()
        config.insert_json5("mode", '"client"')
        config.insert_json5("connect/endpoints", json.dumps(list(endpoints)))
        config.insert_json5("scouting/multicast/enabled", "false")
        self._session = zenoh.open(config)
        self._queue: queue.Queue[bytes] = queue.Queue()
        self._subscriber = self._session.declare_subscriber(
            frames_key(session_id), lambda sample: self._queue.put(sample.payload.to_bytes())
        )
        self.latest = next(
            (decode_frame(r.ok.payload.to_bytes()) for r in self._session.get(latest_key(session_id)) if r.ok),
            None,
        )

    def next(self, timeout: float = DEFAULT_TIMEOUT) -> Frame:
        """The next frame; raises ``queue.Empty`` after ``timeout`` seconds."""
        return decode_frame(self._queue.get(timeout=timeout))

    def close(self) -> None:
        self._subscriber.undeclare()
        self._session.close()

    def __enter__(self) -> "Frames":
        return self

    def __exit__(self, *_exc) -> None:
        self.close()
