"""Frames: the protocol's packed little-endian fields as numpy arrays.

Every array of a decoded :class:`Frame` (fields, surfaces) is a read-only
view into the payload bytes (``np.frombuffer`` at the field's offset):
decoding copies no particle data. The protobuf parser reads the header and
the small messages; a scan of the wire format finds where each packed
field lies in the payload.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

KEY_ROOT = "meshless/v1/sessions"


def frames_key(session_id: str) -> str:
    """Zenoh key on which a session's frames are put."""
    return f"{KEY_ROOT}/{session_id}/frames"


def status_key(session_id: str) -> str:
    """Zenoh key on which a session's status changes are put."""
    return f"{KEY_ROOT}/{session_id}/status"


def latest_key(session_id: str) -> str:
    """Zenoh queryable answering with a session's latest frame."""
    return f"{KEY_ROOT}/{session_id}/latest"


@dataclass
class Surface:
    """A fluid surface mesh: ``(v, 3)`` float32 vertices and ``(t, 3)``
    uint32 triangles, counter-clockwise seen from outside the fluid."""

    vertices: np.ndarray
    triangles: np.ndarray


@dataclass
class SolidSurface:
    """A solid's embedded surface as deformed in a frame: ``system`` is the
    solid's index in the scene's systems; ``(v, 3)`` float32 vertices and
    unit normals, ``(t, 3)`` uint32 triangles, counter-clockwise seen from
    outside the solid."""

    system: int
    vertices: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray


@dataclass
class Body:
    """A rigid body's pose: ``system`` is its index in the scene's
    systems; ``orientation`` the unit quaternion ``(x, y, z, w)`` turning
    the body frame into the world frame; float64 arrays."""

    system: int
    position: np.ndarray
    orientation: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray


@dataclass
class SolidRange:
    """Where an elastic solid's particles sit in a frame's fields: ``count``
    rows from ``first`` (after the fluid's); ``system`` is the solid's index
    in the scene's systems."""

    system: int
    first: int
    count: int

    @property
    def rows(self) -> slice:
        """The solid's rows of any field: ``frame.fields["position"][r.rows]``."""
        return slice(self.first, self.first + self.count)


@dataclass
class Frame:
    """A decoded frame: header values, one ``(n, components)`` float32
    array per field, the surface when the scene asks for one, rigid bodies'
    poses, the rows of each elastic solid, the surfaces solids embed and
    the crack faces of fracturing solids (each crack's two faces, carried
    by the material on either side).

    ``ids``: each particle's stable id within its system, ``(n,)`` uint32
    row for row with the fields, when the scene's ``output.fields`` names
    ``id`` (a particle keeps its id while others leave or join, so
    ``np.nonzero(frame.ids[frame.solids[0].rows] == 7)`` finds solid 0's
    particle 7 in any frame).

    The arrays are read-only views into the payload (no copy); ``header``
    is the ``meshless.v1.FrameHeader`` message, with the last step's
    sub-step size, solver iterations, density error and flags.
    """

    session_id: str
    step: int
    time: float
    particle_count: int
    substeps: int
    fields: dict[str, np.ndarray] = field(default_factory=dict)
    ids: np.ndarray | None = None
    surface: Surface | None = None
    bodies: list[Body] = field(default_factory=list)
    solids: list[SolidRange] = field(default_factory=list)
    solid_surfaces: list[SolidSurface] = field(default_factory=list)
    crack_surfaces: list[SolidSurface] = field(default_factory=list)
    header: Any = None

    @property
    def positions(self) -> np.ndarray:
        """The ``(n, 3)`` positions (every frame carries them)."""
        return self.fields["position"]


# Field numbers of the packed bytes in frame.proto.
_FRAME_FIELDS = 2  # Frame.fields: FieldData
_FRAME_SURFACE = 4  # Frame.surface: SurfaceMesh
_FRAME_SOLID_SURFACES = 6  # Frame.solid_surfaces: SolidSurface
_FRAME_CRACK_SURFACES = 7  # Frame.crack_surfaces: SolidSurface
_FIELD_DATA = 4  # FieldData.data
_SOLID_SURFACE_MESH = 2  # SolidSurface.mesh: SurfaceMesh
_MESH_VERTICES, _MESH_TRIANGLES, _MESH_NORMALS = 1, 2, 3  # SurfaceMesh
_LENGTH_DELIMITED = 2

Span = tuple[int, int]


