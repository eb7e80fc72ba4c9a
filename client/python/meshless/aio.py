"""The asyncio client (``grpc.aio``): the calls of :class:`meshless.Client`
as coroutines, streams as async iterators, frames as :class:`AsyncFrames`."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable, Collection, Iterable
from typing import Any, Generic, TypeVar

import grpc
import grpc.aio

from .client import _LATEST_FRAME, state_value
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
from .subscriber import AsyncFrames

__all__ = ["AsyncClient", "AsyncFrames", "AsyncStream"]

T = TypeVar("T")


class AsyncStream(Generic[T]):
    """A server stream: ``async for`` its messages; :meth:`cancel` (or
    leaving an ``async with`` block) stops it, after which iteration ends
    quietly. A failure raises :class:`MeshlessError`."""

    def __init__(self, call: Any, ends_at: float | None = None):
        self._call = call
        self._ends_at = ends_at
        self._cancelled = False

    def __aiter__(self) -> AsyncIterator[T]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[T]:
        try:
            async for message in self._call:
                yield message
        except asyncio.CancelledError:
            if self._cancelled:
                return
            raise
        except grpc.RpcError as e:
            if self._cancelled and e.code() == grpc.StatusCode.CANCELLED:
                return
            raise call_error(e, self._ends_at) from None

    def cancel(self) -> None:
        """Stops the stream (the server sees the call cancelled)."""
        self._cancelled = True
        self._call.cancel()

    async def __aenter__(self) -> "AsyncStream[T]":
        return self

    async def __aexit__(self, *_exc: object) -> None:
        self.cancel()


class AsyncClient:
    """Drives a meshless server over gRPC from asyncio.

    The arguments and methods are those of :class:`meshless.Client`, each
    call a coroutine. Make it inside the event loop that uses it, and open
    it with ``async with AsyncClient(target) as client`` (or ``await
    client.connect()``), which waits up to
    ``timeout`` seconds for the server (``UNAVAILABLE`` otherwise);
    ``await client.close()`` at the end. Streams (``watch_status``,
    ``simulate_steps``) are :class:`AsyncStream` async iterators.
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
        self._target = target
        self._timeout = timeout
        self._connection = Connection.make(
            target, token, client_id, take_over, tls, tls_ca, tls_cert, tls_key, tls_domain
        )
        c = self._connection
        if c.credentials is not None:
            self._channel = grpc.aio.secure_channel(target, c.credentials, options=c.options)
        else:
            self._channel = grpc.aio.insecure_channel(target, options=c.options)
        self._stub = simulation_pb2_grpc.SimulationStub(self._channel)
        self._latest_frame = self._channel.unary_unary(
            _LATEST_FRAME,
            request_serializer=pb.SessionRef.SerializeToString,
            response_deserializer=None,
        )
        self._info: Any = None

    async def connect(self) -> "AsyncClient":
        """Waits for the server, up to the client's ``timeout``."""
        try:
            await asyncio.wait_for(self._channel.channel_ready(), self._timeout)
        except asyncio.TimeoutError:
            raise MeshlessError(
                grpc.StatusCode.UNAVAILABLE,
                f"no server answered at {self._target} within {self._timeout} s",
            ) from None
        return self

    @property
    def stub(self) -> Any:
        """The generated ``SimulationStub`` on the aio channel; pass
        ``metadata=client.metadata`` to its calls."""
        return self._stub

    @property
    def metadata(self) -> tuple[tuple[str, str], ...]:
        """The metadata every call carries (token, client id, take-over)."""
        return self._connection.metadata

    async def close(self) -> None:
        """Closes the channel; calls in flight are cancelled."""
        await self._channel.close()

    async def __aenter__(self) -> "AsyncClient":
        try:
            return await self.connect()
        except BaseException:
            await self.close()
            raise

    async def __aexit__(self, *_exc: object) -> None:
        await self.close()

    async def _unary(self, method: Any, request: Any, timeout: float | None) -> Any:
        timeout = deadline(self._timeout, timeout)
        ends_at = deadline_at(timeout)
        try:
            return await method(request, timeout=timeout, metadata=self._connection.metadata)
        except grpc.RpcError as e:
            raise call_error(e, ends_at) from None

    def _stream(self, method: Any, request: Any, timeout: float | None) -> AsyncStream[Any]:
        ends_at = deadline_at(timeout)
        call = method(request, timeout=timeout, metadata=self._connection.metadata)
        return AsyncStream(call, ends_at=ends_at)

    def _ref(self, session: Any) -> Any:
        return self._pb.SessionRef(session_id=session_id_of(session))

    async def server_info(self, *, timeout: float | None = None) -> Any:
        """The server's ``ServerInfo``."""
        self._info = await self._unary(
            self._stub.GetServerInfo, self._pb.GetServerInfoRequest(), timeout
        )
        return self._info

    async def create_session(
        self, scene: Scene, observers: Iterable[str] = (), *, timeout: float | None = None
    ) -> Any:
        """Creates a session (see :meth:`meshless.Client.create_session`)."""
        request = create_session_request(scene, observers)
        return await self._unary(self._stub.CreateSession, request, timeout)

    async def get_session(self, session: Any, *, timeout: float | None = None) -> Any:
        """The session's ``Session``."""
        return await self._unary(self._stub.GetSession, self._ref(session), timeout)

    async def list_sessions(self, *, timeout: float | None = None) -> list[Any]:
        """Every session the caller may see, oldest first."""
        answer = await self._unary(
            self._stub.ListSessions, self._pb.ListSessionsRequest(), timeout
        )
        return list(answer.sessions)

    async def delete_session(self, session: Any, *, timeout: float | None = None) -> None:
        """Stops and removes the session."""
        await self._unary(self._stub.DeleteSession, self._ref(session), timeout)

    async def step(self, session: Any, steps: int = 1, *, timeout: float | None = None) -> Any:
        """Takes ``steps`` steps; the ``Session`` once done."""
        request = self._pb.StepRequest(session_id=session_id_of(session), steps=steps)
        return await self._unary(self._stub.Step, request, timeout)

    async def run(
        self,
        session: Any,
        *,
        until: float | None = None,
        forever: bool = False,
        realtime_factor: float | None = None,
        timeout: float | None = None,
    ) -> Any:
        """Starts stepping in the background (see :meth:`meshless.Client.run`)."""
        request = run_request(session_id_of(session), until, forever, realtime_factor)
        return await self._unary(self._stub.Run, request, timeout)

    async def pause(self, session: Any, *, timeout: float | None = None) -> Any:
        """Pauses a running session."""
        return await self._unary(self._stub.Pause, self._ref(session), timeout)

    async def resume(self, session: Any, *, timeout: float | None = None) -> Any:
        """Continues a paused run."""
        return await self._unary(self._stub.Resume, self._ref(session), timeout)

    async def reset(self, session: Any, *, timeout: float | None = None) -> Any:
        """Rebuilds the world from the session's scene."""
        return await self._unary(self._stub.Reset, self._ref(session), timeout)

    def simulate_steps(
        self,
        session: Any,
        steps: int,
        *,
        progress_interval: float | None = None,
        timeout: float | None = None,
    ) -> AsyncStream[Any]:
        """``SimulateProgress`` messages of ``steps`` steps (see
        :meth:`meshless.Client.simulate_steps`)."""
        request = simulate_steps_request(session_id_of(session), steps, progress_interval)
        return self._stream(self._stub.SimulateSteps, request, timeout)

    async def simulate(
        self,
        session: Any,
        steps: int,
        *,
        on_progress: Callable[[Any], None] | None = None,
        progress_interval: float | None = None,
        timeout: float | None = None,
    ) -> Any:
        """:meth:`simulate_steps` to its end; returns the last message."""
        last = None
        async for progress in self.simulate_steps(
            session, steps, progress_interval=progress_interval, timeout=timeout
        ):
            if on_progress is not None:
                on_progress(progress)
            last = progress
        if last is None:
            raise MeshlessError(grpc.StatusCode.INTERNAL, "SimulateSteps sent no message")
        return last

    def watch_status(self, session: Any, *, timeout: float | None = None) -> AsyncStream[Any]:
        """The session's ``SessionStatus`` now, then at every change."""
        return self._stream(self._stub.WatchStatus, self._ref(session), timeout)

    async def wait_for(
        self,
        session: Any,
        states: Collection[str | int] = ("finished", "paused", "faulted", "closed"),
        *,
        timeout: float | None = None,
    ) -> Any:
        """The first ``SessionStatus`` whose state is one of ``states``."""
        wanted = {state_value(s) for s in states}
        async with self.watch_status(session, timeout=deadline(self._timeout, timeout)) as statuses:
            async for status in statuses:
                if status.state in wanted:
                    return status
        raise MeshlessError(grpc.StatusCode.NOT_FOUND, "the status stream ended first")

    async def latest_frame(self, session: Any, *, timeout: float | None = None) -> Frame:
        """The session's latest frame over gRPC."""
        return decode_frame(await self._unary(self._latest_frame, self._ref(session), timeout))

    async def next_frame(
        self, session: Any, after: int = 0, *, wait: float = 5.0, timeout: float | None = None
    ) -> tuple[int, Frame | None]:
        """As :meth:`meshless.Client.next_frame`: ``(number, frame)`` once
        a frame newer than ``after`` exists, ``(after, None)`` after
        ``wait`` seconds without one."""
        request = self._pb.NextFrameRequest(
            session_id=session_id_of(session), after=after, wait_ms=round(wait * 1000)
        )
        reply = await self._unary(
            self._stub.NextFrame, request, timeout or max(self._timeout, wait + 5.0)
        )
        if not reply.frame:
            return reply.number, None
        return reply.number, decode_frame(reply.frame)

    async def frames(
        self,
        session: Any,
        *,
        zenoh_config: str | None = None,
        endpoints: Iterable[str] | None = None,
    ) -> AsyncFrames:
        """An open zenoh subscription to the session's frames
        (:class:`AsyncFrames`; ``async with`` it to close it)."""
        if endpoints is None:
            info = self._info if self._info is not None else await self.server_info()
            endpoints = info.zenoh_locators
        frames = AsyncFrames(list(endpoints), session, zenoh_config=zenoh_config, timeout=self._timeout)
        return await frames.open()

    async def edit_constraints(
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
        """Applies constraint edits all or nothing (see
        :meth:`meshless.Client.edit_constraints`)."""
        request = constraint_edits(
            session_id_of(session), edits, clear=clear, remove=remove, replace=replace, add=add
        )
        return list((await self._unary(self._stub.EditConstraints, request, timeout)).constraints)

    async def list_constraints(self, session: Any, *, timeout: float | None = None) -> list[Any]:
        """The session's constraints in name order."""
        answer = await self._unary(self._stub.ListConstraints, self._ref(session), timeout)
        return list(answer.constraints)

    async def optimize(
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
        """Optimises and returns the :class:`Design` (see
        :meth:`meshless.Client.optimize`)."""
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
        async with self._stream(self._stub.Optimize, request, timeout) as events:
            async for event in events:
                which = event.WhichOneof("event")
                if which == "progress":
                    if on_progress is not None:
                        on_progress(event.progress)
                elif which == "result":
                    return Design.from_proto(event.result)
        raise MeshlessError(grpc.StatusCode.INTERNAL, "the optimisation stream ended without a result")

    async def cancel_optimize(self, session: Any, *, timeout: float | None = None) -> bool:
        """Cancels the running optimisation; whether there was one."""
        answer = await self._unary(self._stub.CancelOptimize, self._ref(session), timeout)
        return answer.cancelled

    async def get_design(self, session: Any, *, timeout: float | None = None) -> Design:
        """The last successful design; NOT_FOUND before the first."""
        return Design.from_proto(
            await self._unary(self._stub.GetDesign, self._ref(session), timeout)
        )

    async def snapshot(self, session: Any, *, timeout: float | None = None) -> Any:
        """The session's state as a ``SessionSnapshot``."""
        return await self._unary(self._stub.Snapshot, self._ref(session), timeout)

    async def restore(
        self,
        snapshot: Any,
        *,
        session: Any = None,
        observers: Iterable[str] | None = None,
        timeout: float | None = None,
    ) -> Any:
        """Restores a snapshot (see :meth:`meshless.Client.restore`)."""
        request = restore_request(
            snapshot, "" if session is None else session_id_of(session), observers
        )
        return await self._unary(self._stub.Restore, request, timeout)

    async def change_particles(
        self,
        session: Any,
        system: int = 0,
        *,
        remove: Iterable[int] = (),
        positions: Iterable[Iterable[float]] = (),
        velocities: Iterable[Iterable[float]] = (),
        timeout: float | None = None,
    ) -> tuple[Any, range]:
        """Removes and adds particles (see
        :meth:`meshless.Client.change_particles`)."""
        request = change_particles_request(
            session_id_of(session), system, remove, positions, velocities
        )
        answer = await self._unary(self._stub.ChangeParticles, request, timeout)
        first = answer.first_inserted_id
        return answer.session, range(first, first + answer.inserted)
