"""The synchronous client: every call of ``meshless.v1.Simulation`` over
gRPC, and the session's frames over zenoh."""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Iterator
from typing import Any, Generic, TypeVar

import grpc

from .connection import (
    DEFAULT_TARGET,
    DEFAULT_TIMEOUT,
    Connection,
    Pem,
    Scene,
    change_particles_request,
    constraint_edits,
    create_session_request,
    deadline,
    restore_request,
    run_request,
    session_id_of,
    simulate_steps_request,
)
from .design import Design, optimize_request
from .errors import MeshlessError, call_error, deadline_at
from .frames import Frame, decode_frame
from .subscriber import FrameCallback, Frames

__all__ = ["Client", "Design", "Frames", "Stream", "state_name", "state_value"]

T = TypeVar("T")
U = TypeVar("U")

# The raw GetLatestFrame call: its answer as bytes, which the frame's
# arrays then view (decode_frame) instead of a parsed message's copies.
_LATEST_FRAME = "/meshless.v1.Simulation/GetLatestFrame"


def state_name(state: Any) -> str:
    """A ``SessionState`` (a number, or a ``SessionStatus`` or ``Session``
    message) as its short name: ``"idle"``, ``"running"``, ``"paused"``,
    ``"finished"``, ``"faulted"``, ``"closed"``."""
    from .v1 import simulation_pb2 as pb

    if hasattr(state, "status"):
        state = state.status
    if hasattr(state, "state"):
        state = state.state
    return pb.SessionState.Name(state).removeprefix("SESSION_STATE_").lower()


def state_value(name: str | int) -> int:
    """A ``SessionState`` number from its short name (``"finished"``)."""
    from .v1 import simulation_pb2 as pb

    if isinstance(name, int):
        return name
    return pb.SessionState.Value("SESSION_STATE_" + name.upper())


class Stream(Generic[T]):
    """A server stream: iterate it for its messages; :meth:`cancel` (or
    leaving a ``with`` block) stops it, after which iteration ends
    quietly. A failure raises :class:`MeshlessError`."""

    def __init__(
        self,
        call: Any,
        convert: Callable[[Any], T] = lambda m: m,
        ends_at: float | None = None,
    ):
        self._call = call
        self._convert = convert
        self._ends_at = ends_at
        self._cancelled = False

    def __iter__(self) -> Iterator[T]:
        try:
            for message in self._call:
                yield self._convert(message)
        except grpc.RpcError as e:
            if self._cancelled and e.code() == grpc.StatusCode.CANCELLED:
                return
            raise call_error(e, self._ends_at) from None

    def cancel(self) -> None:
        """Stops the stream (the server sees the call cancelled)."""
        self._cancelled = True
        self._call.cancel()

    def __enter__(self) -> "Stream[T]":
        return self

    def __exit__(self, *_exc: object) -> None:
        self.cancel()


