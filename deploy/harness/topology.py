"""The hosts the multi-host suite runs against, and what it may do to them.

Two topologies run the same tests (``test_replicas.py``):

- :class:`ComposeTopology`, inside the ``harness`` container of
  ``deploy/compose.yaml``: a real ``zenohd`` and two ``meshless-server``
  containers with their own addresses, driven through the Docker engine's
  API (the socket is mounted into the harness). A partition disconnects a
  server's container from the zenoh network.
- :class:`LocalTopology`, everywhere else: the same servers as local
  processes, a zenoh router as a local process, and between each server and
  the router a TCP relay that a partition cuts (the server's link drops
  and no new one connects), so the server sees what a cut network shows.

Both speak gRPC over TLS with tokens to the servers, and zenoh over TLS
to the router only: the suite knows the servers' gRPC targets and the
router's endpoint, nothing else.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Protocol

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]

#: How long any one wait of the suite may take.
TIMEOUT = 60.0

#: The replicas' server names, as compose.yaml names them.
NAMES = ["meshless-1", "meshless-2"]


def eventually(what: str, check: Callable[[], bool], timeout: float = TIMEOUT) -> None:
    """Polls ``check`` until it holds, failing with ``what`` after
    ``timeout``: for state that no stream announces (a process's exit, a
    port's opening, a metric)."""
    ends = time.monotonic() + timeout
    while not check():
        if time.monotonic() > ends:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.05)


@dataclass
class Server:
    """A replica as the suite reaches it."""

    #: Its ``--server-name``, which its session ids start with.
    name: str
    #: ``host:port`` of its gRPC endpoint (TLS).
    target: str
    #: ``http://host:port/metrics``.
    metrics_url: str
    #: ``(host, port)`` of its browser viewer (HTTPS, ``--http-addr``).
    viewer: tuple[str, int]


@dataclass
class Credentials:
    """What a client of the servers needs: the CA that signed their
    certificates, the name the certificates carry when the target's host
    is not it, and a token."""

    ca: Path
    token: str
    domain: str | None = None


def write_zenoh_ca_config(path: Path, ca: Path) -> Path:
    """Writes, to ``path``, a zenoh configuration that trusts ``ca`` for
    ``tls/`` endpoints (what deploy/config/zenoh-client.json5 gives the
    servers), and returns ``path``."""
    path.write_text(json.dumps({"transport": {"link": {"tls": {"root_ca_certificate": str(ca)}}}}))
    return path


class Topology(Protocol):
    #: The replicas by server name.
    servers: dict[str, Server]
    #: The router's zenoh endpoint (``tls/``), the only one the suite's
    #: subscribers know.
    router: str
    #: The zenoh configuration file subscribers connect with (the CA).
    zenoh_config: Path
    credentials: Credentials
    #: A ``meshless --route`` template that reaches every replica by name,
    #: or ``None`` where names do not resolve (local processes).
    route_template: str | None

    def stop(self, name: str) -> None: ...
    def start(self, name: str) -> None: ...
    def kill(self, name: str) -> None: ...
    def restart_router(self) -> None: ...
    def partition(self, name: str) -> None: ...
    def heal(self, name: str) -> None: ...
    def close(self) -> None: ...


def connect(topology: Topology, name: str):
    """A Python client of replica ``name``, with the topology's TLS CA and
    token."""
    import meshless

    c = topology.credentials
    target = topology.servers[name].target
    return meshless.Client(target, token=c.token, tls_ca=c.ca, tls_domain=c.domain, timeout=30.0)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def port_open(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=0.5):
            return True
    except OSError:
        return False


class Relay:
    """A TCP relay from a local port to ``target``; :meth:`cut` closes every
    connection through it and refuses new ones until :meth:`mend`."""

    def __init__(self, target: tuple[str, int]):
        self.target = target
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port = self._listener.getsockname()[1]
        self._open = True
        self._lock = threading.Lock()
        self._sockets: set[socket.socket] = set()
        self._closed = False
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while not self._closed:
            try:
                incoming, _ = self._listener.accept()
            except OSError:
                return
            with self._lock:
                if not self._open:
                    incoming.close()
                    continue
            try:
                outgoing = socket.create_connection(self.target, timeout=5)
            except OSError:
                incoming.close()
                continue
            outgoing.settimeout(None)
            with self._lock:
                self._sockets.update((incoming, outgoing))
            for a, b in ((incoming, outgoing), (outgoing, incoming)):
                threading.Thread(target=self._pump, args=(a, b), daemon=True).start()

    def _pump(self, source: socket.socket, sink: socket.socket) -> None:
        try:
            while data := source.recv(65536):
                sink.sendall(data)
        except OSError:
            pass
        finally:
            for s in (source, sink):
                try:
                    s.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass

    def cut(self) -> None:
        with self._lock:
            self._open = False
            sockets, self._sockets = self._sockets, set()
        for s in sockets:
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            s.close()

    def mend(self) -> None:
        with self._lock:
            self._open = True

    def close(self) -> None:
        self._closed = True
        self.cut()
        self._listener.close()


@dataclass
class _Process:
    args: list[str]
    env: dict[str, str]
    process: subprocess.Popen | None = None

    def start(self) -> None:
        self.process = subprocess.Popen(
            self.args, env=self.env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )

    def signal(self, kill: bool) -> None:
        if self.process is None:
            return
        if kill:
            self.process.kill()
        else:
            self.process.terminate()
        self.process.wait(timeout=TIMEOUT)
        self.process = None


