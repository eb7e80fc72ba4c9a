"""A session's frames from zenoh: an iterator, a callback, and the
latest-frame query, each frame checked before it is handed on."""

from __future__ import annotations

import asyncio
import atexit
import json
import logging
import queue
import threading
import weakref
from collections import Counter
from collections.abc import AsyncIterator, Callable, Iterator, Sequence
from typing import Any

import zenoh

from .frames import Frame, frames_key, latest_key, parse_frame, unpack_frame
from .seal import Seal

DEFAULT_TIMEOUT = 30.0

log = logging.getLogger(__name__)

FrameCallback = Callable[[Frame], None]

# Subscriptions not closed yet. zenoh runs a subscription's Python callback
# on a thread of its own that Python waits for at exit, so a subscription
# left open would hang the interpreter's exit: they are closed first
# (threading's exit hooks run before it joins threads; `atexit` runs after).
_open: weakref.WeakSet["Frames"] = weakref.WeakSet()


def _close_open_subscriptions() -> None:
    for frames in list(_open):
        try:
            frames.close()
        except Exception:  # the process is ending: nothing left to tell
            pass


getattr(threading, "_register_atexit", atexit.register)(_close_open_subscriptions)


class _Dropped(Exception):
    """Why :class:`Frames` refuses a sample: a reason of
    ``Frames.drop_reasons`` and what was wrong."""

    def __init__(self, reason: str, why: str):
        super().__init__(why)
        self.reason = reason
        self.why = why


class _Closed:
    """What the queue holds after the last frame once closed."""


def _quote(text: str) -> str:
    """At most 64 characters of text a peer chose, quoted, so that a hostile
    sample cannot flood ``last_drop``."""
    return repr(text if len(text) <= 64 else text[:64] + "…")


def zenoh_client_config(endpoints: Sequence[str], zenoh_config: str | None = None) -> zenoh.Config:
    """A zenoh configuration in client mode against ``endpoints``, without
    multicast scouting, starting from the file ``zenoh_config`` (JSON5)
    when given."""
    config = zenoh.Config() if zenoh_config is None else zenoh.Config.from_file(zenoh_config)
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps(list(endpoints)))
    config.insert_json5("scouting/multicast/enabled", "false")
    return config


