#!/usr/bin/env python3
"""Side views of meshless PLY frames, coloured by speed or a field, as one PNG.

    meshless run scenes/dam_break.toml --format ply -o out/ply
    python scripts/plot_frames.py out/ply --times 0 0.25 0.5 1.0 -o dam_break.png
    python scripts/plot_frames.py out/brittle --colour fragment -o brittle.png
    python scripts/plot_frames.py out/notched3d --surfaces -o notched3d.png

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


def frame_time(path: Path) -> float:
    """A PLY frame's time, from its header alone (the first kilobytes)."""
    with path.open("rb") as f:
        head = f.read(4096)
    return float(re.search(rb"time (\S+)", head).group(1))


def read_mesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) and triangles (m, 3) of a meshless OBJ or binary PLY surface."""
    if path.suffix == ".obj":
        vertices, triangles = [], []
        for line in path.read_text().splitlines():
            if line.startswith("v "):
                vertices.append([float(c) for c in line.split()[1:4]])
            elif line.startswith("f "):
                triangles.append([int(c.split("/")[0]) - 1 for c in line.split()[1:4]])
        return np.array(vertices).reshape(-1, 3), np.array(triangles, dtype=np.int64).reshape(-1, 3)
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii")
    count = int(re.search(r"element vertex (\d+)", header).group(1))
    faces = int(re.search(r"element face (\d+)", header).group(1))
    width = len(re.findall(r"property float \w+", header))
    vertices = np.frombuffer(data, dtype="<f4", count=count * width, offset=end).reshape(count, width)[:, :3]
    record = np.dtype([("n", "u1"), ("v", "<u4", 3)])
    triangles = np.frombuffer(data, dtype=record, count=faces, offset=end + 4 * count * width)["v"]
    return vertices.astype(float), triangles.astype(np.int64)


def pieces(triangles: np.ndarray, vertices: int) -> np.ndarray:
    """Each triangle's connected piece (triangles sharing a vertex are one piece),
    numbered by size, the largest 0."""
    root = np.arange(vertices)

    def find(v: int) -> int:
        while root[v] != v:
            root[v] = root[root[v]]
            v = root[v]
        return v

    for a, b, c in triangles:
        ra, rb, rc = find(a), find(b), find(c)
        root[rb] = ra
        root[rc] = ra
    labels = np.unique(np.array([find(t[0]) for t in triangles]), return_inverse=True)[1]
    rank = np.argsort(np.argsort(-np.bincount(labels), kind="stable"))
    return rank[labels]


def plot_surfaces(args: argparse.Namespace, picked: list[tuple[float, Path]]) -> None:
    """One perspective panel per picked frame: its solid surfaces, each piece its own colour."""
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    meshes = []
    for time, frame in picked:
        step = frame.stem.split("_")[-1]
        files = sorted(p for p in args.folder.glob(f"solid*_{step}.*") if p.suffix in (".obj", ".ply"))
        if not files:
            raise SystemExit(f"no solid*_{step}.obj or .ply beside {frame.name}: run a 3D scene whose solid has a surface")
        meshes.append((time, [read_mesh(p) for p in files]))
    every = np.concatenate([v for _, ms in meshes for v, _ in ms])
    lo, hi = every.min(axis=0), every.max(axis=0)
    light = np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8])
    palette = plt.get_cmap("tab10")
    fig = plt.figure(figsize=(4 * len(meshes), 4))
    for k, (time, ms) in enumerate(meshes):
        ax = fig.add_subplot(1, len(meshes), k + 1, projection="3d")
        count = 0
        for vertices, triangles in ms:
            label = pieces(triangles, len(vertices))
            count += int(label.max()) + 1 if len(label) else 0
            corners = vertices[triangles]
            normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
            normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-30)
            shade = 0.35 + 0.65 * np.abs(normal @ light)
            # The nine largest pieces in their own colours, smaller debris grey.
            base = np.array([palette(i)[:3] if i < 9 else (0.5, 0.5, 0.5) for i in label]).reshape(-1, 3)
            ax.add_collection3d(Poly3DCollection(corners, facecolors=base * shade[:, None], linewidths=0))
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(np.maximum(hi - lo, 1e-3 * (hi - lo).max()))
        ax.view_init(elev=25, azim=-60)
        ax.set_title(f"t = {time:.3f} s, {count} piece{'s' if count != 1 else ''}")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zticks([])
    fig.savefig(args.output, dpi=120, bbox_inches="tight")
    print(f"wrote {args.output}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--times", type=float, nargs="+", default=[0.0, 0.25, 0.5, 1.0])
    parser.add_argument("-o", "--output", type=Path, default=Path("frames.png"))
    parser.add_argument(
        "--colour", default="speed", help="speed (from the velocity field) or any field the frames carry, e.g. fragment"
    )
    parser.add_argument(
        "--surfaces",
        action="store_true",
        help="draw the solids' surfaces (solid*_STEP.obj or .ply, 3D scenes) in perspective instead of the particles",
    )
    args = parser.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if args.surfaces:
        stamped = sorted((frame_time(p), p) for p in args.folder.glob("frame_*.ply"))
        if not stamped:
            raise SystemExit(f"no frame_*.ply in {args.folder}")
        plot_surfaces(args, [min(stamped, key=lambda f: abs(f[0] - t)) for t in args.times])
        return
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
