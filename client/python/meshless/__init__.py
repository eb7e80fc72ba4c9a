"""Python client of meshless.

- :class:`Client` (synchronous) and :class:`AsyncClient` (asyncio) wrap
  every call of the gRPC service ``meshless.v1.Simulation`` with keyword
  arguments, per-call deadlines, bearer tokens, client instances and TLS;
  every failure raises :class:`MeshlessError` with the gRPC ``code`` and
  the server's ``details``.
- :class:`Frames` (and :class:`AsyncFrames`) subscribe to a session's
  frames over zenoh: an iterator, a callback, the latest-frame query. Each
  sample is checked (key, session, sealing) and decoded by
  :func:`decode_frame` into numpy arrays that view the payload without a
  copy; a malformed payload raises ``ValueError``.
- :func:`route` picks the replica that holds a session from its id.
- :mod:`meshless.scene` builds scenes from dicts and TOML files;
  :mod:`meshless.design` builds constraints and design problems.

The protocol's messages and stubs, ``meshless.v1``, are generated from
``proto/meshless/v1/*.proto`` when the package is built
(``pip install ./client/python``).
"""

from .aio import AsyncClient, AsyncStream
from .client import Client, Stream, state_name, state_value
from .design import Design, Problem
from .errors import MeshlessError
from .frames import (
    Body,
    Frame,
    SolidRange,
    SolidSurface,
    Surface,
    decode_frame,
    frames_key,
    latest_key,
    status_key,
)
from .route import route, server_of
from .scene import load_scene, scene_toml
from .seal import Seal
from .subscriber import AsyncFrames, Frames

__version__ = "0.1.0"

__all__ = [
    "AsyncClient",
    "AsyncFrames",
    "AsyncStream",
    "Body",
    "Client",
    "Design",
    "Frame",
    "Frames",
    "MeshlessError",
    "Problem",
    "Seal",
    "SolidRange",
    "SolidSurface",
    "Stream",
    "Surface",
    "decode_frame",
    "frames_key",
    "latest_key",
    "load_scene",
    "route",
    "scene_toml",
    "server_of",
    "state_name",
    "state_value",
    "status_key",
]
