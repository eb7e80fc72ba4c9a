"""The synchronous client over a real server: scenes from dicts and files
validated by the server, one exception type with the gRPC code, per-call
deadlines, the status stream, frames without copies (iterator, callback,
latest over gRPC and zenoh), long runs with progress, and snapshots."""

from __future__ import annotations

import threading
import time

import grpc
import numpy as np
import pytest

from conftest import ROOT, TIMEOUT, fixture
from meshless import Client, Frame, MeshlessError, decode_frame, load_scene, scene_toml, state_name

TANK = load_scene(ROOT / "tests" / "fixtures" / "python_tank.toml")


@pytest.fixture()
def client(shared_server):
    with Client(shared_server.grpc_target) as c:
        yield c


def code_of(call) -> grpc.StatusCode:
    with pytest.raises(MeshlessError) as refused:
        call()
    assert isinstance(refused.value.details, str) and refused.value.details
    return refused.value.code


def test_scenes_from_dicts_files_and_text_are_validated_by_the_server(client, tmp_path):
    from meshless.scene import merged

    from_dict = client.create_session(TANK)
    path = tmp_path / "tank.toml"
    path.write_text(scene_toml(TANK))
    from_file = client.create_session(path)
    from_text = client.create_session(fixture("python_tank"))
    assert from_dict.particle_count == from_file.particle_count == from_text.particle_count == 96
    assert from_dict.scene == from_file.scene == from_text.scene

    bad = merged(TANK, {})
    bad["systems"][0]["spacing"] = -0.05
    with pytest.raises(MeshlessError) as refused:
        client.create_session(bad)
    assert refused.value.code == grpc.StatusCode.INVALID_ARGUMENT
    assert "systems[0].spacing" in refused.value.details
    assert "INVALID_ARGUMENT" in str(refused.value)
    unknown = merged(TANK, {"time": {"dt": 0.01, "dtt": 1.0}})
    assert code_of(lambda: client.create_session(unknown)) == grpc.StatusCode.INVALID_ARGUMENT
    for session in (from_dict, from_file, from_text):
        client.delete_session(session)


def test_scene_files_carry_their_meshes_inline(client):
    scene = load_scene(ROOT / "scenes" / "mesh_body.toml")
    shapes = [s["shape"] for s in scene["systems"] if "shape" in s]
    assert shapes and all("base64" in s["data"] for s in shapes if s["type"] == "mesh")
    session = client.create_session(scene)
    assert session.particle_count > 0
    client.delete_session(session)


def test_errors_carry_the_code_and_the_servers_message(client):
    assert code_of(lambda: client.get_session("missing")) == grpc.StatusCode.NOT_FOUND
    assert code_of(lambda: client.step("missing")) == grpc.StatusCode.NOT_FOUND
    session = client.create_session(TANK)
    assert code_of(lambda: client.step(session, 0)) == grpc.StatusCode.INVALID_ARGUMENT
    assert code_of(lambda: client.get_design(session)) == grpc.StatusCode.NOT_FOUND
    with pytest.raises(ValueError, match="until"):
        client.run(session)
    # A per-call deadline shorter than the call (about 1.5 ms a step here).
    started = time.monotonic()
    assert code_of(lambda: client.step(session, 10**5, timeout=0.05)) == grpc.StatusCode.DEADLINE_EXCEEDED
    assert time.monotonic() - started < 5.0
    client.delete_session(session)


def test_the_status_stream_follows_a_run_to_its_end(client):
    session = client.create_session(TANK)
    seen = []
    with client.watch_status(session) as statuses:
        stream = iter(statuses)
        # The state now, read before the run starts: a run asked for at
        # once can reach the server before the watch does (CI saw its
        # first status say running).
        first = next(stream)
        seen.append((state_name(first), first.step))
        client.run(session, until=0.05)
        for status in stream:
            seen.append((state_name(status), status.step))
            if state_name(status) == "finished":
                break
    assert seen[0] == ("idle", 0)
    assert ("running", 0) in seen and seen[-1] == ("finished", 5), seen
    # wait_for returns at once for a state the session is in, and times out
    # for one it never reaches.
    assert client.wait_for(session, ["finished"]).step == 5
    with pytest.raises(MeshlessError) as refused:
        client.wait_for(session, ["running"], timeout=0.3)
    assert refused.value.code == grpc.StatusCode.DEADLINE_EXCEEDED
    client.delete_session(session)