def _varint(buf: bytes, pos: int, end: int) -> tuple[int, int]:
    """A base-128 varint at ``pos``: its value and the position after it."""
    value = shift = 0
    while True:
        if pos >= end:
            raise ValueError("truncated varint")
        byte = buf[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        if not byte & 0x80:
            return value, pos
        shift += 7
        if shift >= 70:
            raise ValueError("varint longer than 10 bytes")


def _scan(buf: bytes, span: Span) -> list[tuple[int, Span]]:
    """The length-delimited fields of the message encoded in
    ``buf[span]``: each one's number and the span of its bytes, in order.
    Other fields are skipped; groups (no proto3 message has one) are
    refused."""
    pos, end = span
    found = []
    while pos < end:
        key, pos = _varint(buf, pos, end)
        number, wire_type = key >> 3, key & 7
        if wire_type == 0:
            _, pos = _varint(buf, pos, end)
        elif wire_type == 1:
            pos += 8
        elif wire_type == 5:
            pos += 4
        elif wire_type == _LENGTH_DELIMITED:
            length, pos = _varint(buf, pos, end)
            if pos + length <= end:
                found.append((number, (pos, pos + length)))
            pos += length
        else:
            raise ValueError(f"field {number}: wire type {wire_type} (a group) is not supported")
        if pos > end:
            raise ValueError(f"field {number} runs past the end of its message")
    return found


def _all(fields: list[tuple[int, Span]], number: int) -> list[Span]:
    return [span for n, span in fields if n == number]


def _merged(buf: bytes, occurrences: list[Span], number: int) -> Span:
    """The span of bytes field ``number`` of a singular message that occurs
    at ``occurrences``: protobuf merges the occurrences, so the last value
    wins; empty when it never occurs."""
    last: Span = (0, 0)
    for occurrence in occurrences:
        for span in _all(_scan(buf, occurrence), number):
            last = span
    return last


def _view(buf: bytes, span: Span, dtype: str, width: int) -> np.ndarray:
    """The bytes at ``span`` as a read-only ``(-1, width)`` array, without
    a copy; the caller has checked that the length is whole rows."""
    start, end = span
    rows = (end - start) // (np.dtype(dtype).itemsize * width)
    # np.frombuffer, shaped at once: the array's base is the payload itself.
    return np.ndarray((rows, width), dtype=dtype, buffer=buf, offset=start)


def _surface(buf: bytes, mesh: list[Span], what: str, normals: bool) -> tuple[np.ndarray, ...]:
    """Vertices, triangles (and normals) of a ``SurfaceMesh`` at the
    occurrences ``mesh``; ``ValueError`` when a byte count is not whole
    vertices or triangles or an index is out of range."""
    vertices = _merged(buf, mesh, _MESH_VERTICES)
    triangles = _merged(buf, mesh, _MESH_TRIANGLES)
    nv, nt = vertices[1] - vertices[0], triangles[1] - triangles[0]
    if nv % 12 or nt % 12:
        raise ValueError(
            f"{what}: {nv} vertex bytes and {nt} triangle bytes, both must be multiples of 12"
        )
    v = _view(buf, vertices, "<f4", 3)
    t = _view(buf, triangles, "<u4", 3)
    if t.size and int(t.max()) >= len(v):
        raise ValueError(f"{what}: index {int(t.max())} but {len(v)} vertices")
    if not normals:
        return v, t
    span = _merged(buf, mesh, _MESH_NORMALS)
    if span[1] - span[0] != 12 * len(v):
        raise ValueError(
            f"{what}: {span[1] - span[0]} normal bytes for {len(v)} vertices, expected 12 per vertex"
        )
    return v, t, _view(buf, span, "<f4", 3)


def decode_body(pose: Any) -> Body:
    """Unpacks a ``meshless.v1.BodyPose``."""

    def vec3(v: Any) -> np.ndarray:
        return np.array([v.x, v.y, v.z], dtype=np.float64)

    q = pose.orientation
    return Body(
        system=pose.system,
        position=vec3(pose.position),
        orientation=np.array([q.x, q.y, q.z, q.w], dtype=np.float64),
        velocity=vec3(pose.velocity),
        angular_velocity=vec3(pose.angular_velocity),
    )


def parse_frame(data: bytes) -> Any:
    """The ``meshless.v1.Frame`` message of encoded bytes, not yet checked;
    ``ValueError`` when they are no such message (protobuf's
    ``DecodeError``, wrapped)."""
    from google.protobuf.message import DecodeError

    from .v1 import frame_pb2

    try:
        return frame_pb2.Frame.FromString(data)
    except DecodeError as e:
        raise ValueError(f"not a Frame message ({len(data)} bytes): {e}") from e


def unpack_frame(message: Any, payload: bytes | None = None) -> Frame:
    """Checks and unpacks a parsed ``meshless.v1.Frame`` (see
    :func:`decode_frame` for the checks). ``payload``: the bytes it was
    parsed from, which the arrays then view; without it the message is
    encoded again first (a copy)."""
    from .v1 import frame_pb2, scene_pb2

    if payload is None:
        payload = message.SerializeToString()
    # Protobuf skips fields it does not know and reads a missing message as
    # empty, so bytes that are no frame can parse as one without a header.
    if not message.HasField("header"):
        raise ValueError("frame without a header")
    header = message.header
    if not header.session_id:
        raise ValueError("frame header names no session")
    n = header.particle_count
    try:
        top = _scan(payload, (0, len(payload)))
    except ValueError as e:
        raise ValueError(f"frame: {e}") from e
    field_spans = _all(top, _FRAME_FIELDS)
    solid_spans = _all(top, _FRAME_SOLID_SURFACES)
    crack_spans = _all(top, _FRAME_CRACK_SURFACES)
    if (
        len(field_spans) != len(message.fields)
        or len(solid_spans) != len(message.solid_surfaces)
        or len(crack_spans) != len(message.crack_surfaces)
    ):
        raise ValueError("frame: the wire scan and the parsed message disagree")
    fields = {}
    ids = None
    for f, span in zip(message.fields, field_spans):
        try:
            name = scene_pb2.FieldKind.Name(f.kind).removeprefix("FIELD_KIND_").lower()
        except ValueError as e:
            raise ValueError(f"unknown field kind {f.kind}") from e
        is_id = f.kind == scene_pb2.FIELD_KIND_ID
        scalar, dtype = (
            (frame_pb2.SCALAR_TYPE_U32, "<u4") if is_id else (frame_pb2.SCALAR_TYPE_F32, "<f4")
        )
        if f.scalar != scalar:
            raise ValueError(f"field {name}: scalar type {f.scalar}, expected {dtype}")
        data = _merged(payload, [span], _FIELD_DATA)
        size = data[1] - data[0]
        if f.components == 0 or size != 4 * f.components * n:
            raise ValueError(f"field {name}: {size} bytes, expected {4 * f.components * n}")
        if name in fields or (is_id and ids is not None):
            raise ValueError(f"field {name} twice in one frame")
        if is_id:
            ids = np.ndarray((n,), dtype=dtype, buffer=payload, offset=data[0])
        else:
            fields[name] = _view(payload, data, dtype, f.components)
    solids = [SolidRange(system=r.system, first=r.first, count=r.count) for r in message.solids]
    for r in solids:
        if r.first + r.count > n:
            raise ValueError(
                f"solid of system {r.system}: rows {r.first}..{r.first + r.count}, but {n} particles"
            )
    surface = None
    if message.HasField("surface"):
        vertices, triangles = _surface(payload, _all(top, _FRAME_SURFACE), "surface", False)
        surface = Surface(vertices=vertices, triangles=triangles)
    def solid_meshes(messages, spans, kind):
        out = []
        for s, span in zip(messages, spans):
            what = f"solid {s.system} {kind}"
            if not s.HasField("mesh"):
                raise ValueError(f"{what}: no mesh")
            mesh = _all(_scan(payload, span), _SOLID_SURFACE_MESH)
            vertices, triangles, normals = _surface(payload, mesh, what, True)
            out.append(SolidSurface(system=s.system, vertices=vertices, normals=normals, triangles=triangles))
        return out

    solid_surfaces = solid_meshes(message.solid_surfaces, solid_spans, "surface")
    crack_surfaces = solid_meshes(message.crack_surfaces, crack_spans, "crack faces")
    return Frame(
        session_id=header.session_id,
        step=header.step,
        time=header.time,
        particle_count=n,
        substeps=header.substeps,
        fields=fields,
        ids=ids,
        surface=surface,
        bodies=[decode_body(pose) for pose in message.bodies],
        solids=solids,
        solid_surfaces=solid_surfaces,
        crack_surfaces=crack_surfaces,
        header=header,
    )


def decode_frame(data: bytes) -> Frame:
    """Decodes an encoded ``meshless.v1.Frame``; its arrays view ``data``.

    Raises ``ValueError`` for every malformed payload: bytes that are no
    ``Frame`` message, a frame without a header or whose header names no
    session, an unknown field kind, a field whose size does not match the
    particle count or whose scalar type is not f32 (u32 for ids), a field
    given twice, a solid's rows past
    the last particle, or an inconsistent surface.
    """
    data = bytes(data) if not isinstance(data, bytes) else data
    return unpack_frame(parse_frame(data), data)
