#!/usr/bin/env python3
"""Drag a design handle: shape design over a running server.

The column of ``scenes/design_stretch.toml`` (1 x 1 x 2 m, an elastic
solid) has its bottom held by one handle and its top lifted by 1 m by
another. The optimiser finds the shape; then the top handle is dragged
sideways by ``--drag`` metres (the constraint replaced) and the shape
optimised again, warm-started from the first. Each result is published as
a frame (``playback``) whose solid surface is the deformed one; the last
is written as a Wavefront OBJ.

    python client/python/examples/design_drag.py --address 127.0.0.1:50051 -o column.obj

``--problem`` reads another problem file (``scenes/design_*.toml``) of a
shape problem with a handle named ``top``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from meshless import Client, Design, Frames, Problem
from meshless.frames import SolidSurface

# scenes/design_stretch.toml, as a dict.
COLUMN = {
    "name": "design column",
    "dimension": 3,
    "gravity": [0.0, 0.0, 0.0],
    "domain": {"min": [-2.0, -2.0, -1.0], "max": [2.0, 2.0, 4.0]},
    "time": {"dt": 0.002},
    "systems": [
        {
            "kind": "solid",
            "shape": {"type": "box", "half_extents": [0.5, 0.5, 1.0]},
            "position": [0.0, 0.0, 1.0],
            "spacing": 0.1,
            "density": 1000.0,
            "young": 1.0e5,
            "poisson": 0.3,
        }
    ],
}


def handle(name: str, zmin: float, zmax: float, translation: list[float]) -> dict:
    """A handle on the design particles between two heights, moved by
    ``translation`` (the TOML form of ``[[constraints]]``)."""
    return {
        "name": name,
        "type": "handle",
        "points": {"region": {"min": [-1.0, -1.0, zmin], "max": [1.0, 1.0, zmax]}},
        "target": {"transform": {"translation": translation}},
    }


def default_problem(particles: int) -> Problem:
    return Problem(
        scene=COLUMN,
        system=0,
        problem="shape",
        design={"particles": particles, "quadrature": "cells", "weights": {"volume": 300.0}},
        constraints=[
            handle("bottom", -1.0, 0.2, [0.0, 0.0, 0.0]),
            handle("top", 1.8, 3.0, [0.0, 0.0, 1.0]),
        ],
    )


def solve(client: Client, frames: Frames, problem: Problem, session_id: str) -> tuple[Design, SolidSurface]:
    """Optimises with playback; the design and the deformed surface the
    playback frame carries."""
    iterations: list[object] = []
    design = client.optimize(
        problem.request(session_id, playback=True), on_progress=iterations.append
    )
    frame = frames.next()
    surface = next(s for s in frame.solid_surfaces if s.system == problem.system)
    info = design.info
    print(
        f"  {info.iterations} iterations, converged {info.converged}, "
        f"handle energy {info.energies.handle:.3e}, {len(iterations)} progress reports"
    )
    return design, surface


def write_obj(path: Path, surface: SolidSurface) -> None:
    """The surface as a Wavefront OBJ: vertices, normals, triangles."""
    with path.open("w") as f:
        f.write("# meshless design_drag.py: the designed column's surface\n")
        np.savetxt(f, surface.vertices, fmt="v %.7g %.7g %.7g")
        np.savetxt(f, surface.normals, fmt="vn %.7g %.7g %.7g")
        faces = surface.triangles.astype(np.int64) + 1
        np.savetxt(f, np.repeat(faces, 2, axis=1), fmt="f %d//%d %d//%d %d//%d")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--address", default="127.0.0.1:50051", help="the server's host:port")
    p.add_argument("--token", help="bearer token, for a server with tokens")
    p.add_argument("--problem", type=Path, help="a shape problem file with a handle named `top`")
    p.add_argument("--particles", type=int, default=128, help="design particles (default 128)")
    p.add_argument("--drag", type=float, default=0.5, help="how far the top handle is dragged along x, m")
    p.add_argument("-o", "--out", type=Path, default=Path("design_drag.obj"), help="the OBJ to write")
    args = p.parse_args()

    problem = Problem.load(args.problem) if args.problem else default_problem(args.particles)
    with Client(args.address, token=args.token) as client:
        session = client.create_session(problem.scene)
        try:
            client.edit_constraints(session, problem.edits())
            with client.frames(session) as frames:
                print("lift:")
                solve(client, frames, problem, session.id)
                top = next(c for c in problem.constraints if c["name"] == "top")
                moved = top["target"]["transform"].get("translation", [0.0, 0.0, 0.0])
                dragged = dict(top, target={"transform": {"translation": [moved[0] + args.drag, *moved[1:]]}})
                client.edit_constraints(session, replace=[dragged])
                problem.constraints = [dragged if c is top else c for c in problem.constraints]
                print(f"drag {args.drag} m along x:")
                design, surface = solve(client, frames, problem, session.id)
        finally:
            client.delete_session(session)
    write_obj(args.out, surface)
    top_particles = design.rest_positions[:, 2] > design.rest_positions[:, 2].max() - 1e-9
    shift = design.displacements[0][top_particles].mean(axis=0)
    print(f"top particles moved by {np.round(shift, 3).tolist()} m")
    print(f"wrote {args.out}: {len(surface.vertices)} vertices, {len(surface.triangles)} triangles")


if __name__ == "__main__":
    main()
