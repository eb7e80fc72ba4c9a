"""Scenes as Python dicts: read from TOML files, written back as the TOML
text that ``CreateSessionRequest.scene_toml`` carries.

A scene dict has the layout of ``scenes/*.toml`` (``docs/scenes.md``):
``{"name": ..., "domain": {"min": [...], "max": [...]}, "systems": [{"kind":
"fluid", ...}]}``. The server validates it: a bad scene is refused with
``INVALID_ARGUMENT`` naming the field (``MeshlessError``), so this module
checks only that the values are ones TOML can hold.
"""

from __future__ import annotations

import base64
import copy
import math
import numbers
import os
import re
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

# Largest mesh file carried inline: a server refuses larger ones anyway
# (its --max-mesh-mb, 16 MB by default).
MAX_MESH_BYTES = 256 << 20

_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def load_scene(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The scene of a TOML file as a dict, with the mesh files its shapes
    name (``shape = { type = "mesh", path = ... }``, relative to the file)
    carried inline as ``data = { format, base64 }``: a server reads none
    of the client's files. ``ValueError`` names a mesh that is no
    ``.obj`` or ``.ply`` file."""
    path = Path(path)
    with path.open("rb") as f:
        scene = tomllib.load(f)
    inline_meshes(scene, path.parent)
    return scene


def inline_meshes(scene: dict[str, Any], base: str | os.PathLike[str]) -> dict[str, Any]:
    """Puts the bytes of every mesh file a system's shape names (relative
    to ``base``) into the shape, in place; returns ``scene``. A shape that
    already has ``data`` is left as it is."""
    for s, system in enumerate(scene.get("systems", [])):
        shape = system.get("shape") if isinstance(system, dict) else None
        if not isinstance(shape, dict) or shape.get("type") != "mesh" or "data" in shape:
            continue
        name = shape.get("path")
        if not isinstance(name, str):
            continue
        file = Path(base) / name
        fmt = file.suffix.lower().lstrip(".")
        if fmt not in ("obj", "ply"):
            raise ValueError(f"systems[{s}].shape.path {name!r}: give an .obj or .ply file")
        if file.stat().st_size > MAX_MESH_BYTES:
            raise ValueError(f"systems[{s}].shape.path: {file} is over {MAX_MESH_BYTES} bytes")
        shape["data"] = {"format": fmt, "base64": base64.b64encode(file.read_bytes()).decode()}
    return scene


def scene_toml(scene: Mapping[str, Any]) -> str:
    """The TOML text of a scene dict (any dict of TOML values: strings,
    booleans, integers, floats, lists and dicts; tuples and numpy values
    too). ``TypeError`` names a value TOML cannot hold."""
    lines: list[str] = []
    _table(lines, [], scene)
    return "\n".join(lines).lstrip("\n") + "\n"


def scene_text(scene: str | os.PathLike[str] | Mapping[str, Any]) -> str:
    """What ``CreateSessionRequest.scene_toml`` carries for a scene given
    as TOML text (a ``str``), a file (a path object, read with
    :func:`load_scene`) or a dict (:func:`scene_toml`)."""
    if isinstance(scene, str):
        return scene
    if isinstance(scene, os.PathLike):
        return scene_toml(load_scene(scene))
    if isinstance(scene, Mapping):
        return scene_toml(scene)
    raise TypeError(
        f"a scene is TOML text, a path or a dict, not {type(scene).__name__}"
    )


def merged(scene: Mapping[str, Any], changes: Mapping[str, Any]) -> dict[str, Any]:
    """A deep copy of ``scene`` with ``changes`` merged in: dicts merge key
    by key, anything else replaces. Lists replace too: change one system
    with ``scene["systems"][0].update(...)`` on the copy."""
    out = copy.deepcopy(dict(scene))
    for key, value in changes.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = merged(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def _key(key: str) -> str:
    if not isinstance(key, str):
        raise TypeError(f"TOML keys are strings, not {key!r}")
    return key if _BARE_KEY.fullmatch(key) else _string(key)


def _string(text: str) -> str:
    out = ['"']
    for c in text:
        if c == '"':
            out.append('\\"')
        elif c == "\\":
            out.append("\\\\")
        elif c == "\n":
            out.append("\\n")
        elif c == "\t":
            out.append("\\t")
        elif c == "\r":
            out.append("\\r")
        elif ord(c) < 0x20 or ord(c) == 0x7F:
            out.append(f"\\u{ord(c):04x}")
        else:
            out.append(c)
    out.append('"')
    return "".join(out)


def _plain(value: Any) -> Any:
    """numpy arrays and scalars, tuples: as lists and Python numbers."""
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    return value


def _is_table_array(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, Mapping) for v in value)


def _inline(value: Any, where: str) -> str:
    value = _plain(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        x = float(value)
        if math.isnan(x):
            return "nan"
        if math.isinf(x):
            return "inf" if x > 0 else "-inf"
        return repr(x)
    if isinstance(value, str):
        return _string(value)
    if isinstance(value, Mapping):
        items = ", ".join(f"{_key(k)} = {_inline(v, f'{where}.{k}')}" for k, v in value.items())
        return "{ " + items + " }" if items else "{}"
    if isinstance(value, Sequence) and not isinstance(value, (bytes, bytearray)):
        return "[" + ", ".join(_inline(v, f"{where}[{i}]") for i, v in enumerate(value)) + "]"
    raise TypeError(f"{where}: TOML holds no {type(value).__name__} ({value!r})")


def _table(lines: list[str], path: list[str], table: Mapping[str, Any]) -> None:
    """Appends ``table``'s key/value lines, then its sub-tables and arrays
    of tables under their headers."""
    nested = []
    for key, value in table.items():
        value = _plain(value)
        if isinstance(value, Mapping) or _is_table_array(value):
            nested.append((key, value))
        else:
            where = ".".join([*path, str(key)])
            lines.append(f"{_key(key)} = {_inline(value, where)}")
    for key, value in nested:
        sub = [*path, _key(key)]
        if isinstance(value, Mapping):
            lines.extend(["", f"[{'.'.join(sub)}]"])
            _table(lines, sub, value)
        else:
            for element in value:
                lines.extend(["", f"[[{'.'.join(sub)}]]"])
                _table(lines, sub, element)
