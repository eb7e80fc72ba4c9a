#!/usr/bin/env python3
"""Snapshot a session and restore it: the copy computes what the original
computes, bit for bit.

A small block of water falls in a tank for ``--steps`` steps; its state is
saved (``Snapshot``, an opaque checksummed blob, written to ``--out``)
and restored into a new session (``Restore``); both then take ``--steps``
more steps, and their latest frames are compared byte for byte, field by
field. Exits with status 1 when they differ.

    python client/python/examples/snapshot_restore.py --address 127.0.0.1:50051 -o tank.snapshot
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from meshless import Client, Frame

TANK = {
    "name": "snapshot tank",
    "domain": {"min": [0.0, 0.0, 0.0], "max": [0.5, 0.5, 0.5]},
    "time": {"dt": 0.01},
    "output": {"fields": ["velocity", "density", "pressure"]},
    "systems": [
        {
            "kind": "fluid",
            "spacing": 0.05,
            "stiffness": 2.0e4,
            "blocks": [{"region": {"min": [0.0, 0.1, 0.0], "max": [0.2, 0.4, 0.2]}}],
        }
    ],
}


def differences(a: Frame, b: Frame) -> list[str]:
    """What differs between two frames, bit for bit; empty when nothing."""
    found = []
    if (a.step, a.time, a.particle_count) != (b.step, b.time, b.particle_count):
        found.append(f"clock: step {a.step} t {a.time!r} vs step {b.step} t {b.time!r}")
    if set(a.fields) != set(b.fields):
        found.append(f"fields: {sorted(a.fields)} vs {sorted(b.fields)}")
    for name in sorted(set(a.fields) & set(b.fields)):
        x, y = a.fields[name], b.fields[name]
        if x.shape != y.shape or x.tobytes() != y.tobytes():
            if x.shape != y.shape:
                found.append(f"{name}: shapes {x.shape} and {y.shape}")
            else:
                n = int(np.count_nonzero(x.view(np.uint32) != y.view(np.uint32)))
                found.append(f"{name}: {n} of {x.size} values differ")
    return found


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--address", default="127.0.0.1:50051", help="the server's host:port")
    p.add_argument("--token", help="bearer token, for a server with tokens")
    p.add_argument("--steps", type=int, default=10, help="steps before and after the snapshot")
    p.add_argument(
        "-o", "--out", type=Path, default=Path("snapshot_restore.snapshot"), help="where the blob goes"
    )
    args = p.parse_args()

    with Client(args.address, token=args.token) as client:
        original = client.create_session(TANK)
        client.step(original, args.steps)
        snapshot = client.snapshot(original)
        args.out.write_bytes(snapshot.data)
        print(f"snapshot of {original.id} at step {snapshot.step}: {len(snapshot.data)} bytes -> {args.out}")
        copy = client.restore(args.out.read_bytes())
        print(f"restored as {copy.id} at step {copy.status.step}")
        for session in (original, copy):
            client.step(session, args.steps)
        a, b = client.latest_frame(original), client.latest_frame(copy)
        for session in (original, copy):
            client.delete_session(session)
    diff = differences(a, b)
    if diff:
        print("the restored session differs:\n  " + "\n  ".join(diff))
        sys.exit(1)
    print(f"step {a.step}: {a.particle_count} particles, fields {sorted(a.fields)} equal bit for bit")


if __name__ == "__main__":
    main()
