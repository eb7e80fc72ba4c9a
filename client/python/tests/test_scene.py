"""Scenes as dicts and problem files, without a server: every shipped
scene reads into a dict whose TOML text reads back as the same dict, and
design problems become the protocol's messages."""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest

from conftest import ROOT
from meshless import Problem, load_scene, scene_toml
from meshless.design import constraint, optimize_request
from meshless.scene import merged

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

SCENES = sorted((ROOT / "scenes").glob("*.toml")) + sorted((ROOT / "tests" / "fixtures").glob("*.toml"))


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.name)
def test_every_shipped_scene_round_trips_through_toml(path):
    scene = load_scene(path)
    assert tomllib.loads(scene_toml(scene)) == scene


def test_values_toml_holds_and_values_it_does_not():
    scene = {
        "name": 'quote " backslash \\ tab \t newline \n del \x7f é',
        "numbers": (1, 2.5, -0.0, 1e-300, float("inf"), np.float32(0.25), np.int64(3)),
        "array": np.arange(3),
        "empty": {},
        "with space": {"nested": [{"a": 1}, {"b": {"c": [True, False]}}]},
        "inline": [[1, 2], [{"x": 1}]],
    }
    back = tomllib.loads(scene_toml(scene))
    assert back["name"] == scene["name"]
    assert back["numbers"][:4] == [1, 2.5, -0.0, 1e-300] and math.isinf(back["numbers"][4])
    assert back["numbers"][5:] == [0.25, 3] and back["array"] == [0, 1, 2]
    assert back["empty"] == {} and back["with space"] == scene["with space"]
    assert back["inline"] == [[1, 2], [{"x": 1}]]
    with pytest.raises(TypeError, match="bytes"):
        scene_toml({"systems": [{"data": b"raw"}]})
    with pytest.raises(TypeError, match="keys are strings"):
        scene_toml({1: 2})


def test_merged_changes_a_copy():
    scene = load_scene(ROOT / "scenes" / "dam_break.toml")
    changed = merged(scene, {"time": {"dt": 0.005}, "name": "finer"})
    assert changed["time"] == {**scene["time"], "dt": 0.005} and changed["name"] == "finer"
    assert scene["time"]["dt"] == 0.01
    changed["systems"][0]["spacing"] = 1.0
    assert scene["systems"][0]["spacing"] == 0.02


def test_problem_files_become_messages():
    from meshless.v1 import design_pb2 as d

    stretch = Problem.load(ROOT / "scenes" / "design_stretch.toml")
    assert stretch.scene["systems"][0]["kind"] == "solid"
    request = stretch.request("s")
    assert request.WhichOneof("problem") == "shape"
    assert request.design.particles == 128
    assert request.design.quadrature == d.DESIGN_QUADRATURE_CELLS
    assert request.design.weights.volume == 300.0
    edits = stretch.edits()
    assert edits[0].WhichOneof("edit") == "clear"
    top = edits[2].add
    assert top.name == "top" and top.handle.target.transform.translation.z == 1.0
    assert top.handle.points.region.max.z == 3.0

    motion = Problem.load(ROOT / "scenes" / "design_motion.toml")
    assert motion.scene["name"], "the scene file beside it was read"
    request = motion.request("s", playback=True)
    assert request.playback and request.motion.playback_rate == 30.0
    assert request.motion.settings.max_frames == 16
    post = constraint(motion.constraints[-1])
    assert post.obstacle.shape.box.half_extents.z == 0.4
    assert post.obstacle.path[0].position.x == 0.5


def test_constraint_dicts_name_what_does_not_fit():
    with pytest.raises(ValueError, match=r"c\.type: 'handel'"):
        constraint({"name": "c", "type": "handel"})
    with pytest.raises(ValueError, match=r"c\.handle\.target\.move: DesignTarget has no field 'move'"):
        constraint({"name": "c", "type": "handle", "target": {"move": [1, 2, 3]}})
    with pytest.raises(ValueError, match="3 components"):
        constraint({"name": "c", "type": "velocity", "velocity": [1, 2]})
    with pytest.raises(ValueError, match="'particles', 'cells'"):
        optimize_request("s", design={"quadrature": "corners"})
    points = constraint(
        {
            "name": "p",
            "type": "handle",
            "points": {"points": [[0, 0, 1]]},
            "target": {"positions": [[0, 0, 2]]},
        }
    )
    assert points.handle.points.points.points[0].z == 1.0
    assert points.handle.target.positions.positions[0].z == 2.0
    empty = constraint({"name": "e", "type": "handle", "target": {"transform": {}}})
    assert empty.handle.target.WhichOneof("kind") == "transform"