class Frames:
    """A session's frames from zenoh, decoded into numpy arrays.

    Opens zenoh in client mode against the given endpoints (the server's
    ``zenoh_locators`` or a router's). Once constructed, the server knows
    of the subscription: a latest-frame query has made the round trip, so
    no frame published afterwards is missed. ``latest`` is the frame that
    query returned (``None`` when no server answered with a valid one);
    :meth:`query_latest` asks again.

    Frames are handed on in one of two ways. Without ``callback`` they are
    queued: :meth:`next` takes one, and iterating (``for frame in
    frames``) takes them as they come until :meth:`close`, raising
    ``TimeoutError`` when none comes for ``timeout`` seconds. With
    ``callback``, it is called with each frame on zenoh's thread instead
    (keep it short: zenoh waits for it); an exception it raises is logged
    and counted in ``callback_errors``.

    Any zenoh peer can put on a session's key, so each sample is checked in
    zenoh's callback before it is handed on: it must be put on exactly the
    session's frame key, decode as a ``Frame`` whose header names this
    session, and pass :func:`meshless.decode_frame`'s checks. Anything else
    is dropped and counted: ``dropped`` (the total), ``drop_reasons`` (by
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
    frames are opened with it (:class:`meshless.Seal`), and a payload that
    does not open (``not_authentic``) or was sealed before the last one
    taken (``replayed``) is dropped too. Before it subscribes, a sealed
    subscription asks for the session's latest frame and takes nothing
    sealed before that answer, so a recording of an older frame played to
    a fresh subscription is ``replayed`` as well.

    ``zenoh_config`` names a zenoh configuration file (JSON5) to start
    from: the CA of ``tls/`` endpoints, a client certificate.
    """

    def __init__(
        self,
        endpoints: Sequence[str],
        session: Any,
        zenoh_config: str | None = None,
        seal_key: bytes | None = None,
        callback: FrameCallback | None = None,
        timeout: float = DEFAULT_TIMEOUT,
    ):
        if isinstance(session, str):
            session_id, key = session, b""
        else:
            session_id, key = session.id, session.seal_key
        if seal_key is not None:
            key = seal_key
        self._seal = Seal(key) if key else None
        self._session_id = session_id
        self._key = frames_key(session_id)
        self._timeout = timeout
        self._newest = 0
        self._lock = threading.Lock()
        self._drop_reasons: Counter[str] = Counter()
        self._last_drop: tuple[str, str] | None = None
        self._callback = callback
        self._callback_errors = 0
        self._queue: queue.Queue[Frame | _Closed] = queue.Queue()
        self._closed = False
        self._session = zenoh.open(zenoh_client_config(endpoints, zenoh_config))
        try:
            # The replay floor: a fresh subscription has taken no counter
            # yet, so it would take any recorded payload. The answer is
            # sealed after everything the session put before it (one
            # counter seals all of a session's keys), and only the server
            # can seal it. Asked before subscribing, so that the floor
            # holds for the first sample the callback meets.
            if self._seal is not None:
                _, self._newest = self._query_latest()
            self._subscriber = self._session.declare_subscriber(self._key, self._on_sample)
            self.latest: Frame | None = self.query_latest()
        except BaseException:
            self._session.close()
            raise
        _open.add(self)

    @property
    def session_id(self) -> str:
        """The session whose frames these are."""
        return self._session_id

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

    @property
    def callback_errors(self) -> int:
        """Exceptions the callback raised so far."""
        with self._lock:
            return self._callback_errors

    def _admit(
        self, key: str, data: bytes, expected_key: str, replay: bool = True
    ) -> tuple[Frame, int]:
        """The frame of a sample on ``key`` and its seal counter (0
        unsealed), or ``_Dropped`` saying why not. ``replay``: refuse a
        sealed payload sealed before the last one taken (a subscription's;
        a query's replies are each new)."""
        if key != expected_key:
            raise _Dropped("wrong_key", f"put on {_quote(key)}, not {expected_key}")
        counter = 0
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
            return unpack_frame(message, data), counter
        except ValueError as e:
            raise _Dropped("malformed", str(e)) from e

    def _on_sample(self, sample: zenoh.Sample) -> None:
        # Runs on zenoh's thread, where an exception would be logged and the
        # sample lost uncounted: every failure is a counted drop instead.
        try:
            frame, _ = self._admit(str(sample.key_expr), sample.payload.to_bytes(), self._key)
        except _Dropped as e:
            self._drop(e.reason, e.why)
        except Exception as e:
            # A check that fails in a way decode_frame does not foresee.
            self._drop("malformed", f"{type(e).__name__}: {e}")
        else:
            self._deliver(frame)

    def _deliver(self, frame: Frame) -> None:
        if self._callback is None:
            self._queue.put(frame)
            return
        try:
            self._callback(frame)
        except Exception:
            log.exception("the frame callback of session %s raised", self._session_id)
            with self._lock:
                self._callback_errors += 1

    def _drop(self, reason: str, why: str) -> None:
        with self._lock:
            self._drop_reasons[reason] += 1
            self._last_drop = (reason, why)

    def query_latest(self) -> Frame | None:
        """The session's latest frame from its ``latest`` queryable: the
        reply that passes the checks and was sealed last (the last to come
        when unsealed), the others skipped; ``None`` when no reply does.
        Every queryable is asked and every reply kept (by default zenoh
        asks only a queryable declared complete when there is one, and
        keeps one reply per key, so another peer could answer in the
        server's place, or answer with a recorded older reply, which the
        seal counter outranks)."""
        return self._query_latest()[0]

    def _query_latest(self) -> tuple[Frame | None, int]:
        """:meth:`query_latest`'s frame and its seal counter (0 when none
        or unsealed)."""
        key = latest_key(self._session_id)
        latest: Frame | None = None
        newest = 0
        for reply in self._session.get(
            key,
            target=zenoh.QueryTarget.ALL,
            consolidation=zenoh.ConsolidationMode.NONE,
            timeout=self._timeout,
        ):
            if reply.ok is None:
                continue
            try:
                frame, counter = self._admit(
                    str(reply.ok.key_expr), reply.ok.payload.to_bytes(), key, replay=False
                )
            except Exception:
                # Skipped as the subscriber drops it, but not counted: the
                # counts are of the subscription.
                continue
            if counter >= newest:
                latest, newest = frame, counter
        return latest, newest

    def next(self, timeout: float | None = None) -> Frame:
        """The next frame that passed the checks, waiting at most
        ``timeout`` seconds (default: the constructor's); raises
        ``queue.Empty`` when none came, ``EOFError`` once closed, and
        ``RuntimeError`` with a callback (frames go there)."""
        if self._callback is not None:
            raise RuntimeError("these frames go to their callback; there is no queue to read")
        got = self._queue.get(timeout=self._timeout if timeout is None else timeout)
        if isinstance(got, _Closed):
            self._queue.put(got)
            raise EOFError("the subscription is closed")
        return got

    def iter(self, timeout: float | None = None) -> Iterator[Frame]:
        """The frames as they come, until :meth:`close`; raises
        ``TimeoutError`` when none comes for ``timeout`` seconds (default:
        the constructor's; ``float('inf')`` waits for ever)."""
        wait = self._timeout if timeout is None else timeout
        while True:
            try:
                yield self.next(None if wait == float("inf") else wait)
            except queue.Empty:
                raise TimeoutError(
                    f"no frame of session {self._session_id} in {wait} s"
                ) from None
            except EOFError:
                return

    def __iter__(self) -> Iterator[Frame]:
        return self.iter()

    def close(self) -> None:
        """Ends the subscription; iterations end after the frames queued."""
        if self._closed:
            return
        self._closed = True
        _open.discard(self)
        try:
            self._subscriber.undeclare()
        finally:
            self._session.close()
            self._queue.put(_Closed())

    def __enter__(self) -> "Frames":
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


