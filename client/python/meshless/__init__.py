"""Python client of meshless.

The gRPC messages and stubs of package ``meshless.v1`` are generated from
``proto/meshless/v1/*.proto`` into ``meshless/v1`` (``scripts/test`` does it
with ``grpc_tools.protoc -I proto``). Frames arrive over zenoh;
:func:`decode_frame` turns one into numpy arrays without per-particle
parsing.
"""

from .frames import Frame, decode_frame, frames_key, latest_key, status_key

__all__ = ["Frame", "decode_frame", "frames_key", "latest_key", "status_key"]
