"""The topology the multi-host suite runs on: the compose harness's
containers when ``MESHLESS_HARNESS=compose`` (deploy/compose.yaml sets it),
local processes otherwise (scripts/test)."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import pytest

from topology import NAMES, ROOT, ComposeTopology, LocalTopology, Topology, connect


def _binary(variable: str, name: str) -> str:
    path = os.environ.get(variable) or shutil.which(name) or str(ROOT / "target" / "debug" / name)
    if not Path(path).exists():
        raise FileNotFoundError(
            f"{path} is missing: run `cargo build --workspace --bins` or set {variable}"
        )
    return path


@pytest.fixture(scope="session")
def cli() -> str:
    """The ``meshless`` command line: the Rust client."""
    return _binary("MESHLESS_CLI_BIN", "meshless")


@pytest.fixture(scope="session")
def topology():
    if os.environ.get("MESHLESS_HARNESS") == "compose":
        top: Topology = ComposeTopology(NAMES)
        yield top
        top.close()
        return
    with tempfile.TemporaryDirectory(prefix="meshless-harness-") as workdir:
        top = LocalTopology.launch(
            Path(workdir), _binary("MESHLESS_SERVER_BIN", "meshless-server"), NAMES
        )
        try:
            yield top
        finally:
            top.close()


@pytest.fixture()
def clients(topology):
    """A client of each server, by name, each server emptied of sessions
    first so that every test starts from the same state."""
    opened = {name: connect(topology, name) for name in NAMES}
    for client in opened.values():
        for session in client.list_sessions():
            client.delete_session(session)
    yield opened
    for client in opened.values():
        client.close()