class AsyncFrames:
    """:class:`Frames` for asyncio: ``async for frame in frames`` and
    ``await frames.next()``, the frames handed from zenoh's thread to the
    event loop. Open it with ``async with AsyncFrames(endpoints, session)
    as frames`` (zenoh opens on a worker thread); the arguments are those
    of :class:`Frames`, less ``callback``."""

    def __init__(
        self,
        endpoints: Sequence[str],
        session: Any,
        zenoh_config: str | None = None,
        seal_key: bytes | None = None,
        timeout: float = DEFAULT_TIMEOUT,
    ):
        self._args = (endpoints, session, zenoh_config, seal_key)
        self._timeout = timeout
        self._queue: asyncio.Queue[Frame | _Closed] = asyncio.Queue()
        self._frames: Frames | None = None

    async def open(self) -> "AsyncFrames":
        """Subscribes (once the latest-frame query has made its round
        trip); does nothing when already open."""
        if self._frames is not None:
            return self
        loop = asyncio.get_running_loop()

        def hand_on(frame: Frame) -> None:
            loop.call_soon_threadsafe(self._queue.put_nowait, frame)

        endpoints, session, zenoh_config, seal_key = self._args
        self._frames = await asyncio.to_thread(
            Frames, endpoints, session, zenoh_config, seal_key, hand_on, self._timeout
        )
        return self

    @property
    def frames(self) -> Frames:
        """The underlying subscription: its ``latest``, drop counters."""
        if self._frames is None:
            raise RuntimeError("AsyncFrames is not open: use `async with` or `await open()`")
        return self._frames

    @property
    def latest(self) -> Frame | None:
        """The frame the subscription's latest-frame query returned."""
        return self.frames.latest

    async def query_latest(self) -> Frame | None:
        """The session's latest frame over zenoh (:meth:`Frames.query_latest`)."""
        return await asyncio.to_thread(self.frames.query_latest)

    async def next(self, timeout: float | None = None) -> Frame:
        """The next frame; ``TimeoutError`` after ``timeout`` seconds
        (default: the constructor's), ``EOFError`` once closed."""
        self.frames  # noqa: B018 - raises when not open
        wait = self._timeout if timeout is None else timeout
        try:
            got = await asyncio.wait_for(self._queue.get(), wait)
        except asyncio.TimeoutError:
            raise TimeoutError(f"no frame in {wait} s") from None
        if isinstance(got, _Closed):
            self._queue.put_nowait(got)
            raise EOFError("the subscription is closed")
        return got

    def __aiter__(self) -> AsyncIterator[Frame]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[Frame]:
        while True:
            try:
                yield await self.next()
            except EOFError:
                return

    async def close(self) -> None:
        """Ends the subscription; iterations end after the frames queued."""
        if self._frames is not None:
            await asyncio.to_thread(self._frames.close)
            self._queue.put_nowait(_Closed())

    async def __aenter__(self) -> "AsyncFrames":
        return await self.open()

    async def __aexit__(self, *_exc: object) -> None:
        await self.close()
