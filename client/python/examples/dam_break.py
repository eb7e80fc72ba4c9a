#!/usr/bin/env python3
"""The dam break against Martin & Moyce (1952), over a running server.

A water column of width a = 0.3 m and height 2a collapses in a 1.5 m
tank; the surge front Z = x_front / a is plotted against the time
T = t sqrt(2 g / a), with the measured points, as
``validation/src/dam_break.rs`` does: x_front is the 99.5th percentile of
x among the particles lower than a / 6, so a stray particle does not
define it. The scene is built here as a dict (the layout of
``scenes/dam_break_2d.toml``) at ``--size`` particles across the column
(the shipped scene has 15); the run goes to T = 3.4.

    python client/python/examples/dam_break.py --address 127.0.0.1:50051 -o dam_break.png

Needs matplotlib (``pip install matplotlib``); it draws off screen (Agg).
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

import numpy as np

from meshless import Client, Frame

A = 0.3  # the column's width, m
G = 9.81
T_END = 3.4  # in units of sqrt(a / (2 g)), as the Rust study runs it
DATA = Path(__file__).resolve().parent / "data" / "dam_break_martin_moyce_1952.csv"


def scene(size: int, dimension: int) -> dict:
    """The Martin & Moyce column at ``size`` particles across its width."""
    spacing = A / size
    depth = 0.0 if dimension == 2 else 0.3
    return {
        "name": f"dam break {dimension}d, {size} across",
        "dimension": dimension,
        "gravity": [0.0, -G, 0.0],
        "domain": {"min": [0.0, 0.0, 0.0], "max": [1.5, 0.8, depth]},
        "time": {"dt": 0.01, "cfl": 0.4, "max_substeps": 256},
        "output": {"fields": [], "frame_every": 1},
        "systems": [
            {
                "kind": "fluid",
                "spacing": spacing,
                "support_radius": 2.0 * spacing,
                "rest_density": 1000.0,
                "stiffness": 1.75e5,
                "gamma": 7.0,
                "xsph": 0.1,
                "density_kernel": "poly6",
                "gradient_kernel": "spiky",
                "walls": "solid",
                "blocks": [{"region": {"min": [0.0, 0.0, 0.0], "max": [A, 2.0 * A, depth]}}],
            }
        ],
    }


def surge_front(positions: np.ndarray) -> float | None:
    """Z = x_front / a: the 99.5th percentile of x among particles lower
    than a / 6 (``surge_front`` of validation/src/dam_break.rs)."""
    low = np.sort(positions[positions[:, 1] < A / 6.0, 0].astype(np.float64))
    if low.size == 0:
        return None
    return float(low[int(math.floor((low.size - 1) * 0.995 + 0.5))]) / A


def martin_moyce() -> np.ndarray:
    """The measured front, ``(T, Z)`` rows."""
    rows = []
    with DATA.open() as f:
        for row in csv.reader(line for line in f if not line.startswith("#")):
            if row and row[0] == "front":
                rows.append((float(row[1]), float(row[2])))
    return np.array(rows)


def front_error(curve: np.ndarray, measured: np.ndarray) -> tuple[float, float]:
    """Worst and rms relative error of ``curve`` against the measured
    points with 1 <= T <= 3 (``front_error`` of the Rust study)."""
    points = measured[(measured[:, 0] >= 1.0) & (measured[:, 0] <= 3.0)]
    simulated = np.interp(points[:, 0], curve[:, 0], curve[:, 1])
    errors = (simulated - points[:, 1]) / points[:, 1]
    return float(np.abs(errors).max()), float(np.sqrt(np.mean(errors**2)))


def run(client: Client, size: int, dimension: int) -> np.ndarray:
    """Runs the dam break to T_END, measuring the front in every frame;
    ``(T, Z)`` rows."""
    scale = math.sqrt(2.0 * G / A)
    session = client.create_session(scene(size, dimension))
    print(f"session {session.id}: {session.particle_count} particles")
    curve = []
    try:
        with client.frames(session) as frames:
            until = T_END / scale
            client.run(session, until=until)
            frame: Frame
            for frame in frames:
                z = surge_front(frame.positions)
                if z is not None:
                    curve.append((frame.time * scale, z))
                if frame.time >= until - 1e-9:
                    break
    finally:
        client.delete_session(session)
    return np.array(curve)


def plot(curve: np.ndarray, measured: np.ndarray, title: str, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4), dpi=120)
    ax.plot(curve[:, 0], curve[:, 1], "-", label="meshless")
    ax.plot(measured[:, 0], measured[:, 1], "o", mfc="none", label="Martin & Moyce (1952)")
    ax.set_xlabel(r"$T = t\,\sqrt{2g/a}$")
    ax.set_ylabel(r"$Z = x_\mathrm{front}/a$")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--address", default="127.0.0.1:50051", help="the server's host:port")
    p.add_argument("--token", help="bearer token, for a server with tokens")
    p.add_argument("--size", type=int, default=10, help="particles across the column (default 10)")
    p.add_argument("--dimension", type=int, choices=(2, 3), default=2)
    p.add_argument("-o", "--out", type=Path, default=Path("dam_break.png"), help="the PNG to write")
    p.add_argument("--csv", type=Path, help="also write the simulated front (T, Z) here")
    args = p.parse_args()

    with Client(args.address, token=args.token) as client:
        curve = run(client, args.size, args.dimension)
    measured = martin_moyce()
    worst, rms = front_error(curve, measured)
    print(f"{len(curve)} frames to T = {curve[-1, 0]:.2f}; front error for 1 <= T <= 3: "
          f"worst {100 * worst:.1f} %, rms {100 * rms:.1f} %")
    title = f"Dam break, {args.dimension}D, a / {args.size} spacing: rms error {100 * rms:.1f} %"
    plot(curve, measured, title, args.out)
    print(f"wrote {args.out}")
    if args.csv:
        with args.csv.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["T", "Z"])
            w.writerows(curve.tolist())
        print(f"wrote {args.csv}")


if __name__ == "__main__":
    main()
