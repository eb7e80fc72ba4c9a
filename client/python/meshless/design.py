"""Shape and motion design: constraints and settings from Python dicts
in the TOML form of ``scenes/design_*.toml`` (``docs/optimiser.md``),
problem files, and the solved :class:`Design` as numpy arrays."""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .scene import inline_meshes, load_scene

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


@dataclass
class Design:
    """A solved design: the design particles' rest positions and their
    displacements per frame, as numpy arrays (lengths checked)."""

    session_id: str
    system: int
    kind: str
    info: Any
    rest_positions: np.ndarray
    times: np.ndarray
    displacements: np.ndarray

    @classmethod
    def from_proto(cls, result: Any) -> "Design":
        """The design of a ``meshless.v1.DesignResult``; ``ValueError``
        when its lengths disagree."""
        from .v1 import design_pb2

        rest = np.asarray(result.rest_positions, dtype=np.float64)
        times = np.asarray(result.times, dtype=np.float64)
        values = np.asarray(result.displacements, dtype=np.float64)
        if rest.size % 3 or times.size == 0 or values.size != rest.size * times.size:
            raise ValueError(
                f"malformed design: {rest.size} rest coordinates, {times.size} times, "
                f"{values.size} displacement values"
            )
        n = rest.size // 3
        kind = design_pb2.DesignKind.Name(result.kind).removeprefix("DESIGN_KIND_").lower()
        return cls(
            session_id=result.session_id,
            system=result.system,
            kind=kind,
            info=result.info,
            rest_positions=rest.reshape(n, 3),
            times=times,
            displacements=values.reshape(times.size, n, 3),
        )

    def positions(self, frame: int) -> np.ndarray:
        """The design particles' positions at ``frame``."""
        return self.rest_positions + self.displacements[frame]


def to_message(message: Any, value: Any, where: str = "") -> Any:
    """Fills a protobuf ``message`` from ``value`` in the TOML form, in
    place, and returns it. The rules, which the engine's serde format and
    ``proto/meshless/v1/*.proto`` share:

    - a dict sets fields by name; a ``type`` key picks the member of the
      message's oneof that the other keys fill (``{type = "handle",
      points, target}`` on a ``Constraint``, ``{type = "box",
      half_extents}`` on a ``Shape``), keys naming the message's own
      fields staying on it (``name``);
    - ``[x, y, z]`` fills a ``Vec3``; a list fills a message of one
      repeated field (``points = [[...]]``, ``positions = [[...]]``);
    - a string fills an enum by its short name (``"cells"`` is
      ``DESIGN_QUADRATURE_CELLS``).

    ``ValueError`` names the key (``where``) that fits nowhere.
    """
    descriptor = message.DESCRIPTOR
    # Present even when nothing in it is set: `{transform = {}}` picks the
    # transform of its oneof.
    message.SetInParent()
    if descriptor.full_name == "meshless.v1.Vec3" and isinstance(value, Sequence):
        if len(value) != 3:
            raise ValueError(f"{where}: a vector has 3 components, not {len(value)}")
        message.x, message.y, message.z = (float(v) for v in value)
        return message
    if isinstance(value, Sequence) and not isinstance(value, str):
        if len(descriptor.fields) == 1 and descriptor.fields[0].is_repeated:
            return to_message(message, {descriptor.fields[0].name: value}, where)
        raise ValueError(f"{where}: a list does not fill a {descriptor.name}")
    if not isinstance(value, Mapping):
        raise ValueError(f"{where}: a {type(value).__name__} does not fill a {descriptor.name}")
    value = dict(value)
    kind = value.pop("type", None)
    if kind is not None:
        member = descriptor.fields_by_name.get(kind)
        if member is None or member.containing_oneof is None or member.message_type is None:
            raise ValueError(f"{where}.type: {kind!r} is no kind of {descriptor.name}")
        oneof = member.containing_oneof
        own = {
            k: value.pop(k)
            for k in list(value)
            if k in descriptor.fields_by_name
            and getattr(descriptor.fields_by_name[k].containing_oneof, "name", None) != oneof.name
        }
        to_message(getattr(message, kind), value, f"{where}.{kind}" if where else kind)
        value = own
    for key, item in value.items():
        path = f"{where}.{key}" if where else key
        f = descriptor.fields_by_name.get(key)
        if f is None:
            raise ValueError(f"{path}: {descriptor.name} has no field {key!r}")
        if f.is_repeated:
            if not isinstance(item, Sequence) or isinstance(item, str):
                raise ValueError(f"{path}: expected a list")
            target = getattr(message, key)
            for i, element in enumerate(item):
                if f.message_type is not None:
                    to_message(target.add(), element, f"{path}[{i}]")
                else:
                    target.append(_scalar(f, element, f"{path}[{i}]"))
        elif f.message_type is not None:
            to_message(getattr(message, key), item, path)
        else:
            setattr(message, key, _scalar(f, item, path))
    return message


