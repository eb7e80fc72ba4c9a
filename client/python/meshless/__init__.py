"""Python client of meshless.

The gRPC messages and stubs of package ``meshless.v1`` are generated from
``proto/meshless/v1/*.proto`` into ``meshless/v1`` (``scripts/test`` does it
with ``grpc_tools.protoc -I proto``). Frames arrive over zenoh;
:func:`decode_frame` turns one into numpy arrays without per-particle
parsing, and raises ``ValueError`` for any malformed payload.
:class:`Client` drives a server over gRPC and :class:`Frames` subscribes
to a session's frames, dropping and counting samples that are malformed or
name another session, and opening sealed ones with the session's key
(:class:`Seal`).
"""

from .frames import Body, Frame, SolidRange, SolidSurface, Surface, decode_frame, frames_key, latest_key, status_key
from .seal import Seal


def __getattr__(name: str):
    # The client needs the generated modules; import it lazily so that
    # `decode_frame` works before they are generated.
    if name in ("Client", "Design", "Frames"):
        from . import client

        return getattr(client, name)
    raise AttributeError(name)


__all__ = ["Body", "Client", "Design", "Frame", "Frames", "Seal", "SolidRange", "SolidSurface", "Surface", "decode_frame", "frames_key", "latest_key", "status_key"]
