"""The examples in client/python/examples, run as a user runs them against
a real server (matplotlib headless), their outputs checked."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from conftest import EXAMPLES, TIMEOUT

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def example(name: str, server, *args: str) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / name), "--address", server.grpc_target, *args],
        capture_output=True,
        text=True,
        timeout=TIMEOUT * 6,
        env={**os.environ, "MPLBACKEND": "Agg"},
    )
    assert done.returncode == 0, f"{name} failed:\n{done.stdout}\n{done.stderr}"
    return done


def test_dam_break_plots_the_surge_front_against_martin_moyce(shared_server, tmp_path):
    png, table = tmp_path / "dam_break.png", tmp_path / "front.csv"
    done = example("dam_break.py", shared_server, "--size", "8", "-o", str(png), "--csv", str(table))
    assert png.read_bytes()[:8] == PNG_SIGNATURE
    with table.open() as f:
        rows = [(float(t), float(z)) for t, z in list(csv.reader(f))[1:]]
    curve = np.array(rows)
    # To T = 3.4, a frame per 10 ms step; the front starts at the column's
    # edge (Z = 1) and runs out along the floor.
    assert curve[-1, 0] >= 3.39 and len(curve) >= 40, curve[-1]
    assert abs(curve[0, 1] - 1.0) < 0.15, curve[0]
    assert curve[-1, 1] > 3.0, curve[-1]
    # Within 15 % of the measurements for 1 <= T <= 3 even this coarse (8
    # particles across: 8.1 % measured; 15 across, the shipped scene's
    # spacing, 6.2 %).
    worst = float(done.stdout.split("worst ")[1].split(" %")[0])
    assert worst < 15.0, done.stdout


def read_obj(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    vertices, normals, faces = [], [], []
    for line in path.read_text().splitlines():
        word, *rest = line.split() or [""]
        if word == "v":
            vertices.append([float(x) for x in rest])
        elif word == "vn":
            normals.append([float(x) for x in rest])
        elif word == "f":
            faces.append([int(x.split("//")[0]) - 1 for x in rest])
    return np.array(vertices), np.array(normals), np.array(faces)


def test_design_drag_writes_the_dragged_surface(shared_server, tmp_path):
    obj = tmp_path / "column.obj"
    done = example("design_drag.py", shared_server, "--particles", "48", "--drag", "0.5", "-o", str(obj))
    vertices, normals, faces = read_obj(obj)
    assert len(vertices) > 0 and normals.shape == vertices.shape
    assert faces.shape[1] == 3 and faces.min() >= 0 and faces.max() < len(vertices)
    assert np.abs(np.linalg.norm(normals, axis=1) - 1.0).max() < 1e-3
    # The 1 x 1 x 2 m column standing on z = 0: its bottom stays, its top is
    # lifted by 1 m and dragged 0.5 m along x.
    bottom = vertices[vertices[:, 2] < 0.05]
    top = vertices[vertices[:, 2] > vertices[:, 2].max() - 0.05]
    assert abs(vertices[:, 2].min()) < 0.1 and abs(vertices[:, 2].max() - 3.0) < 0.1, done.stdout
    assert abs(bottom[:, 0].mean()) < 0.05, bottom[:, 0].mean()
    assert abs(top[:, 0].mean() - 0.5) < 0.1, top[:, 0].mean()
    assert "drag 0.5 m" in done.stdout


def test_snapshot_restore_agrees_bit_for_bit(shared_server, tmp_path):
    blob = tmp_path / "tank.snapshot"
    done = example("snapshot_restore.py", shared_server, "--steps", "5", "-o", str(blob))
    assert blob.stat().st_size > 0
    assert "equal bit for bit" in done.stdout, done.stdout