@dataclass
class LocalTopology:
    """Servers, router and relays as local processes and threads."""

    workdir: Path
    server_bin: str
    servers: dict[str, Server] = field(default_factory=dict)
    router: str = ""
    zenoh_config: Path = Path()
    credentials: Credentials | None = None  # type: ignore[assignment]
    route_template: str | None = None
    _processes: dict[str, _Process] = field(default_factory=dict)
    _relays: dict[str, Relay] = field(default_factory=dict)
    _router: _Process | None = None
    _router_port: int = 0

    @classmethod
    def launch(cls, workdir: Path, server_bin: str, names: list[str]) -> "LocalTopology":
        from certs import write_credentials

        top = cls(workdir=workdir, server_bin=server_bin)
        token = write_credentials(workdir, [])
        ca, cert, key = workdir / "ca.crt", workdir / "tls.crt", workdir / "tls.key"
        top.credentials = Credentials(ca=ca, token=token, domain="localhost")
        top.zenoh_config = write_zenoh_ca_config(workdir / "zenoh-client.json", ca)

        top._router_port = free_port()
        top.router = f"tls/127.0.0.1:{top._router_port}"
        top._router = _Process(
            [sys.executable, str(HERE / "router.py"), top.router, str(cert), str(key)],
            dict(os.environ),
        )
        top._start_router()
        for name in names:
            relay = Relay(("127.0.0.1", top._router_port))
            grpc, metrics, http = free_port(), free_port(), free_port()
            checkpoints = workdir / name
            checkpoints.mkdir()
            args = [
                server_bin,
                "--server-name", name,
                "--grpc-addr", f"127.0.0.1:{grpc}",
                "--metrics-addr", f"127.0.0.1:{metrics}",
                "--http-addr", f"127.0.0.1:{http}",
                "--zenoh-mode", "client",
                "--zenoh-connect", f"tls/127.0.0.1:{relay.port}",
                "--zenoh-config", str(top.zenoh_config),
                "--tokens-file", str(workdir / "tokens"),
                "--tls-cert", str(cert),
                "--tls-key", str(key),
                "--checkpoint-dir", str(checkpoints),
                "--checkpoint-interval", "0.5",
            ]
            top._processes[name] = _Process(args, {**os.environ, "MESHLESS_LOG": "warn"})
            top._relays[name] = relay
            top.servers[name] = Server(
                name,
                f"127.0.0.1:{grpc}",
                f"http://127.0.0.1:{metrics}/metrics",
                ("127.0.0.1", http),
            )
            top.start(name)
        return top

    def _start_router(self) -> None:
        assert self._router is not None
        self._router.start()
        eventually("the router to listen", lambda: port_open("127.0.0.1", self._router_port))

    def start(self, name: str) -> None:
        self._processes[name].start()
        host, port = self.servers[name].target.rsplit(":", 1)
        eventually(f"{name} to listen", lambda: port_open(host, int(port)))

    def stop(self, name: str) -> None:
        self._processes[name].signal(kill=False)

    def kill(self, name: str) -> None:
        self._processes[name].signal(kill=True)

    def restart_router(self) -> None:
        assert self._router is not None
        self._router.signal(kill=False)
        self._start_router()

    def partition(self, name: str) -> None:
        self._relays[name].cut()

    def heal(self, name: str) -> None:
        self._relays[name].mend()

    def close(self) -> None:
        for process in self._processes.values():
            process.signal(kill=False)
        if self._router is not None:
            self._router.signal(kill=False)
        for relay in self._relays.values():
            relay.close()


class ComposeTopology:
    """The containers of ``deploy/compose.yaml``, seen from its harness."""

    def __init__(self, names: list[str]):
        import docker

        self._docker = docker.from_env(timeout=int(TIMEOUT))
        me = self._docker.containers.get(socket.gethostname())
        self._project = me.labels["com.docker.compose.project"]
        certs = Path(os.environ.get("MESHLESS_HARNESS_CERTS", "/certs"))
        self.credentials = Credentials(
            ca=certs / "ca.crt", token=(certs / "harness.token").read_text().strip()
        )
        self.zenoh_config = write_zenoh_ca_config(Path("/tmp/zenoh-client.json"), certs / "ca.crt")
        self.servers = {
            name: Server(name, f"{name}:50051", f"http://{name}:9464/metrics", (name, 8080))
            for name in names
        }
        self.router = os.environ.get("MESHLESS_HARNESS_ROUTER", "tls/zenohd:7447")
        self.route_template = "https://{server}:50051"
        self._zenoh_network = self._docker.networks.get(f"{self._project}_zenoh")

    def _container(self, service: str):
        found = self._docker.containers.list(
            all=True,
            filters={
                "label": [
                    f"com.docker.compose.project={self._project}",
                    f"com.docker.compose.service={service}",
                ]
            },
        )
        if len(found) != 1:
            raise AssertionError(f"expected one container of service {service}, found {len(found)}")
        return found[0]

    def _wait_listening(self, name: str) -> None:
        eventually(f"{name} to listen", lambda: port_open(name, 50051))

    def start(self, name: str) -> None:
        self._container(name).start()
        self._wait_listening(name)

    def stop(self, name: str) -> None:
        self._container(name).stop(timeout=30)

    def kill(self, name: str) -> None:
        container = self._container(name)
        container.kill()
        container.wait(timeout=TIMEOUT)

    def restart_router(self) -> None:
        self._container("zenohd").restart(timeout=10)
        eventually("the router to listen", lambda: port_open("zenohd", 7447))

    def partition(self, name: str) -> None:
        self._zenoh_network.disconnect(self._container(name))

    def heal(self, name: str) -> None:
        self._zenoh_network.connect(self._container(name), aliases=[name])

    def close(self) -> None:
        self._docker.close()
