"""The package as pip builds it: the protocol code generated from proto/
at build time (never checked in), the typing marker, the command line,
and a source distribution that builds outside the repository."""

from __future__ import annotations

import os
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import meshless
from conftest import PACKAGE, ROOT, TIMEOUT, running_server

PROTOS = sorted(p.stem for p in (ROOT / "proto" / "meshless" / "v1").glob("*.proto"))


def test_the_tests_import_the_installed_package_with_its_generated_code():
    installed = Path(meshless.__file__).resolve().parent
    assert PACKAGE not in installed.parents, (
        f"meshless imports from {installed}, the source tree: install it "
        "(pip install ./client/python), as scripts/test does"
    )
    assert (installed / "py.typed").is_file()
    for stem in PROTOS:
        for suffix in ("_pb2.py", "_pb2.pyi", "_pb2_grpc.py"):
            assert (installed / "v1" / f"{stem}{suffix}").is_file(), f"{stem}{suffix} was not generated"


def test_no_generated_code_is_checked_in():
    tracked = subprocess.run(
        ["git", "ls-files", "client/python/meshless/v1"],
        cwd=ROOT, capture_output=True, text=True, check=True,
    ).stdout.split()
    assert tracked == ["client/python/meshless/v1/__init__.py"], tracked


def test_a_source_distribution_builds_a_wheel_outside_the_repository(tmp_path):
    """The sdist carries the .proto files; pip builds a wheel from it in a
    folder of its own, where ../../proto does not exist."""
    dist = tmp_path / "dist"
    subprocess.run(
        [sys.executable, "-c", f"from setuptools import build_meta; build_meta.build_sdist({str(dist)!r})"],
        cwd=PACKAGE, check=True, capture_output=True, timeout=120,
    )
    (sdist,) = dist.glob("meshless-*.tar.gz")
    with tarfile.open(sdist) as tar:
        names = tar.getnames()
    assert {f"proto/meshless/v1/{stem}.proto" for stem in PROTOS} <= {n.partition("/")[2] for n in names}
    # Unpacked far from the repository, as an index's user gets it.
    with tarfile.open(sdist) as tar:
        tar.extractall(tmp_path / "unpacked", filter="data")
    (source,) = (tmp_path / "unpacked").iterdir()
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation",
         "--disable-pip-version-check", "-w", str(tmp_path / "wheels"), str(source)],
        cwd=tmp_path, check=True, capture_output=True, timeout=300,
    )
    (wheel,) = (tmp_path / "wheels").glob("meshless-*.whl")
    with zipfile.ZipFile(wheel) as z:
        files = set(z.namelist())
    assert "meshless/py.typed" in files
    assert {f"meshless/v1/{stem}_pb2.py" for stem in PROTOS} <= files
    assert "meshless/v1/simulation_pb2_grpc.py" in files


def run_cli(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "meshless", *args],
        capture_output=True, text=True, timeout=TIMEOUT * 4, env={**os.environ, **(env or {})},
    )


def test_python_m_meshless_help_lists_its_commands():
    done = run_cli("--help")
    assert done.returncode == 0, done.stderr
    for command in ("info", "run", "snapshot", "restore"):
        assert command in done.stdout


def test_the_command_line_drives_a_server(tmp_path):
    scene = ROOT / "tests" / "fixtures" / "python_tank.toml"
    with running_server() as server:
        # The Rust command's variable, a URL, works too.
        env = {"MESHLESS_SERVER": f"http://{server.grpc_target}"}
        info = run_cli("info", env=env)
        assert info.returncode == 0, info.stderr
        assert server.zenoh_endpoints[0] in info.stdout

        ran = run_cli("--address", server.grpc_target, "run", str(scene), "--steps", "3")
        assert ran.returncode == 0, ran.stderr
        session_id = ran.stdout.split()[0]
        assert "3/3 steps" in ran.stdout, ran.stdout

        blob = tmp_path / "tank.snapshot"
        saved = run_cli("--address", server.grpc_target, "snapshot", session_id, "-o", str(blob))
        assert saved.returncode == 0, saved.stderr
        assert blob.stat().st_size > 0
        restored = run_cli("--address", server.grpc_target, "restore", str(blob), "--steps", "2")
        assert restored.returncode == 0, restored.stderr
        assert "at step 3" in restored.stdout and "2/2 steps" in restored.stdout, restored.stdout

        bad = run_cli("--address", server.grpc_target, "status", "no-such-session")
        assert bad.returncode == 1
        assert "NOT_FOUND" in bad.stderr
