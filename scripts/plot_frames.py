#!/usr/bin/env python3
"""Side views of meshless PLY frames, coloured by speed or a field, as one PNG.

    meshless run scenes/dam_break.toml --format ply -o out/ply
    python scripts/plot_frames.py out/ply --times 0 0.25 0.5 1.0 -o dam_break.png
    python scripts/plot_frames.py out/brittle --colour fragment -o brittle.png

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
    parser.add_argument(
        "--colour", default="speed", help="speed (from the velocity field) or any field the frames carry, e.g. fragment"
    )
    args = parser.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = sorted((read_ply(p) for p in args.folder.glob("frame_*.ply")), key=lambda f: f[0])
    if not frames:
        raise SystemExit(f"no frame_*.ply in {args.folder}")
    picked = [min(frames, key=lambda f: abs(f[0] - t)) for t in args.times]
    lo = [min(f[a].min() for _, f in frames) for a in ("x", "y")]
    hi = [max(f[a].max() for _, f in frames) for a in ("x", "y")]
    pad = [0.02 * (h - l) for l, h in zip(lo, hi)]

    def colour(f: dict[str, np.ndarray]) -> np.ndarray | None:
        if args.colour == "speed":
            return np.sqrt(f["vx"] ** 2 + f["vy"] ** 2 + f["vz"] ** 2) if "vx" in f else None
        if args.colour not in f:
            raise SystemExit(f"the frames carry no field {args.colour}; add it to [output] fields")
        return f[args.colour]

    values = [colour(f) for _, f in picked]
    if args.colour == "speed":
        vmin, vmax, cmap, label = 0, 4, "viridis", "speed [m/s]"
    else:
        known = [v for v in values if v is not None]
        vmin = min(float(np.nanmin(v)) for v in known)
        vmax = max(float(np.nanmax(v)) for v in known)
        cmap, label = ("tab10" if args.colour == "fragment" else "viridis"), args.colour
    fig, axes = plt.subplots(1, len(picked), figsize=(4 * len(picked), 3), sharey=True)
    for ax, (time, f), c in zip(np.atleast_1d(axes), picked, values):
        points = ax.scatter(f["x"], f["y"], c=c, s=1, cmap=cmap, vmin=vmin, vmax=vmax)
        ax.set_title(f"t = {time:.2f} s")
        ax.set_xlim(lo[0] - pad[0], hi[0] + pad[0])
        ax.set_ylim(lo[1] - pad[1], hi[1] + pad[1])
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
    np.atleast_1d(axes)[0].set_ylabel("y [m]")
    if values[-1] is not None:
        fig.colorbar(points, ax=axes, label=label, shrink=0.8)
    fig.savefig(args.output, dpi=120, bbox_inches="tight")
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
