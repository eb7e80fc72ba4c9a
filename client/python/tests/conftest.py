"""Starts the real meshless-server binary on free loopback ports."""

from __future__ import annotations

import contextlib
import os
import queue
import subprocess
import threading
from dataclasses import dataclass
from pathlib import Path

import pytest

TIMEOUT = 30.0

ROOT = Path(__file__).resolve().parents[3]
PACKAGE = ROOT / "client" / "python"
EXAMPLES = PACKAGE / "examples"


def fixture(name: str) -> str:
    """A scene shared with the Rust tests: ``tests/fixtures/NAME.toml``."""
    return (ROOT / "tests" / "fixtures" / f"{name}.toml").read_text()


@dataclass
class Server:
    grpc_target: str
    zenoh_endpoints: list[str]
    # The browser viewer's address, when started with --http-addr.
    http: str | None = None


def _server_binary() -> str:
    path = os.environ.get("MESHLESS_SERVER_BIN")
    if path:
        return path
    return str(ROOT / "target" / "debug" / "meshless-server")


@contextlib.contextmanager
def running_server(*extra_args: str):
    """The real server with ``extra_args``, stopped (SIGTERM) on exit."""
    binary = _server_binary()
    if not Path(binary).exists():
        raise FileNotFoundError(
            f"{binary} is missing: run `cargo build -p meshless-server` or set MESHLESS_SERVER_BIN"
        )
    process = subprocess.Popen(
        [binary, "--grpc-addr", "127.0.0.1:0", "--zenoh-listen", "tcp/127.0.0.1:0", *extra_args],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "MESHLESS_LOG": "warn"},
    )
    lines: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        assert process.stdout is not None
        for line in process.stdout:
            lines.put(line)

    threading.Thread(target=pump, daemon=True).start()
    try:
        while True:
            line = lines.get(timeout=TIMEOUT)
            if line.startswith("meshless-server ready "):
                break
        parts = dict(p.split("=", 1) for p in line.split()[2:])
        yield Server(
            grpc_target=parts["grpc"],
            zenoh_endpoints=parts["zenoh"].split(","),
            http=parts.get("http"),
        )
    finally:
        process.terminate()
        assert process.wait(timeout=TIMEOUT) == 0, "the server exits cleanly on SIGTERM"


@pytest.fixture()
def server():
    with running_server() as running:
        yield running


@pytest.fixture()
def open_server():
    """A server that lets any zenoh peer publish on its session keys (no
    access control), so that the subscribers' own checks meet forgeries."""
    with running_server("--zenoh-publishers", "any") as running:
        yield running


@pytest.fixture(scope="module")
def shared_server():
    """One server for a module's tests (each makes its own sessions), so
    that they do not each pay for a server's start."""
    with running_server() as running:
        yield running
