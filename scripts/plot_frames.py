#!/usr/bin/env python3
"""Side views of meshless PLY frames, coloured by speed, as one PNG.

    meshless run scenes/dam_break.toml --format ply -o out/ply
    python scripts/plot_frames.py out/ply --times 0 0.25 0.5 1.0 -o dam_break.png

Needs numpy and matplotlib (`pip install numpy matplotlib`).
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np


def read_ply(path: Path) -> tuple[float, dict[str, np.ndarray]]:
    """Time and per-vertex properties of a binary little-endian PLY frame."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii")
    time = float(re.search(r"time (\S+)", header).group(1))
    names = re.findall(r"property float (\w+)", header)
    values = np.frombuffer(data[end:], dtype="<f4").reshape(-1, len(names))
    return time, {name: values[:, i] for i, name in enumerate(names)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--times", type=float, nargs="+", default=[0.0, 0.25, 0.5, 1.0])
    parser.add_argument("-o", "--output", type=Path, default=Path("frames.png"))
    args = parser.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = sorted((read_ply(p) for p in args.folder.glob("frame_*.ply")), key=lambda f: f[0])
    if not frames:
        raise SystemExit(f"no frame_*.ply in {args.folder}")
    picked = [min(frames, key=lambda f: abs(f[0] - t)) for t in args.times]
    x_max = max(f["x"].max() for _, f in frames)
    y_max = max(f["y"].max() for _, f in frames)
    fig, axes = plt.subplots(1, len(picked), figsize=(4 * len(picked), 3), sharey=True)
    for ax, (time, f) in zip(np.atleast_1d(axes), picked):
        speed = np.sqrt(f["vx"] ** 2 + f["vy"] ** 2 + f["vz"] ** 2) if "vx" in f else None
        points = ax.scatter(f["x"], f["y"], c=speed, s=1, cmap="viridis", vmin=0, vmax=4)
        ax.set_title(f"t = {time:.2f} s")
        ax.set_xlim(0, x_max * 1.02)
        ax.set_ylim(0, y_max * 1.02)
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
    np.atleast_1d(axes)[0].set_ylabel("y [m]")
    if speed is not None:
        fig.colorbar(points, ax=axes, label="speed [m/s]", shrink=0.8)
    fig.savefig(args.output, dpi=120, bbox_inches="tight")
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
