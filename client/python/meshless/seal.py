"""Sealed zenoh payloads (``meshless_proto::seal`` on the Rust side).

A server with tokens seals what it puts on a session's keys: one version
byte (1), a 12-byte nonce whose last 8 bytes are a big-endian counter,
then the message encrypted with AES-256-GCM under the session's
``Session.seal_key``, its 16-byte tag appended, with the key expression as
associated data. ``docs/protocol.md`` ("Sealed payloads") has the why.
"""

from __future__ import annotations

from cryptography.exceptions import InvalidTag
from cryptography.hazmat.primitives.ciphers.aead import AESGCM

VERSION = 1
KEY_LEN = 32
_NONCE_LEN = 12
_HEADER_LEN = 1 + _NONCE_LEN
_TAG_LEN = 16


class Seal:
    """Opens a session's sealed payloads with its 32-byte key."""

    def __init__(self, key: bytes):
        if len(key) != KEY_LEN:
            raise ValueError(f"a seal key has {KEY_LEN} bytes, this one {len(key)}")
        self._aead = AESGCM(bytes(key))

    def open(self, key_expr: str, payload: bytes) -> tuple[int, bytes]:
        """The counter and the message of ``payload``, sealed for
        ``key_expr``; ``ValueError`` when it is too short, of another
        version, or does not open (another key, another key expression,
        altered bytes, or not sealed at all)."""
        if len(payload) < _HEADER_LEN + _TAG_LEN:
            raise ValueError(
                f"{len(payload)} bytes is too short for a sealed payload "
                f"(at least {_HEADER_LEN + _TAG_LEN})"
            )
        if payload[0] != VERSION:
            raise ValueError(f"sealed payload version {payload[0]}, expected {VERSION}")
        view = memoryview(payload)
        nonce = bytes(view[1:_HEADER_LEN])
        try:
            plain = self._aead.decrypt(nonce, view[_HEADER_LEN:], key_expr.encode())
        except InvalidTag as e:
            raise ValueError(
                "the payload does not open with the session's key on this key expression"
            ) from e
        return int.from_bytes(nonce[4:], "big"), plain
