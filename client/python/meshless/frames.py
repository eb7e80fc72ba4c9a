"""Frames: the protocol's packed little-endian fields as numpy arrays."""

from __future__ import annotations

from dataclasses import dataclass, field

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
    """A decoded frame: header values, one ``(n, components)`` array per
    field, the surface when the scene asks for one, rigid bodies' poses,
    the rows of each elastic solid and the surfaces solids embed."""

    session_id: str
    step: int
    time: float
    particle_count: int
    substeps: int
    fields: dict[str, np.ndarray] = field(default_factory=dict)
    surface: Surface | None = None
    bodies: list[Body] = field(default_factory=list)
    solids: list[SolidRange] = field(default_factory=list)
    solid_surfaces: list[SolidSurface] = field(default_factory=list)


def decode_surface(message) -> Surface:
    """Unpacks a ``meshless.v1.SurfaceMesh``; ``ValueError`` when a byte
    count is not whole vertices or triangles or an index is out of range."""
    if len(message.vertices) % 12 or len(message.triangles) % 12:
        raise ValueError(
            f"surface: {len(message.vertices)} vertex bytes and {len(message.triangles)} "
            "triangle bytes, both must be multiples of 12"
        )
    vertices = np.frombuffer(message.vertices, dtype="<f4").reshape(-1, 3)
    triangles = np.frombuffer(message.triangles, dtype="<u4").reshape(-1, 3)
    if triangles.size and int(triangles.max()) >= len(vertices):
        raise ValueError(f"surface: index {int(triangles.max())} but {len(vertices)} vertices")
    return Surface(vertices=vertices, triangles=triangles)


def decode_solid_surface(message) -> SolidSurface:
    """Unpacks a ``meshless.v1.SolidSurface``; ``ValueError`` when its mesh
    is missing or inconsistent (as :func:`decode_surface`) or has not one
    normal per vertex."""
    if not message.HasField("mesh"):
        raise ValueError(f"solid {message.system} surface: no mesh")
    mesh = decode_surface(message.mesh)
    normals = message.mesh.normals
    if len(normals) != 12 * len(mesh.vertices):
        raise ValueError(
            f"solid {message.system} surface: {len(normals)} normal bytes for "
            f"{len(mesh.vertices)} vertices, expected 12 per vertex"
        )
    return SolidSurface(
        system=message.system,
        vertices=mesh.vertices,
        normals=np.frombuffer(normals, dtype="<f4").reshape(-1, 3),
        triangles=mesh.triangles,
    )


def decode_body(pose) -> Body:
    """Unpacks a ``meshless.v1.BodyPose``."""

    def vec3(v) -> np.ndarray:
        return np.array([v.x, v.y, v.z], dtype=np.float64)

    q = pose.orientation
    return Body(
        system=pose.system,
        position=vec3(pose.position),
        orientation=np.array([q.x, q.y, q.z, q.w], dtype=np.float64),
        velocity=vec3(pose.velocity),
        angular_velocity=vec3(pose.angular_velocity),
    )


def parse_frame(data: bytes):
    """The ``meshless.v1.Frame`` message of encoded bytes, not yet checked;
    ``ValueError`` when they are no such message (protobuf's
    ``DecodeError``, wrapped)."""
    from google.protobuf.message import DecodeError

    from .v1 import frame_pb2

    try:
        return frame_pb2.Frame.FromString(data)
    except DecodeError as e:
        raise ValueError(f"not a Frame message ({len(data)} bytes): {e}") from e


def unpack_frame(message) -> Frame:
    """Checks and unpacks a parsed ``meshless.v1.Frame`` (see
    :func:`decode_frame` for the checks)."""
    from .v1 import frame_pb2, scene_pb2

    # Protobuf skips fields it does not know and reads a missing message as
    # empty, so bytes that are no frame can parse as one without a header.
    if not message.HasField("header"):
        raise ValueError("frame without a header")
    header = message.header
    if not header.session_id:
        raise ValueError("frame header names no session")
    n = header.particle_count
    fields = {}
    for f in message.fields:
        name = scene_pb2.FieldKind.Name(f.kind).removeprefix("FIELD_KIND_").lower()
        if f.scalar != frame_pb2.SCALAR_TYPE_F32:
            raise ValueError(f"field {name}: scalar type {f.scalar}, expected f32")
        if len(f.data) != 4 * f.components * n:
            raise ValueError(
                f"field {name}: {len(f.data)} bytes, expected {4 * f.components * n}"
            )
        fields[name] = np.frombuffer(f.data, dtype="<f4").reshape(n, f.components)
    solids = [SolidRange(system=r.system, first=r.first, count=r.count) for r in message.solids]
    for r in solids:
        if r.first + r.count > n:
            raise ValueError(
                f"solid of system {r.system}: rows {r.first}..{r.first + r.count}, but {n} particles"
            )
    return Frame(
        session_id=header.session_id,
        step=header.step,
        time=header.time,
        particle_count=n,
        substeps=header.substeps,
        fields=fields,
        surface=decode_surface(message.surface) if message.HasField("surface") else None,
        bodies=[decode_body(pose) for pose in message.bodies],
        solids=solids,
        solid_surfaces=[decode_solid_surface(s) for s in message.solid_surfaces],
    )


def decode_frame(data: bytes) -> Frame:
    """Decodes an encoded ``meshless.v1.Frame``.

    Raises ``ValueError`` for every malformed payload: bytes that are no
    ``Frame`` message, a frame without a header or whose header names no
    session, an unknown field kind, a field whose size does not match the
    particle count or whose scalar type is not f32, a solid's rows past
    the last particle, or an inconsistent surface.
    """
    return unpack_frame(parse_frame(data))