def _scalar(f: Any, value: Any, where: str) -> Any:
    if f.enum_type is None:
        return value
    if isinstance(value, int):
        return value
    names = [v.name for v in f.enum_type.values]
    prefix = names[0].removesuffix("UNSPECIFIED") if names[0].endswith("UNSPECIFIED") else ""
    name = prefix + str(value).upper()
    if name not in names:
        choices = ", ".join(repr(n.removeprefix(prefix).lower()) for n in names[1:])
        raise ValueError(f"{where}: {value!r} is none of {choices}")
    return f.enum_type.values_by_name[name].number


def constraint(value: Mapping[str, Any]) -> Any:
    """A ``meshless.v1.Constraint`` from its TOML form, e.g.
    ``{"name": "top", "type": "handle", "points": {"region": {"min": [...],
    "max": [...]}}, "target": {"transform": {"translation": [0, 0, 1]}}}``."""
    from .v1 import design_pb2

    return to_message(design_pb2.Constraint(), value, str(value.get("name", "constraint")))


def design_settings(value: Mapping[str, Any]) -> Any:
    """``meshless.v1.DesignSettings`` from a problem's ``[design]`` table."""
    from .v1 import design_pb2

    return to_message(design_pb2.DesignSettings(), value, "design")


def motion_settings(value: Mapping[str, Any]) -> Any:
    """``meshless.v1.MotionSettings`` from a problem's ``[motion]`` table."""
    from .v1 import design_pb2

    return to_message(design_pb2.MotionSettings(), value, "motion")


@dataclass
class Problem:
    """A design problem file (``scenes/design_*.toml``): the scene (a dict,
    meshes inline), the solid (``system``), the problem (``"shape"`` or
    ``"motion"``), its settings and constraints (TOML dicts)."""

    scene: dict[str, Any]
    system: int = 0
    problem: str = "shape"
    design: dict[str, Any] = field(default_factory=dict)
    motion: dict[str, Any] = field(default_factory=dict)
    playback_rate: float | None = None
    constraints: list[dict[str, Any]] = field(default_factory=list)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> "Problem":
        """Reads a problem file; its ``scene`` is a file relative to it or
        an inline ``[scene]`` table."""
        path = Path(path)
        with path.open("rb") as f:
            table = tomllib.load(f)
        known = {"scene", "system", "problem", "design", "motion", "playback_rate", "constraints"}
        unknown = sorted(set(table) - known)
        if unknown:
            raise ValueError(f"{path}: unknown keys {unknown}")
        scene = table.get("scene")
        if isinstance(scene, str):
            scene = load_scene(path.parent / scene)
        elif isinstance(scene, dict):
            scene = inline_meshes(scene, path.parent)
        else:
            raise ValueError(f"{path}: `scene` is a file name or a [scene] table")
        return cls(
            scene=scene,
            system=int(table.get("system", 0)),
            problem=str(table.get("problem", "shape")),
            design=dict(table.get("design", {})),
            motion=dict(table.get("motion", {})),
            playback_rate=table.get("playback_rate"),
            constraints=list(table.get("constraints", [])),
        )

    def edits(self) -> list[Any]:
        """The constraint edits that give a session exactly this problem's
        constraints: clear, then add each."""
        from .v1 import design_pb2

        edits = [design_pb2.ConstraintEdit(clear=design_pb2.ClearConstraints())]
        edits += [design_pb2.ConstraintEdit(add=constraint(c)) for c in self.constraints]
        return edits

    def request(self, session_id: str, playback: bool = False) -> Any:
        """The ``OptimizeRequest`` of this problem in session ``session_id``."""
        return optimize_request(
            session_id,
            system=self.system,
            problem=self.problem,
            design=self.design,
            motion=self.motion,
            playback_rate=self.playback_rate,
            playback=playback,
        )


def optimize_request(
    session_id: str,
    *,
    system: int = 0,
    problem: str = "shape",
    design: Mapping[str, Any] | Any | None = None,
    motion: Mapping[str, Any] | Any | None = None,
    playback_rate: float | None = None,
    playback: bool = False,
) -> Any:
    """An ``OptimizeRequest``: ``problem`` is ``"shape"`` or ``"motion"``;
    ``design`` and ``motion`` are settings as dicts (TOML form) or
    messages."""
    from .v1 import design_pb2 as d

    request = d.OptimizeRequest(session_id=session_id, system=system, playback=playback)
    if design is not None:
        request.design.CopyFrom(
            design if isinstance(design, d.DesignSettings) else design_settings(design)
        )
    if problem == "shape":
        request.shape.SetInParent()
    elif problem == "motion":
        request.motion.SetInParent()
        if motion is not None:
            request.motion.settings.CopyFrom(
                motion if isinstance(motion, d.MotionSettings) else motion_settings(motion)
            )
        if playback_rate is not None:
            request.motion.playback_rate = playback_rate
    else:
        raise ValueError(f"problem {problem!r}: \"shape\" or \"motion\"")
    return request
