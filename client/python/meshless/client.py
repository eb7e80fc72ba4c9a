"""A small synchronous client: gRPC control and zenoh frames."""

from __future__ import annotations

import json
import queue
from pathlib import Path

import grpc
import zenoh

from .frames import Frame, decode_frame, frames_key, latest_key

DEFAULT_TIMEOUT = 30.0


class Client:
    """Drives a meshless server over gRPC.

    Errors surface as ``grpc.RpcError`` with the server's status code and a
    message that names what to change.
    """

    def __init__(self, target: str = "127.0.0.1:50051", timeout: float = DEFAULT_TIMEOUT):
        from .v1 import simulation_pb2 as pb
        from .v1 import simulation_pb2_grpc

        self._pb = pb
        self._timeout = timeout
        self._channel = grpc.insecure_channel(target)
        grpc.channel_ready_future(self._channel).result(timeout=timeout)
        self._stub = simulation_pb2_grpc.SimulationStub(self._channel)

    def close(self) -> None:
        self._channel.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *_exc) -> None:
        self.close()

    def server_info(self):
        return self._stub.GetServerInfo(self._pb.GetServerInfoRequest(), timeout=self._timeout)

    def create_session(self, scene: str | Path):
        """Creates a session from a TOML scene: a path or the text itself."""
        text = Path(scene).read_text() if isinstance(scene, Path) else scene
        request = self._pb.CreateSessionRequest(scene_toml=text)
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