def test_frames_are_numpy_views_of_the_payload(client):
    session = client.create_session(TANK)
    client.step(session, 2)
    over_grpc = client.latest_frame(session)
    payload = client.stub.GetLatestFrame(
        client._ref(session), timeout=TIMEOUT, metadata=client.metadata
    ).SerializeToString()
    frame = decode_frame(payload)
    for f in (frame, over_grpc):
        assert f.step == 2 and set(f.fields) == {"position", "velocity", "pressure"}
        for name, array in f.fields.items():
            assert array.dtype == np.float32 and not array.flags.writeable, name
            assert isinstance(array.base, bytes), f"{name} is a copy, not a view of the payload"
    for name, array in frame.fields.items():
        assert array.base is payload, name
        np.testing.assert_array_equal(array, over_grpc.fields[name])
    assert frame.header.substeps == frame.substeps >= 1
    client.delete_session(session)


def test_frames_by_iterator_callback_and_latest_query(client):
    session = client.create_session(TANK)
    got: list[Frame] = []
    done = threading.Event()

    def on_frame(frame: Frame) -> None:
        got.append(frame)
        if frame.step == 4:
            done.set()

    with client.frames(session) as frames, client.frames(session, callback=on_frame) as called:
        assert frames.latest is not None and frames.latest.step == 0
        assert called.latest is not None and called.latest.step == 0
        client.step(session, 4)
        steps = []
        for frame in frames:
            steps.append(frame.step)
            if frame.step == 4:
                break
        assert steps == [1, 2, 3, 4]
        assert done.wait(TIMEOUT)
        assert [f.step for f in got] == [1, 2, 3, 4]
        assert frames.query_latest().step == 4
        with pytest.raises(RuntimeError, match="callback"):
            called.next()
        with pytest.raises(TimeoutError):
            next(iter(frames.iter(timeout=0.2)))
    # Iteration ends once closed.
    assert list(frames) == []
    client.delete_session(session)


def test_a_long_run_streams_progress_and_stops_at_a_step_on_its_deadline(client):
    session = client.create_session(TANK)
    progress = []
    last = client.simulate(session, 20, on_progress=progress.append, progress_interval=0.01)
    assert last.done and last.steps_done == last.steps_total == 20
    assert last.status.step == 20
    assert progress[0].steps_done <= progress[-1].steps_done and progress[-1] == last
    assert client.get_session(session).status.step == 20

    # A deadline ends the call at the last completed step; the session is
    # paused there, and its latest frame is that step's.
    started = time.monotonic()
    with pytest.raises(MeshlessError) as ended:
        for _ in client.simulate_steps(session, 10**9, timeout=0.5):
            pass
    assert ended.value.code == grpc.StatusCode.DEADLINE_EXCEEDED
    assert time.monotonic() - started < TIMEOUT
    status = client.wait_for(session, ["paused"])
    assert status.step > 20
    assert client.latest_frame(session).step == status.step
    # Cancelling stops it the same way.
    stream = client.simulate_steps(session, 10**9, progress_interval=0.01)
    for message in stream:
        if message.steps_done >= 2:
            stream.cancel()
    paused = client.wait_for(session, ["paused"])
    assert paused.step >= status.step + 2
    client.delete_session(session)


