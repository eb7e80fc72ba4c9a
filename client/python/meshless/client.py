"""A small synchronous client: gRPC control and zenoh frames."""

from __future__ import annotations

import collections
import json
import queue
import threading
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable

import grpc
import numpy as np
import zenoh

from .frames import Frame, decode_frame, frames_key, latest_key, parse_frame, unpack_frame
from .seal import Seal

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
    ``tls`` speaks TLS to a server started with ``--tls-cert``, checking
    its certificate against ``tls_ca`` (PEM bytes; default: the system's
    CAs) and the name ``tls_domain`` (default: the target's host); a
    server with ``--tls-client-ca`` also wants ``tls_cert`` and
    ``tls_key`` (PEM bytes). Any ``tls_*`` argument implies ``tls``.
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
        tls: bool = False,
        tls_ca: bytes | None = None,
        tls_cert: bytes | None = None,
        tls_key: bytes | None = None,
        tls_domain: str | None = None,
    ):
        from .v1 import simulation_pb2 as pb
        from .v1 import simulation_pb2_grpc

        self._pb = pb
        self._timeout = timeout
        if (tls_cert is None) != (tls_key is None):
            raise ValueError("tls_cert and tls_key go together: give both or neither")
        if tls or any(x is not None for x in (tls_ca, tls_cert, tls_key, tls_domain)):
            credentials = grpc.ssl_channel_credentials(
                root_certificates=tls_ca, private_key=tls_key, certificate_chain=tls_cert
            )
            options = [] if tls_domain is None else [("grpc.ssl_target_name_override", tls_domain)]
            self._channel = grpc.secure_channel(target, credentials, options=options)
        else:
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
        """Every session the caller may see, oldest first, without their
        scenes (``get_session`` has them)."""
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


class _Dropped(Exception):
    """Why :class:`Frames` refuses a sample: a reason of
    ``Frames.drop_reasons`` and what was wrong."""

    def __init__(self, reason: str, why: str):
        super().__init__(why)
        self.reason = reason
        self.why = why


def _quote(text: str) -> str:
    """At most 64 characters of text a peer chose, quoted, so that a hostile
    sample cannot flood ``last_drop``."""
    return repr(text if len(text) <= 64 else text[:64] + "…")


