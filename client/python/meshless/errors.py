"""The one exception the clients raise for a failed call."""

from __future__ import annotations

import time

import grpc


class MeshlessError(Exception):
    """A call the server refused or that did not complete.

    ``code`` is the gRPC status code (``grpc.StatusCode.INVALID_ARGUMENT``
    for a bad scene, ``NOT_FOUND`` for an unknown session,
    ``DEADLINE_EXCEEDED`` past a call's timeout, ``UNAVAILABLE`` when no
    server answers, ...); ``details`` is the server's message, which names
    what to change. ``docs/protocol.md`` lists which call answers which
    code.
    """

    def __init__(self, code: grpc.StatusCode, details: str):
        super().__init__(f"{code.name}: {details}")
        self.code = code
        self.details = details

    @classmethod
    def from_rpc_error(cls, error: grpc.RpcError) -> "MeshlessError":
        """The exception for a failed gRPC call (sync or asyncio)."""
        code = error.code() if hasattr(error, "code") else grpc.StatusCode.UNKNOWN
        details = error.details() if hasattr(error, "details") else str(error)
        return cls(code or grpc.StatusCode.UNKNOWN, details or "")


def call_error(error: grpc.RpcError, deadline_at: float | None) -> MeshlessError:
    """The exception for a failed call that had to end by ``deadline_at``
    (``time.monotonic()``; ``None`` without a deadline). A tonic server
    answers a call whose deadline passed with CANCELLED ("Timeout
    expired") when its own timer fires before the client's: that is
    DEADLINE_EXCEEDED, as gRPC has it and as the client's timer would
    have said."""
    e = MeshlessError.from_rpc_error(error)
    if (
        e.code == grpc.StatusCode.CANCELLED
        and deadline_at is not None
        and time.monotonic() >= deadline_at
    ):
        return MeshlessError(
            grpc.StatusCode.DEADLINE_EXCEEDED, f"the call's deadline passed ({e.details})"
        )
    return e


def deadline_at(timeout: float | None) -> float | None:
    """When a call with ``timeout`` seconds must end, on ``time.monotonic()``."""
    return None if timeout is None else time.monotonic() + timeout
