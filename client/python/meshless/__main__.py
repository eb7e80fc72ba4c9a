"""``python -m meshless``: a small command line over :class:`meshless.Client`.

    python -m meshless info
    python -m meshless run scenes/dam_break_2d.toml --steps 20
    python -m meshless snapshot SESSION -o session.snapshot
    python -m meshless restore session.snapshot --steps 5

The server is ``--address`` (default: ``$MESHLESS_SERVER``, as the Rust
``meshless`` command reads it, else 127.0.0.1:50051); ``--token``
defaults to ``$MESHLESS_TOKEN``.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import grpc

from .client import Client, state_name
from .connection import DEFAULT_TARGET
from .errors import MeshlessError


def _address(value: str) -> tuple[str, bool]:
    """``host:port`` and whether TLS is implied, from an address or a URL
    (``http://`` or ``https://``)."""
    for scheme, tls in (("http://", False), ("https://", True)):
        if value.startswith(scheme):
            return value[len(scheme) :].rstrip("/"), tls
    return value, False


def _client(args: argparse.Namespace) -> Client:
    target, tls = _address(args.address)
    return Client(
        target,
        timeout=args.timeout,
        token=args.token,
        client_id=args.client_id,
        take_over=args.take_over,
        tls=tls or args.tls,
        tls_ca=args.tls_ca,
        tls_cert=args.tls_cert,
        tls_key=args.tls_key,
        tls_domain=args.tls_domain,
    )


def _status(status: Any) -> str:
    line = f"{state_name(status.state)} at step {status.step}, t = {status.time:.4f} s"
    return f"{line} ({status.reason})" if status.reason else line


def _simulate(client: Client, session_id: str, steps: int, interval: float | None) -> None:
    def report(progress: Any) -> None:
        rate = f", {progress.realtime_factor:.3g}x real time" if progress.realtime_factor else ""
        print(
            f"  {progress.steps_done}/{progress.steps_total} steps: {_status(progress.status)}{rate}",
            flush=True,
        )

    last = client.simulate(session_id, steps, on_progress=report, progress_interval=interval)
    if state_name(last.status.state) == "faulted":
        raise MeshlessError(grpc.StatusCode.ABORTED, f"the session faulted: {last.status.reason}")


def cmd_info(client: Client, _args: argparse.Namespace) -> None:
    info = client.server_info()
    print(f"meshless-server {info.version}")
    print(f"  zenoh            {', '.join(info.zenoh_locators)}")
    print(f"  max particles    {info.max_particles_per_session} per session")
    print(f"  max sessions     {info.max_sessions}")
    print(f"  max snapshot     {info.max_snapshot_bytes} bytes")
    print(f"  sealed frames    {'yes' if info.zenoh_sealed else 'no'}")


def cmd_list(client: Client, _args: argparse.Namespace) -> None:
    for s in client.list_sessions():
        print(f"{s.id} {s.name!r} {s.particle_count} particles, {_status(s.status)}")


def cmd_run(client: Client, args: argparse.Namespace) -> None:
    session = client.create_session(Path(args.scene), observers=args.observer)
    print(f"{session.id} {session.name!r}, {session.particle_count} particles")
    _simulate(client, session.id, args.steps, args.progress_interval)
    if args.delete:
        client.delete_session(session.id)


def cmd_step(client: Client, args: argparse.Namespace) -> None:
    _simulate(client, args.session, args.steps, args.progress_interval)


def cmd_status(client: Client, args: argparse.Namespace) -> None:
    print(_status(client.get_session(args.session).status))


def cmd_snapshot(client: Client, args: argparse.Namespace) -> None:
    snapshot = client.snapshot(args.session)
    Path(args.output).write_bytes(snapshot.data)
    print(
        f"{args.output}: {len(snapshot.data)} bytes, session {snapshot.session_id} "
        f"at step {snapshot.step}, t = {snapshot.time:.4f} s"
    )


def cmd_restore(client: Client, args: argparse.Namespace) -> None:
    data = Path(args.snapshot).read_bytes()
    session = client.restore(data, session=args.session, observers=args.observer or None)
    print(f"{session.id} {session.name!r}, {_status(session.status)}")
    if args.steps:
        _simulate(client, session.id, args.steps, args.progress_interval)


def cmd_delete(client: Client, args: argparse.Namespace) -> None:
    client.delete_session(args.session)
    print(f"{args.session} deleted")


def parser() -> argparse.ArgumentParser:
    """The command line's parser."""
    server = os.environ.get("MESHLESS_SERVER", DEFAULT_TARGET)
    p = argparse.ArgumentParser(
        prog="python -m meshless",
        description="Drive a meshless server over gRPC (the Python client's command line).",
    )
    p.add_argument("--address", default=server, help=f"host:port or URL of the server (default {server})")
    p.add_argument(
        "--token", default=os.environ.get("MESHLESS_TOKEN"), help="bearer token (default $MESHLESS_TOKEN)"
    )
    p.add_argument("--client-id", help="this client instance's name (meshless-client metadata)")
    p.add_argument("--take-over", action="store_true", help="take control from another instance")
    p.add_argument("--timeout", type=float, default=30.0, help="seconds to connect and per call (default 30)")
    p.add_argument("--tls", action="store_true", help="speak TLS, trusting the system's CAs")
    p.add_argument("--tls-ca", type=Path, help="PEM file of the CA that signed the server's certificate")
    p.add_argument("--tls-cert", type=Path, help="PEM file of this client's certificate")
    p.add_argument("--tls-key", type=Path, help="PEM file of this client's key")
    p.add_argument("--tls-domain", help="the name the server's certificate must carry")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, run: Any, help: str) -> argparse.ArgumentParser:
        c = sub.add_parser(name, help=help, description=help)
        c.set_defaults(run=run)
        return c

    def stepping(c: argparse.ArgumentParser, default: int | None) -> None:
        c.add_argument("--steps", type=int, default=default, required=default is None, help="steps to take")
        c.add_argument("--progress-interval", type=float, help="seconds between progress lines (default 0.5)")

    command("info", cmd_info, "the server's version, limits and zenoh endpoints")
    command("list", cmd_list, "the sessions this caller may see")
    c = command("run", cmd_run, "create a session from a TOML scene file and step it, with progress")
    c.add_argument("scene", help="a TOML scene file (its meshes are sent inline)")
    stepping(c, None)
    c.add_argument("--observer", action="append", default=[], help="a principal that may watch it")
    c.add_argument("--delete", action="store_true", help="delete the session at the end")
    c = command("step", cmd_step, "step an existing session, with progress")
    c.add_argument("session")
    stepping(c, None)
    c = command("status", cmd_status, "a session's state, step and time")
    c.add_argument("session")
    c = command("snapshot", cmd_snapshot, "save a session's state to a file")
    c.add_argument("session")
    c.add_argument("-o", "--output", required=True, help="the snapshot file to write")
    c = command("restore", cmd_restore, "restore a snapshot file into a new or existing session")
    c.add_argument("snapshot", help="a file `snapshot` wrote")
    c.add_argument("--session", help="restore into this session (same scene) instead of a new one")
    c.add_argument(
        "--observer", action="append", default=[], help="a principal that may watch the new session"
    )
    stepping(c, 0)
    c = command("delete", cmd_delete, "delete a session")
    c.add_argument("session")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Runs the command line; the exit status."""
    args = parser().parse_args(argv)
    try:
        with _client(args) as client:
            args.run(client, args)
    except MeshlessError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