class Client:
    """Drives a meshless server over gRPC.

    ``target`` is ``host:port``. ``timeout`` bounds the wait for the
    connection and is the deadline of each call that takes none of its
    own (a call's ``timeout=`` keyword); streams (``watch_status``,
    ``simulate_steps``, ``optimize``) have no deadline unless given one.
    ``token`` is the bearer token of a server with tokens; ``client_id``
    names this client instance (one instance drives a session at a time);
    ``take_over`` takes control of sessions another instance drives.
    ``tls`` speaks TLS to a server started with ``--tls-cert``, checking
    its certificate against ``tls_ca`` (default: the system's CAs) and the
    name ``tls_domain`` (default: the target's host); a server with
    ``--tls-client-ca`` also wants ``tls_cert`` and ``tls_key``. The PEM
    values are bytes, text or a file path; any ``tls_*`` argument implies
    ``tls``.

    Sessions are named by their id or their ``Session`` message. Answers
    are the protocol's messages (``meshless.v1``), frames a
    :class:`meshless.Frame` of numpy arrays, designs a
    :class:`meshless.Design`. Every failure raises
    :class:`meshless.MeshlessError` with the gRPC code and the server's
    message, ``UNAVAILABLE`` when no server answers within ``timeout``.
    """

    def __init__(
        self,
        target: str = DEFAULT_TARGET,
        timeout: float = DEFAULT_TIMEOUT,
        token: str | None = None,
        client_id: str | None = None,
        take_over: bool = False,
        tls: bool = False,
        tls_ca: Pem | None = None,
        tls_cert: Pem | None = None,
        tls_key: Pem | None = None,
        tls_domain: str | None = None,
    ):
        from .v1 import simulation_pb2 as pb
        from .v1 import simulation_pb2_grpc

        self._pb = pb
        self._timeout = timeout
        self._connection = Connection.make(
            target, token, client_id, take_over, tls, tls_ca, tls_cert, tls_key, tls_domain
        )
        c = self._connection
        if c.credentials is not None:
            self._channel = grpc.secure_channel(target, c.credentials, options=c.options)
        else:
            self._channel = grpc.insecure_channel(target, options=c.options)
        try:
            grpc.channel_ready_future(self._channel).result(timeout=timeout)
        except grpc.FutureTimeoutError:
            self._channel.close()
            raise MeshlessError(
                grpc.StatusCode.UNAVAILABLE,
                f"no server answered at {target} within {timeout} s"
                + (" (over TLS: is the CA right?)" if c.credentials is not None else ""),
            ) from None
        self._stub = simulation_pb2_grpc.SimulationStub(self._channel)
        self._latest_frame = self._channel.unary_unary(
            _LATEST_FRAME,
            request_serializer=pb.SessionRef.SerializeToString,
            response_deserializer=None,
        )
        self._info: Any = None

    @property
    def stub(self) -> Any:
        """The generated ``SimulationStub``, for what this class does not
        wrap; pass ``metadata=client.metadata`` to its calls."""
        return self._stub

    @property
    def metadata(self) -> tuple[tuple[str, str], ...]:
        """The metadata every call carries (token, client id, take-over)."""
        return self._connection.metadata

    def close(self) -> None:
        """Closes the channel; calls in flight are cancelled."""
        self._channel.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    # --- plumbing ------------------------------------------------------------

    def _unary(self, method: Any, request: Any, timeout: float | None) -> Any:
        timeout = deadline(self._timeout, timeout)
        ends_at = deadline_at(timeout)
        try:
            return method(request, timeout=timeout, metadata=self._connection.metadata)
        except grpc.RpcError as e:
            raise call_error(e, ends_at) from None

    def _stream(self, method: Any, request: Any, timeout: float | None) -> Stream[Any]:
        ends_at = deadline_at(timeout)
        call = method(request, timeout=timeout, metadata=self._connection.metadata)
        return Stream(call, ends_at=ends_at)

    def _ref(self, session: Any) -> Any:
        return self._pb.SessionRef(session_id=session_id_of(session))

    # --- sessions ------------------------------------------------------------

    def server_info(self, *, timeout: float | None = None) -> Any:
        """The server's ``ServerInfo``: version, limits, zenoh locators."""
        self._info = self._unary(self._stub.GetServerInfo, self._pb.GetServerInfoRequest(), timeout)
        return self._info

    def create_session(
        self, scene: Scene, observers: Iterable[str] = (), *, timeout: float | None = None
    ) -> Any:
        """Creates a session and returns its ``Session``. ``scene`` is TOML
        text (a ``str``), a TOML file (a ``pathlib.Path``; its meshes go
        inline), a dict (:mod:`meshless.scene`) or a ``SceneSpec`` message.
        ``observers`` names principals that may see it read-only (``"*"``:
        everyone). The server validates it: ``INVALID_ARGUMENT`` names the
        bad field, ``RESOURCE_EXHAUSTED`` a limit passed."""
        request = create_session_request(scene, observers)
        return self._unary(self._stub.CreateSession, request, timeout)

    def get_session(self, session: Any, *, timeout: float | None = None) -> Any:
        """The session's ``Session``: status and scene; NOT_FOUND if unknown."""
        return self._unary(self._stub.GetSession, self._ref(session), timeout)

    def list_sessions(self, *, timeout: float | None = None) -> list[Any]:
        """Every session the caller may see, oldest first, without their
        scenes (``get_session`` has them)."""
        answer = self._unary(self._stub.ListSessions, self._pb.ListSessionsRequest(), timeout)
        return list(answer.sessions)

    def delete_session(self, session: Any, *, timeout: float | None = None) -> None:
        """Stops and removes the session."""
        self._unary(self._stub.DeleteSession, self._ref(session), timeout)

    # --- stepping ------------------------------------------------------------

    def step(self, session: Any, steps: int = 1, *, timeout: float | None = None) -> Any:
        """Takes ``steps`` steps and returns the ``Session`` once done."""
        request = self._pb.StepRequest(session_id=session_id_of(session), steps=steps)
        return self._unary(self._stub.Step, request, timeout)

    def run(
        self,
        session: Any,
        *,
        until: float | None = None,
        forever: bool = False,
        realtime_factor: float | None = None,
        timeout: float | None = None,
    ) -> Any:
        """Starts stepping in the background, to simulated time ``until``
        (then FINISHED) or ``forever`` (until paused); ``realtime_factor``
        paces it (simulated seconds per second). Returns at once."""
        request = run_request(session_id_of(session), until, forever, realtime_factor)
        return self._unary(self._stub.Run, request, timeout)

    def run_until(
        self, session: Any, until: float, realtime_factor: float | None = None
    ) -> Any:
        """``run(session, until=until, realtime_factor=...)``."""
        return self.run(session, until=until, realtime_factor=realtime_factor)

    def pause(self, session: Any, *, timeout: float | None = None) -> Any:
        """Pauses a running session."""
        return self._unary(self._stub.Pause, self._ref(session), timeout)

    def resume(self, session: Any, *, timeout: float | None = None) -> Any:
        """Continues a paused run."""
        return self._unary(self._stub.Resume, self._ref(session), timeout)

    def reset(self, session: Any, *, timeout: float | None = None) -> Any:
        """Rebuilds the world from the session's scene; clears a fault."""
        return self._unary(self._stub.Reset, self._ref(session), timeout)

    def simulate_steps(
        self,
        session: Any,
        steps: int,
        *,
        progress_interval: float | None = None,
        timeout: float | None = None,
    ) -> Stream[Any]:
        """Takes ``steps`` steps, streaming ``SimulateProgress`` messages
        (at the start, every ``progress_interval`` seconds, at the end,
        ``done`` set on the last). Cancelling the stream or passing
        ``timeout`` stops the session at the last completed step, paused."""
        request = simulate_steps_request(session_id_of(session), steps, progress_interval)
        return self._stream(self._stub.SimulateSteps, request, timeout)

    def simulate(
        self,
        session: Any,
        steps: int,
        *,
        on_progress: Callable[[Any], None] | None = None,
        progress_interval: float | None = None,
        timeout: float | None = None,
    ) -> Any:
        """:meth:`simulate_steps` to its end, calling ``on_progress`` with
        each message; returns the last (``done``)."""
        last = None
        for progress in self.simulate_steps(
            session, steps, progress_interval=progress_interval, timeout=timeout
        ):
            if on_progress is not None:
                on_progress(progress)
            last = progress
        if last is None:
            raise MeshlessError(grpc.StatusCode.INTERNAL, "SimulateSteps sent no message")
        return last

    # --- status and frames ---------------------------------------------------

    def watch_status(self, session: Any, *, timeout: float | None = None) -> Stream[Any]:
        """The session's ``SessionStatus`` now, then at every change until
        it is deleted (a last CLOSED): iterate the returned stream, cancel
        it to stop."""
        return self._stream(self._stub.WatchStatus, self._ref(session), timeout)

    def wait_for(
        self,
        session: Any,
        states: Collection[str | int] = ("finished", "paused", "faulted", "closed"),
        *,
        timeout: float | None = None,
    ) -> Any:
        """Watches the session until its state is one of ``states`` (short
        names or numbers) and returns that ``SessionStatus``;
        ``DEADLINE_EXCEEDED`` after ``timeout`` seconds (default: the
        client's)."""
        wanted = {state_value(s) for s in states}
        with self.watch_status(session, timeout=deadline(self._timeout, timeout)) as statuses:
            for status in statuses:
                if status.state in wanted:
                    return status
        raise MeshlessError(grpc.StatusCode.NOT_FOUND, "the status stream ended first")

    def latest_frame(self, session: Any, *, timeout: float | None = None) -> Frame:
        """The session's latest frame over gRPC (for clients without
        zenoh), its arrays viewing the answer's bytes."""
        return decode_frame(self._unary(self._latest_frame, self._ref(session), timeout))

    def next_frame(
        self, session: Any, after: int = 0, *, wait: float = 5.0, timeout: float | None = None
    ) -> tuple[int, Frame | None]:
        """The session's latest frame once it is newer than frame number
        ``after`` (0: at once), waiting up to ``wait`` seconds (at most 60)
        on the server: ``(number, frame)``, or ``(after, None)`` when none
        came in time. Pass the number back as ``after``: one call at a time
        follows the session's frames over gRPC, skipping those a slow
        reader would not keep up with (the browser viewer reads this way)."""
        request = self._pb.NextFrameRequest(
            session_id=session_id_of(session), after=after, wait_ms=round(wait * 1000)
        )
        # The call's deadline leaves the wait room to answer.
        reply = self._unary(self._stub.NextFrame, request, timeout or max(self._timeout, wait + 5.0))
        if not reply.frame:
            return reply.number, None
        return reply.number, decode_frame(reply.frame)

    def frames(
        self,
        session: Any,
        *,
        callback: FrameCallback | None = None,
        zenoh_config: str | None = None,
        endpoints: Iterable[str] | None = None,
    ) -> Frames:
        """A zenoh subscription to the session's frames (:class:`Frames`),
        at the server's ``zenoh_locators`` unless ``endpoints`` are given.
        Pass the ``Session`` message to open sealed frames."""
        if endpoints is None:
            info = self._info if self._info is not None else self.server_info()
            endpoints = info.zenoh_locators
        return Frames(
            list(endpoints),
            session,
            zenoh_config=zenoh_config,
            callback=callback,
            timeout=self._timeout,
        )

    # --- design --------------------------------------------------------------

    def edit_constraints(
        self,
        session: Any,
        edits: Iterable[Any] = (),
        *,
        clear: bool = False,
        remove: Iterable[str] = (),
        replace: Iterable[Any] = (),
        add: Iterable[Any] = (),
        timeout: float | None = None,
    ) -> list[Any]:
        """Applies constraint edits all or nothing: ``edits``
        (``ConstraintEdit`` messages), then ``clear``, ``remove`` (names),
        ``replace`` and ``add`` (``Constraint`` messages or TOML-form
        dicts, :func:`meshless.design.constraint`). Returns the
        constraints in name order; INVALID_ARGUMENT names the bad one."""
        request = constraint_edits(
            session_id_of(session), edits, clear=clear, remove=remove, replace=replace, add=add
        )
        return list(self._unary(self._stub.EditConstraints, request, timeout).constraints)

    def list_constraints(self, session: Any, *, timeout: float | None = None) -> list[Any]:
        """The session's constraints in name order."""
        return list(self._unary(self._stub.ListConstraints, self._ref(session), timeout).constraints)

    def optimize(
        self,
        request: Any = None,
        *,
        session: Any = None,
        system: int = 0,
        problem: str = "shape",
        design: Any = None,
        motion: Any = None,
        playback_rate: float | None = None,
        playback: bool = False,
        on_progress: Callable[[Any], None] | None = None,
        timeout: float | None = None,
    ) -> Design:
        """Optimises a solid of the session against its constraints and
        returns the :class:`Design`, calling ``on_progress`` with each
        ``DesignProgress``. Give an ``OptimizeRequest`` or the keywords
        (:func:`meshless.design.optimize_request`: ``problem`` ``"shape"``
        or ``"motion"``, ``design``/``motion`` settings as dicts or
        messages, ``playback`` to publish the result as frames). Raises
        :class:`MeshlessError` (CANCELLED, INVALID_ARGUMENT, ABORTED)."""
        if request is None:
            if session is None:
                raise ValueError("give an OptimizeRequest or session=")
            request = optimize_request(
                session_id_of(session),
                system=system,
                problem=problem,
                design=design,
                motion=motion,
                playback_rate=playback_rate,
                playback=playback,
            )
        events = self._stream(self._stub.Optimize, request, timeout)
        for event in events:
            which = event.WhichOneof("event")
            if which == "progress":
                if on_progress is not None:
                    on_progress(event.progress)
            elif which == "result":
                return Design.from_proto(event.result)
        raise MeshlessError(grpc.StatusCode.INTERNAL, "the optimisation stream ended without a result")

    def cancel_optimize(self, session: Any, *, timeout: float | None = None) -> bool:
        """Cancels the running optimisation; whether there was one."""
        return self._unary(self._stub.CancelOptimize, self._ref(session), timeout).cancelled

    def get_design(self, session: Any, *, timeout: float | None = None) -> Design:
        """The last successful design; NOT_FOUND before the first."""
        return Design.from_proto(self._unary(self._stub.GetDesign, self._ref(session), timeout))

    # --- snapshots -----------------------------------------------------------

    def snapshot(self, session: Any, *, timeout: float | None = None) -> Any:
        """The session's state as a ``SessionSnapshot`` (its ``data`` an
        opaque, checksummed blob); the owner alone may take one."""
        return self._unary(self._stub.Snapshot, self._ref(session), timeout)

    def restore(
        self,
        snapshot: Any,
        *,
        session: Any = None,
        observers: Iterable[str] | None = None,
        timeout: float | None = None,
    ) -> Any:
        """Restores a snapshot (a ``SessionSnapshot`` or its ``data``) into a
        new session, or into ``session`` (same scene, not running), and
        returns that ``Session``. ``observers`` replaces a new session's
        (default: the snapshot's). INVALID_ARGUMENT for a blob of another
        build, truncated or corrupted; nothing changes then."""
        request = restore_request(
            snapshot, "" if session is None else session_id_of(session), observers
        )
        return self._unary(self._stub.Restore, request, timeout)

    def change_particles(
        self,
        session: Any,
        system: int = 0,
        *,
        remove: Iterable[int] = (),
        positions: Iterable[Iterable[float]] = (),
        velocities: Iterable[Iterable[float]] = (),
        timeout: float | None = None,
    ) -> tuple[Any, range]:
        """Removes the particles of system ``system`` (the scene's index of
        the fluid) whose ids ``remove`` lists and adds new ones at
        ``positions`` moving at ``velocities`` (``[x, y, z]`` rows), all or
        nothing, from the session's next step. Returns the ``Session`` and
        the ``range`` of ids the new particles get; a frame's ``ids``
        (``output.fields = ["id"]``) names every particle, so a particle
        is followed from frame to frame by its id. INVALID_ARGUMENT names
        what is wrong; RESOURCE_EXHAUSTED past the particles the session
        was created with; nothing changes then."""
        request = change_particles_request(
            session_id_of(session), system, remove, positions, velocities
        )
        answer = self._unary(self._stub.ChangeParticles, request, timeout)
        first = answer.first_inserted_id
        return answer.session, range(first, first + answer.inserted)