def test_a_snapshot_restores_into_a_new_or_the_same_session_bit_for_bit(client):
    session = client.create_session(TANK)
    client.step(session, 3)
    snapshot = client.snapshot(session)
    assert (snapshot.session_id, snapshot.step) == (session.id, 3) and snapshot.data
    assert len(snapshot.data) <= client.server_info().max_snapshot_bytes

    copy = client.restore(snapshot)
    assert copy.id != session.id and copy.status.step == 3 and copy.owner == session.owner
    for s in (session, copy):
        client.step(s, 4)
    a, b = client.latest_frame(session), client.latest_frame(copy)
    assert a.step == b.step == 7
    for name in a.fields:
        assert a.fields[name].tobytes() == b.fields[name].tobytes(), name

    # Back into the original: it is at step 3 again, then computes the same.
    back = client.restore(snapshot.data, session=session)
    assert back.id == session.id and back.status.step == 3
    client.step(session, 4)
    assert client.latest_frame(session).fields["position"].tobytes() == a.fields["position"].tobytes()

    # A corrupted or truncated blob is refused and changes nothing.
    corrupted = bytearray(snapshot.data)
    corrupted[len(corrupted) // 2] ^= 0xFF
    for blob in (bytes(corrupted), snapshot.data[: len(snapshot.data) // 2], b""):
        refused = code_of(lambda blob=blob: client.restore(blob, session=copy))
        assert refused == grpc.StatusCode.INVALID_ARGUMENT
    assert client.get_session(copy).status.step == 7
    for s in (session, copy):
        client.delete_session(s)


def test_design_calls_take_dicts_and_keywords(client):
    column = fixture("small_column")
    session = client.create_session(column)

    def handle(name: str, zmin: float, zmax: float, lift: float) -> dict:
        return {
            "name": name,
            "type": "handle",
            "points": {"region": {"min": [0.3, 0.3, zmin], "max": [0.7, 0.7, zmax]}},
            "target": {"transform": {"translation": [0.0, 0.0, lift]}},
        }

    listed = client.edit_constraints(
        session, add=[handle("bottom", 0.25, 0.36, 0.0), handle("top", 0.64, 0.75, 0.1)]
    )
    assert [c.name for c in listed] == ["bottom", "top"]
    listed = client.edit_constraints(session, replace=[handle("top", 0.64, 0.75, 0.05)])
    assert listed[1].handle.target.transform.translation.z == 0.05
    assert [c.name for c in client.list_constraints(session)] == ["bottom", "top"]
    design = client.optimize(session=session, design={"particles": 40}, timeout=TIMEOUT)
    assert design.kind == "shape" and design.info.converged
    assert abs(design.displacements[0, :, 2].max() - 0.05) < 0.01
    np.testing.assert_array_equal(client.get_design(session).positions(0), design.positions(0))
    assert client.cancel_optimize(session) is False
    assert client.edit_constraints(session, clear=True) == []
    client.delete_session(session)


def test_the_wire_scan_knows_the_frame_messages_field_numbers():
    """decode_frame finds the packed bytes by field number: they must be
    those of proto/meshless/v1/frame.proto."""
    from meshless import frames as f
    from meshless.v1 import frame_pb2

    def number(message, name):
        field = message.DESCRIPTOR.fields_by_name[name]
        assert field.type == field.TYPE_MESSAGE or field.type == field.TYPE_BYTES, name
        return field.number

    assert f._FRAME_FIELDS == number(frame_pb2.Frame, "fields")
    assert f._FRAME_SURFACE == number(frame_pb2.Frame, "surface")
    assert f._FRAME_SOLID_SURFACES == number(frame_pb2.Frame, "solid_surfaces")
    assert f._FRAME_CRACK_SURFACES == number(frame_pb2.Frame, "crack_surfaces")
    assert f._FIELD_DATA == number(frame_pb2.FieldData, "data")
    assert f._SOLID_SURFACE_MESH == number(frame_pb2.SolidSurface, "mesh")
    mesh = frame_pb2.SurfaceMesh
    assert (f._MESH_VERTICES, f._MESH_TRIANGLES, f._MESH_NORMALS) == tuple(
        number(mesh, name) for name in ("vertices", "triangles", "normals")
    )


def test_the_views_hold_what_protobuf_parses_even_from_mangled_payloads():
    """Seeded mutations of a frame with fields and surfaces: decode_frame
    raises ValueError, or each array it returns holds exactly the bytes
    protobuf's own parser reads for that field."""
    import random

    from meshless.v1 import frame_pb2, scene_pb2

    message = frame_pb2.Frame()
    message.header.session_id = "s"
    message.header.particle_count = 4
    for kind, components in ((scene_pb2.FIELD_KIND_POSITION, 3), (scene_pb2.FIELD_KIND_PRESSURE, 1)):
        f = message.fields.add(kind=kind, components=components, scalar=frame_pb2.SCALAR_TYPE_F32)
        f.data = np.arange(4 * components, dtype="<f4").tobytes()
    ids = message.fields.add(
        kind=scene_pb2.FIELD_KIND_ID, components=1, scalar=frame_pb2.SCALAR_TYPE_U32
    )
    ids.data = np.array([0, 1, 5, 9], dtype="<u4").tobytes()
    triangle = np.array([[0, 1, 2]], dtype="<u4").tobytes()
    message.surface.vertices = np.ones((3, 3), dtype="<f4").tobytes()
    message.surface.triangles = triangle
    solid = message.solid_surfaces.add(system=1)
    solid.mesh.vertices = np.full((3, 3), 2.0, dtype="<f4").tobytes()
    solid.mesh.triangles = triangle
    solid.mesh.normals = np.full((3, 3), 3.0, dtype="<f4").tobytes()
    crack = message.crack_surfaces.add(system=1)
    crack.mesh.vertices = np.full((3, 3), 4.0, dtype="<f4").tobytes()
    crack.mesh.triangles = triangle
    crack.mesh.normals = np.full((3, 3), 5.0, dtype="<f4").tobytes()
    payload = message.SerializeToString()
    # A second surface occurrence: protobuf merges it, its vertices win.
    extra = frame_pb2.Frame()
    extra.surface.vertices = np.full((3, 3), 7.0, dtype="<f4").tobytes()
    payloads = [payload, payload + extra.SerializeToString()]

    rng = random.Random(15)
    for _ in range(1500):
        data = bytearray(rng.choice(payloads))
        for _ in range(rng.randint(1, 3)):
            data[rng.randrange(len(data))] = rng.randrange(256)
        payloads.append(bytes(data))
    decoded = 0
    for data in payloads:
        try:
            frame = decode_frame(data)
        except ValueError:
            continue
        decoded += 1
        parsed = frame_pb2.Frame.FromString(data)
        # decode_frame refuses a kind given twice, so each is here once.
        expected = {
            scene_pb2.FieldKind.Name(f.kind).removeprefix("FIELD_KIND_").lower(): f.data
            for f in parsed.fields
        }
        if frame.ids is not None:
            assert frame.ids.dtype == np.dtype("<u4")
            assert frame.ids.tobytes() == expected.pop("id")
            assert frame.ids.base is data
        assert set(frame.fields) == set(expected)
        for name, array in frame.fields.items():
            assert array.tobytes() == expected[name], name
            assert array.base is data
        if frame.surface is not None:
            assert frame.surface.vertices.tobytes() == parsed.surface.vertices
            assert frame.surface.triangles.tobytes() == parsed.surface.triangles
        assert len(frame.solid_surfaces) == len(parsed.solid_surfaces)
        assert len(frame.crack_surfaces) == len(parsed.crack_surfaces)
        for s, p in zip(
            frame.solid_surfaces + frame.crack_surfaces,
            list(parsed.solid_surfaces) + list(parsed.crack_surfaces),
        ):
            assert s.vertices.tobytes() == p.mesh.vertices
            assert s.normals.tobytes() == p.mesh.normals
    assert decoded > 100, decoded
    assert decode_frame(payloads[1]).surface.vertices[0, 0] == 7.0


def test_a_server_timeout_reported_as_cancelled_is_a_passed_deadline():
    """tonic answers CANCELLED "Timeout expired" when the server's timer
    for a call's deadline fires before the client's: the client reports
    DEADLINE_EXCEEDED once the deadline has passed, CANCELLED otherwise."""
    from meshless.errors import call_error

    class Cancelled(grpc.RpcError):
        def code(self):
            return grpc.StatusCode.CANCELLED

        def details(self):
            return "Timeout expired"

    passed = call_error(Cancelled(), time.monotonic() - 0.001)
    assert passed.code == grpc.StatusCode.DEADLINE_EXCEEDED and "Timeout expired" in passed.details
    assert call_error(Cancelled(), time.monotonic() + 10).code == grpc.StatusCode.CANCELLED
    assert call_error(Cancelled(), None).code == grpc.StatusCode.CANCELLED


def test_a_modal_solid_is_grabbed_with_dicts_and_streams_its_skin(client):
    """A modal EFG cantilever (``tests/fixtures/small_modal.toml``): its
    frames carry the nodes and the skin with unit normals, a grab in the
    TOML form of ``docs/modal.md`` pulls the skin's tip vertex to its
    target, and a grab off the solid is INVALID_ARGUMENT and changes
    nothing."""
    session = client.create_session(fixture("small_modal"))
    rest = client.latest_frame(session)
    assert [s.system for s in rest.solids] == [0]
    assert rest.solids[0].count == rest.particle_count
    skin = rest.solid_surfaces[0]
    tip = int(np.argmin(np.linalg.norm(skin.vertices - [0.16, 0.0, 0.0], axis=1)))
    point = skin.vertices[tip].astype(float).tolist()
    target = [0.15, 0.05, 0.0]
    grab = {"name": "tip", "type": "grab", "system": 0, "point": point, "position": target}
    listed = client.edit_constraints(session, add=[grab])
    assert [c.name for c in listed] == ["tip"] and listed[0].grab.position.y == 0.05
    far = dict(grab, name="far", point=[2.0, 0.0, 0.0])
    assert code_of(lambda: client.edit_constraints(session, add=[far])) == (
        grpc.StatusCode.INVALID_ARGUMENT
    )
    assert [c.name for c in client.list_constraints(session)] == ["tip"]
    client.step(session, 60)
    held = client.latest_frame(session).solid_surfaces[0]
    np.testing.assert_allclose(held.vertices[tip], target, atol=1e-3)
    np.testing.assert_allclose(np.linalg.norm(held.normals, axis=1), 1.0, atol=1e-5)
    client.delete_session(session)


def test_a_shell_streams_its_nodes_and_surface_and_restores_from_a_snapshot(client):
    """A thin shell (``tests/fixtures/small_shell.toml``): its frames list
    its nodes as one solid and carry the plate's mesh with unit normals,
    sagging under gravity; a snapshot restored into a new session steps on
    to the same frame; a grab pulls its free corner to a target and one off
    the surface is INVALID_ARGUMENT and changes nothing; a closed surface
    is INVALID_ARGUMENT naming the shape, and no session is made of it."""
    session = client.create_session(fixture("small_shell"))
    assert list(session.system_kinds) == ["shell"]
    rest = client.latest_frame(session)
    assert [s.system for s in rest.solids] == [0]
    assert rest.solids[0].count == rest.particle_count
    plate = rest.solid_surfaces[0]
    assert plate.vertices.shape == (9 * 5, 3)
    client.step(session, 5)
    snapshot = client.snapshot(session)
    client.step(session, 5)
    bent = client.latest_frame(session).solid_surfaces[0]
    assert bent.vertices[:, 1].min() < -1e-3
    np.testing.assert_allclose(np.linalg.norm(bent.normals, axis=1), 1.0, atol=1e-5)
    again = client.restore(snapshot)
    client.step(again, 5)
    np.testing.assert_array_equal(
        client.latest_frame(again).solid_surfaces[0].vertices, bent.vertices
    )
    corner = [0.4, 0.0, 0.1]
    tip = int(np.argmin(np.linalg.norm(plate.vertices - corner, axis=1)))
    target = [0.4, 0.02, 0.1]
    grab = {"name": "corner", "type": "grab", "system": 0, "point": corner, "position": target}
    client.edit_constraints(session, add=[grab])
    client.step(session, 3)
    np.testing.assert_allclose(
        client.latest_frame(session).solid_surfaces[0].vertices[tip], target, atol=1e-4
    )
    off = dict(grab, name="off", point=[0.4, 0.5, 0.1])
    assert code_of(lambda: client.edit_constraints(session, add=[off])) == (
        grpc.StatusCode.INVALID_ARGUMENT
    )
    assert [c.name for c in client.list_constraints(session)] == ["corner"]
    before = len(client.list_sessions())
    closed = fixture("small_shell").replace(
        'shape = { type = "box", half_extents = [0.2, 0.0, 0.1] }',
        'shape = { type = "capsule", half_length = 0.1, radius = 0.05 }',
    )
    with pytest.raises(MeshlessError) as refused:
        client.create_session(closed)
    assert refused.value.code == grpc.StatusCode.INVALID_ARGUMENT
    assert "systems[0].shape" in refused.value.details
    assert "a mesh file or an oriented point cloud" in refused.value.details
    assert len(client.list_sessions()) == before
    for s in (session, again):
        client.delete_session(s)


def test_a_shell_from_a_scan_streams_the_scans_points(client):
    """``scenes/shell_scan.toml``: a rubber ball given as 1,200 points with
    normals and no faces (its PLY sent inline by the scene loader). The
    server meshes the cloud's surface and charts it; frames carry the
    scan's own points with unit normals and no triangles, and 2 kPa
    swells them by about the membrane solution (5.5 mm)."""
    session = client.create_session(load_scene(ROOT / "scenes" / "shell_scan.toml"))
    assert list(session.system_kinds) == ["shell"]
    rest = client.latest_frame(session).solid_surfaces[0]
    assert rest.vertices.shape == (1200, 3)
    assert len(rest.triangles) == 0
    np.testing.assert_allclose(np.linalg.norm(rest.normals, axis=1), 1.0, atol=1e-5)
    client.step(session, 3)
    swollen = client.latest_frame(session).solid_surfaces[0]
    radius = lambda v: np.linalg.norm(v - v.mean(axis=0), axis=1)
    moved = float(np.mean(radius(swollen.vertices) - radius(rest.vertices)))
    assert 0.005 < moved < 0.006, moved
    client.delete_session(session)


def test_next_frame_follows_a_session_frame_by_frame(client):
    session = client.create_session(TANK)
    number, frame = client.next_frame(session, 0, wait=0)
    assert number >= 1 and frame is not None and frame.step == 0
    # Nothing newer on an idle session: the wait ends empty.
    assert client.next_frame(session, number, wait=0.2) == (number, None)
    client.step(session, 2)
    newer, frame = client.next_frame(session, number, wait=5)
    assert newer > number and frame is not None and frame.step == 2
    assert code_of(lambda: client.next_frame(session, 0, wait=61)) == grpc.StatusCode.INVALID_ARGUMENT