class Frames:
    """A session's frames from zenoh, decoded into numpy arrays.

    Opens zenoh in client mode against the given endpoints (the server's
    ``zenoh_locators`` or a router's). Once constructed, the server knows
    of the subscription: a latest-frame query has made the round trip, so
    no frame published afterwards is missed. ``latest`` is the frame that
    query returned (``None`` when no server answered with a valid one).

    Any zenoh peer can put on a session's key, so each sample is checked in
    zenoh's callback before it is queued: it must be put on exactly the
    session's frame key, decode as a ``Frame`` whose header names this
    session, and pass :func:`decode_frame`'s checks. Anything else is
    dropped and counted: ``dropped`` (the total), ``drop_reasons`` (by
    reason: ``wrong_key``, ``undecodable``, ``malformed``,
    ``wrong_session``, and for sealed frames ``not_authentic`` and
    ``replayed``) and ``last_drop`` (the last reason and what was
    wrong). Unsealed (below), a peer that puts a well-formed frame naming
    this session is not caught here: the server's zenoh access control
    refuses it (its default), or a router's.

    ``session`` is the ``Session`` message the server answered with
    (``Client.create_session``, ``get_session``), or a session id. A server
    with tokens seals what it puts on zenoh with a key of each session
    (``ServerInfo.zenoh_sealed``) that only callers who may see the session
    receive (``Session.seal_key``); given the message, or ``seal_key``,
    frames are opened with it (:class:`Seal`), and a payload that does not
    open (``not_authentic``) or was sealed before the last one taken
    (``replayed``) is dropped too.

    ``zenoh_config`` names a zenoh configuration file (JSON5) to start
    from: the CA of ``tls/`` endpoints, a client certificate.
    """

    def __init__(
        self,
        endpoints: list[str],
        session,
        zenoh_config: str | None = None,
        seal_key: bytes | None = None,
    ):
        if isinstance(session, str):
            session_id, key = session, b""
        else:
            session_id, key = session.id, session.seal_key
        if seal_key is not None:
            key = seal_key
        self._seal = Seal(key) if key else None
        config = zenoh.Config() if zenoh_config is None else zenoh.Config.from_file(zenoh_config)
        config.insert_json5("mode", '"client"')
        config.insert_json5("connect/endpoints", json.dumps(list(endpoints)))
        config.insert_json5("scouting/multicast/enabled", "false")
        self._session_id = session_id
        self._key = frames_key(session_id)
        self._newest = 0
        self._lock = threading.Lock()
        self._drop_reasons: Counter[str] = Counter()
        self._last_drop: tuple[str, str] | None = None
        self._session = zenoh.open(config)
        self._queue: queue.Queue[Frame] = queue.Queue()
        self._subscriber = self._session.declare_subscriber(self._key, self._on_sample)
        self.latest = self._latest()

    # zenoh's thread counts while the caller's reads: copies under a lock.
    @property
    def dropped(self) -> int:
        """Samples dropped so far, for any reason."""
        with self._lock:
            return sum(self._drop_reasons.values())

    @property
    def drop_reasons(self) -> Counter[str]:
        """Samples dropped so far, by reason."""
        with self._lock:
            return Counter(self._drop_reasons)

    @property
    def last_drop(self) -> tuple[str, str] | None:
        """The last drop's reason and what was wrong, if any."""
        with self._lock:
            return self._last_drop

    def _admit(self, key: str, data: bytes, expected_key: str, replay: bool = True) -> Frame:
        """The frame of a sample on ``key``, or ``_Dropped`` saying why not.
        ``replay``: refuse a sealed payload sealed before the last one taken
        (a subscription's; a query's replies are each new)."""
        if key != expected_key:
            raise _Dropped("wrong_key", f"put on {_quote(key)}, not {expected_key}")
        if self._seal is not None:
            try:
                counter, data = self._seal.open(key, data)
            except ValueError as e:
                raise _Dropped("not_authentic", str(e)) from e
            if replay:
                if counter <= self._newest:
                    raise _Dropped(
                        "replayed", f"sealed as number {counter}, after number {self._newest}"
                    )
                self._newest = counter
        try:
            message = parse_frame(data)
        except ValueError as e:
            raise _Dropped("undecodable", str(e)) from e
        if not message.HasField("header"):
            raise _Dropped("malformed", "frame without a header")
        session_id = message.header.session_id
        if session_id != self._session_id:
            raise _Dropped(
                "wrong_session", f"names session {_quote(session_id)}, not {self._session_id!r}"
            )
        try:
            return unpack_frame(message)
        except ValueError as e:
            raise _Dropped("malformed", str(e)) from e

    def _on_sample(self, sample) -> None:
        # Runs on zenoh's thread, where an exception would be logged and the
        # sample lost uncounted: every failure is a counted drop instead.
        try:
            frame = self._admit(str(sample.key_expr), sample.payload.to_bytes(), self._key)
        except _Dropped as e:
            self._drop(e.reason, e.why)
        except Exception as e:
            # A check that fails in a way decode_frame does not foresee.
            self._drop("malformed", f"{type(e).__name__}: {e}")
        else:
            self._queue.put(frame)

    def _drop(self, reason: str, why: str) -> None:
        with self._lock:
            self._drop_reasons[reason] += 1
            self._last_drop = (reason, why)

    def _latest(self) -> Frame | None:
        """The session's latest frame from its ``latest`` queryable: the last
        reply that passes the checks, the others skipped. Every queryable is
        asked and every reply kept (by default zenoh asks only a queryable
        declared complete when there is one, and keeps one reply per key,
        so another peer could answer in the server's place)."""
        key = latest_key(self._session_id)
        latest = None
        for reply in self._session.get(
            key, target=zenoh.QueryTarget.ALL, consolidation=zenoh.ConsolidationMode.NONE
        ):
            if reply.ok is None:
                continue
            try:
                latest = self._admit(
                    str(reply.ok.key_expr), reply.ok.payload.to_bytes(), key, replay=False
                )
            except Exception:
                # Skipped as the subscriber drops it, but not counted: the
                # counts are of the subscription.
                continue
        return latest

    def next(self, timeout: float = DEFAULT_TIMEOUT) -> Frame:
        """The next frame that passed the checks; raises ``queue.Empty``
        after ``timeout`` seconds."""
        return self._queue.get(timeout=timeout)

    def close(self) -> None:
        self._subscriber.undeclare()
        self._session.close()

    def __enter__(self) -> "Frames":
        return self

    def __exit__(self, *_exc) -> None:
        self.close()
