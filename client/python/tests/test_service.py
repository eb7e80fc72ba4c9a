"""The Python side of the protocol: code generated from proto/ imports as
meshless.v1, drives the real server over gRPC, and decodes its frames from
zenoh into numpy arrays."""

from __future__ import annotations

import json
import queue

import grpc
import numpy as np
import pytest
import zenoh

from conftest import TIMEOUT, fixture
from meshless import decode_frame, frames_key, latest_key

SCENE = fixture("python_tank")


def stub(server):
    from meshless.v1 import simulation_pb2_grpc

    channel = grpc.insecure_channel(server.grpc_target)
    grpc.channel_ready_future(channel).result(timeout=TIMEOUT)
    return simulation_pb2_grpc.SimulationStub(channel)


def test_generated_code_imports_as_meshless_v1():
    from meshless.v1 import frame_pb2, scene_pb2, simulation_pb2, simulation_pb2_grpc

    assert simulation_pb2.DESCRIPTOR.package == "meshless.v1"
    assert "Simulation" in simulation_pb2.DESCRIPTOR.services_by_name
    assert frame_pb2.Frame.DESCRIPTOR.full_name == "meshless.v1.Frame"
    assert scene_pb2.FieldKind.Value("FIELD_KIND_DENSITY") == 3
    assert hasattr(simulation_pb2_grpc, "SimulationStub")
    # Every RPC of the service, the snapshot calls included.
    methods = {m.name for m in simulation_pb2.DESCRIPTOR.services_by_name["Simulation"].methods}
    assert {"SimulateSteps", "Snapshot", "Restore", "Optimize"} <= methods


def test_steps_stream_frames_that_numpy_reads(server):
    from meshless.v1 import simulation_pb2 as pb

    sim = stub(server)
    session = sim.CreateSession(pb.CreateSessionRequest(scene_toml=SCENE), timeout=TIMEOUT)
    n = session.particle_count
    assert n == 4 * 6 * 4

    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps(server.zenoh_endpoints))
    config.insert_json5("scouting/multicast/enabled", "false")
    received: queue.Queue[bytes] = queue.Queue()
    with zenoh.open(config) as z:
        z.declare_subscriber(
            frames_key(session.id), lambda sample: received.put(sample.payload.to_bytes())
        )
        # The query's round trip makes sure the server knows the subscriber.
        latest = [decode_frame(r.ok.payload.to_bytes()) for r in z.get(latest_key(session.id)) if r.ok]
        assert [f.step for f in latest] == [0]

        stepped = sim.Step(pb.StepRequest(session_id=session.id, steps=3), timeout=TIMEOUT)
        assert stepped.status.step == 3
        frames = [decode_frame(received.get(timeout=TIMEOUT)) for _ in range(3)]

    assert [f.step for f in frames] == [1, 2, 3]
    last = frames[-1]
    assert last.particle_count == n
    assert set(last.fields) == {"position", "velocity", "pressure"}
    assert last.fields["position"].shape == (n, 3)
    assert last.fields["pressure"].shape == (n, 1)
    assert np.isfinite(last.fields["position"]).all()
    # Gravity pulls the fluid down: the mean height falls step by step.
    heights = [f.fields["position"][:, 1].mean() for f in [latest[0], *frames]]
    assert all(b < a for a, b in zip(heights, heights[1:])), heights

    # The same frame over gRPC, for clients without zenoh.
    over_grpc = sim.GetLatestFrame(pb.SessionRef(session_id=session.id), timeout=TIMEOUT)
    again = decode_frame(over_grpc.SerializeToString())
    np.testing.assert_array_equal(again.fields["position"], last.fields["position"])


def test_a_bad_scene_is_invalid_argument_naming_the_field(server):
    from meshless.v1 import simulation_pb2 as pb

    sim = stub(server)
    bad = SCENE.replace("spacing = 0.05", "spacing = -0.05")
    with pytest.raises(grpc.RpcError) as error:
        sim.CreateSession(pb.CreateSessionRequest(scene_toml=bad), timeout=TIMEOUT)
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "systems[0].spacing" in error.value.details()
    with pytest.raises(grpc.RpcError) as error:
        sim.Step(pb.StepRequest(session_id="missing", steps=1), timeout=TIMEOUT)
    assert error.value.code() == grpc.StatusCode.NOT_FOUND


def test_an_undecodable_request_is_invalid_argument(server):
    # Raw bytes that are no protobuf message: a field tag of 0 (tonic's
    # codec alone would answer INTERNAL, as if the server had broken).
    channel = grpc.insecure_channel(server.grpc_target)
    grpc.channel_ready_future(channel).result(timeout=TIMEOUT)
    raw = channel.unary_unary(
        "/meshless.v1.Simulation/GetSession",
        request_serializer=None,
        response_deserializer=None,
    )
    with pytest.raises(grpc.RpcError) as error:
        raw(b"\x00\x00\x00", timeout=TIMEOUT)
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "not a valid protobuf message" in error.value.details()
    # The server serves the next request.
    from meshless.v1 import simulation_pb2 as pb

    with pytest.raises(grpc.RpcError) as error:
        stub(server).GetSession(pb.SessionRef(session_id="missing"), timeout=TIMEOUT)
    assert error.value.code() == grpc.StatusCode.NOT_FOUND


def test_the_client_wrapper_drives_a_session(server):
    from meshless import Client, Frames, MeshlessError

    with Client(server.grpc_target) as client:
        info = client.server_info()
        assert info.zenoh_locators == server.zenoh_endpoints
        session = client.create_session(SCENE)
        assert [s.id for s in client.list_sessions()] == [session.id]
        with Frames(info.zenoh_locators, session.id) as frames:
            assert frames.latest is not None and frames.latest.step == 0
            client.run_until(session.id, 0.05)
            steps = [frames.next().step for _ in range(5)]
        assert steps == [1, 2, 3, 4, 5]
        done = client.get_session(session.id)
        assert done.status.step == 5
        assert client.latest_frame(session.id).step == 5
        client.reset(session.id)
        assert client.get_session(session.id).status.step == 0
        client.delete_session(session.id)
        with pytest.raises(MeshlessError) as error:
            client.get_session(session.id)
        assert error.value.code == grpc.StatusCode.NOT_FOUND


def test_particles_leave_and_join_and_are_followed_by_id(server):
    """ChangeParticles over gRPC: survivors keep their ids, new particles
    get the next ones, a refused change queues nothing."""
    from meshless import Client, MeshlessError

    scene = SCENE.replace('fields = ["velocity"', 'fields = ["id", "velocity"')
    with Client(server.grpc_target) as client:
        session = client.create_session(scene)
        client.step(session.id, 1)
        before = client.latest_frame(session.id)
        assert before.ids is not None and before.ids.dtype == np.uint32
        assert sorted(before.ids) == list(range(96)) and "id" not in before.fields
        followed = before.positions[before.ids == 50][0]
        _, new = client.change_particles(
            session.id, 0, remove=[3, 7], positions=[[0.4, 0.4, 0.4]], velocities=[[0, -1, 0]]
        )
        assert new == range(96, 97)
        with pytest.raises(MeshlessError) as refused:
            client.change_particles(
                session.id, 0, remove=[9], positions=[[2.0, 0.1, 0.1]], velocities=[[0, 0, 0]]
            )
        assert refused.value.code == grpc.StatusCode.INVALID_ARGUMENT
        with pytest.raises(MeshlessError) as full:
            client.change_particles(
                session.id, 0, positions=[[0.4, 0.4, 0.3], [0.3, 0.4, 0.4]], velocities=[[0, 0, 0]] * 2
            )
        assert full.value.code == grpc.StatusCode.RESOURCE_EXHAUSTED, full.value
        client.step(session.id, 1)
        after = client.latest_frame(session.id)
        assert sorted(after.ids) == sorted(set(range(97)) - {3, 7}), "9 stays: refused"
        moved = np.linalg.norm(after.positions[after.ids == 50][0] - followed)
        assert moved < 0.01, moved
        joined = after.positions[after.ids == 96][0]
        assert np.linalg.norm(joined - [0.4, 0.4, 0.4]) < 0.02, joined
        client.delete_session(session.id)


def test_frames_carry_the_surface_the_scene_asks_for(server):
    from meshless.v1 import simulation_pb2 as pb

    sim = stub(server)
    scene = SCENE.replace("[output]", "[output]\nsurface = { iso = 0.5 }")
    session = sim.CreateSession(pb.CreateSessionRequest(scene_toml=scene), timeout=TIMEOUT)
    assert session.scene.output.surface.iso == 0.5
    frame = decode_frame(
        sim.GetLatestFrame(pb.SessionRef(session_id=session.id), timeout=TIMEOUT).SerializeToString()
    )
    surface = frame.surface
    assert surface is not None and len(surface.triangles) > 0
    assert surface.vertices.dtype == np.float32 and surface.triangles.dtype == np.uint32
    # Closed and consistently oriented: each directed edge once, and its reverse once.
    t = surface.triangles.astype(np.int64)
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    keys = edges[:, 0] * len(surface.vertices) + edges[:, 1]
    reverse = edges[:, 1] * len(surface.vertices) + edges[:, 0]
    assert len(np.unique(keys)) == len(keys)
    assert np.array_equal(np.sort(keys), np.sort(reverse))
    # The block of fluid is 0.2 x 0.3 x 0.2 m: the enclosed volume is that box's,
    # less the rounding of its free edges at four particles across (measured -3.5 %).
    a, b, c = (surface.vertices[t[:, k]].astype(np.float64) for k in range(3))
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    assert abs(volume / (0.2 * 0.3 * 0.2) - 1.0) < 0.06, volume
    # A frame without a surface decodes to None.
    plain = sim.CreateSession(pb.CreateSessionRequest(scene_toml=SCENE), timeout=TIMEOUT)
    latest = sim.GetLatestFrame(pb.SessionRef(session_id=plain.id), timeout=TIMEOUT)
    assert decode_frame(latest.SerializeToString()).surface is None


def test_frames_carry_rigid_body_poses(server):
    from meshless.v1 import simulation_pb2 as pb

    sim = stub(server)
    ball = """
[[systems]]
kind = "rigid_body"
shape = { type = "sphere", radius = 0.05 }
position = [0.35, 0.44, 0.25]
motion = "dynamic"
density = 500.0
"""
    session = sim.CreateSession(pb.CreateSessionRequest(scene_toml=SCENE + ball), timeout=TIMEOUT)
    sim.Step(pb.StepRequest(session_id=session.id, steps=5), timeout=TIMEOUT)
    frame = decode_frame(
        sim.GetLatestFrame(pb.SessionRef(session_id=session.id), timeout=TIMEOUT).SerializeToString()
    )
    assert len(frame.bodies) == 1
    body = frame.bodies[0]
    assert body.system == 1
    assert np.isclose(np.linalg.norm(body.orientation), 1.0)
    # Five steps of 0.01 s in free fall, out of the water's reach. The
    # symplectic Euler sub-steps give v = g t exactly, and a drop between
    # g t^2 / 2 and g t^2 / 2 + g t dt / 2 for sub-steps no longer than dt.
    g, t = 9.81, 0.05
    assert abs(body.velocity[1] + g * t) < 1e-9, body.velocity
    drop = 0.44 - body.position[1]
    assert 0.5 * g * t * t < drop <= 0.5 * g * t * (t + 0.01), body.position


def test_a_solid_sent_as_messages_falls_under_gravity(server):
    from meshless.v1 import scene_pb2 as sc
    from meshless.v1 import simulation_pb2 as pb

    def vec(x, y, z):
        return sc.Vec3(x=x, y=y, z=z)

    solid = sc.SolidSpec(
        shape=sc.Shape(box=sc.BoxShape(half_extents=vec(0.1, 0.1, 0.1))),
        position=vec(0.5, 0.7, 0.5),
        spacing=0.05,
        young=1.0e5,
        poisson=0.25,
        order=sc.MLS_ORDER_LINEAR,
        integrator=sc.SOLID_INTEGRATOR_EXPLICIT,
    )
    scene = sc.SceneSpec(
        name="falling jelly",
        domain=sc.Aabb(min=vec(0, 0, 0), max=vec(1, 1, 1)),
        time=sc.TimeSpec(dt=0.01),
        systems=[sc.SystemSpec(solid=solid)],
    )
    sim = stub(server)
    session = sim.CreateSession(pb.CreateSessionRequest(scene=scene), timeout=TIMEOUT)
    echoed = session.scene.systems[0].solid
    assert echoed.density == 1000.0 and echoed.support == 2.0, "defaults made explicit"
    n = session.particle_count
    assert n == 4 * 4 * 4

    def latest():
        message = sim.GetLatestFrame(pb.SessionRef(session_id=session.id), timeout=TIMEOUT)
        return decode_frame(message.SerializeToString())

    before = latest()
    assert [(r.system, r.first, r.count) for r in before.solids] == [(0, 0, n)]
    steps = 20
    sim.Step(pb.StepRequest(session_id=session.id, steps=steps), timeout=TIMEOUT)
    after = latest()
    assert after.step == steps and len(after.solids) == 1
    rows = after.solids[0].rows
    positions = after.fields["position"][rows]
    assert np.isfinite(positions).all()
    # Internal forces cancel, so the centre of mass falls freely, g t^2 / 2
    # (the sub-steps' symplectic Euler adds under g t dt / 2, 5 % here).
    g, t = 9.81, steps * 0.01
    drop = before.fields["position"][rows, 1].mean() - positions[:, 1].mean()
    assert abs(drop / (0.5 * g * t * t) - 1.0) < 0.1, drop


def test_a_solid_carries_its_embedded_surface_as_it_falls(server):
    from meshless.v1 import scene_pb2 as sc
    from meshless.v1 import simulation_pb2 as pb

    def vec(x, y, z):
        return sc.Vec3(x=x, y=y, z=z)

    solid = sc.SolidSpec(
        shape=sc.Shape(box=sc.BoxShape(half_extents=vec(0.1, 0.1, 0.1))),
        position=vec(0.5, 0.7, 0.5),
        spacing=0.05,
        young=1.0e5,
        surface=sc.SolidSurfaceSpec(method=sc.EMBEDDING_METHOD_GRADIENTS, subdivisions=2),
    )
    scene = sc.SceneSpec(
        name="falling jelly with a surface",
        dimension=3,
        domain=sc.Aabb(min=vec(0, 0, 0), max=vec(1, 1, 1)),
        time=sc.TimeSpec(dt=0.01),
        systems=[sc.SystemSpec(solid=solid)],
    )
    sim = stub(server)
    session = sim.CreateSession(pb.CreateSessionRequest(scene=scene), timeout=TIMEOUT)
    echoed = session.scene.systems[0].solid.surface
    assert (echoed.method, echoed.subdivisions) == (sc.EMBEDDING_METHOD_GRADIENTS, 2)

    def latest():
        message = sim.GetLatestFrame(pb.SessionRef(session_id=session.id), timeout=TIMEOUT)
        return decode_frame(message.SerializeToString())

    before = latest()
    sim.Step(pb.StepRequest(session_id=session.id, steps=20), timeout=TIMEOUT)
    after = latest()
    surfaces = [frame.solid_surfaces for frame in (before, after)]
    assert [[s.system for s in f] for f in surfaces] == [[0], [0]]
    first, last = surfaces[0][0], surfaces[1][0]
    # A box's 6 faces of 2 triangles, each split in four twice.
    assert len(first.triangles) == 12 * 4**2
    assert last.vertices.shape == first.vertices.shape and len(first.vertices) > 0
    assert np.array_equal(last.triangles, first.triangles), "the connectivity is fixed"
    for s in (first, last):
        assert s.vertices.dtype == np.float32 and s.normals.dtype == np.float32
        assert s.triangles.dtype == np.uint32 and s.normals.shape == s.vertices.shape
        assert np.abs(np.linalg.norm(s.normals, axis=1) - 1.0).max() < 1e-4
    # The surface falls with the particles' centre of mass.
    rows = after.solids[0].rows
    particles = before.fields["position"][rows, 1].mean() - after.fields["position"][rows, 1].mean()
    surface = first.vertices[:, 1].mean() - last.vertices[:, 1].mean()
    assert particles > 0.1, particles
    assert abs(surface / particles - 1.0) < 0.05, (surface, particles)


COLUMN = fixture("small_column")


def test_constraints_and_a_shape_optimisation(server):
    """Constraint edits are atomic and name the bad constraint; a shape
    optimisation reports progress and returns the design as numpy arrays,
    the column's top lifted by its handle."""
    from meshless import Client, MeshlessError
    from meshless.v1 import design_pb2 as d
    from meshless.v1 import scene_pb2 as sc

    def region_handle(name, zmin, zmax, lift):
        return d.ConstraintEdit(
            add=d.Constraint(
                name=name,
                handle=d.HandleConstraint(
                    points=d.Selection(
                        region=sc.Aabb(min=sc.Vec3(x=0.3, y=0.3, z=zmin), max=sc.Vec3(x=0.7, y=0.7, z=zmax))
                    ),
                    target=d.DesignTarget(transform=d.TransformTarget(translation=sc.Vec3(z=lift))),
                ),
            )
        )

    with Client(server.grpc_target) as client:
        session = client.create_session(COLUMN)
        listed = client.edit_constraints(
            session.id, [region_handle("bottom", 0.25, 0.36, 0.0), region_handle("top", 0.64, 0.75, 0.1)]
        )
        assert [c.name for c in listed] == ["bottom", "top"]

        bad = d.ConstraintEdit(
            add=d.Constraint(
                name="far",
                handle=d.HandleConstraint(
                    points=d.Selection(particles=d.ParticleSelection(system=0, indices=[100000])),
                    target=d.DesignTarget(positions=d.PositionsTarget(positions=[sc.Vec3()])),
                ),
            )
        )
        with pytest.raises(MeshlessError) as error:
            client.edit_constraints(session.id, [d.ConstraintEdit(remove="top"), bad])
        assert error.value.code == grpc.StatusCode.INVALID_ARGUMENT
        assert "far" in error.value.details
        assert [c.name for c in client.list_constraints(session.id)] == ["bottom", "top"]

        with pytest.raises(MeshlessError) as error:
            client.get_design(session.id)
        assert error.value.code == grpc.StatusCode.NOT_FOUND

        progress = []
        request = d.OptimizeRequest(
            session_id=session.id,
            system=0,
            design=d.DesignSettings(particles=40),
            shape=d.ShapeProblem(),
        )
        design = client.optimize(request, on_progress=progress.append, timeout=TIMEOUT)
        assert len(progress) >= 1
        assert design.kind == "shape"
        assert design.info.converged
        assert design.info.energies.handle < 1.0
        n = design.rest_positions.shape[0]
        assert design.displacements.shape == (1, n, 3)
        lift = design.displacements[0, :, 2].max()
        assert abs(lift - 0.1) < 0.02, lift
        again = client.get_design(session.id)
        np.testing.assert_array_equal(again.positions(0), design.positions(0))
        assert client.cancel_optimize(session.id) is False


def test_a_brittle_beam_breaks_and_its_pieces_and_cracks_are_served(server):
    """The shipped brittle cantilever over gRPC: its frames label the
    fragments, carry the crack faces with normals, and a snapshot taken
    once it cracked restores into a session that steps on identically."""
    from conftest import ROOT
    from meshless import Client

    scene = (ROOT / "scenes" / "brittle_beam.toml").read_text()
    with Client(server.grpc_target) as client:
        session = client.create_session(scene)
        assert session.scene.systems[0].solid.fracture.stress == 3.5e5
        frame = client.latest_frame(session.id)
        assert set(np.unique(frame.fields["fragment"])) == {0.0}
        assert frame.crack_surfaces == []
        # It breaks within 0.3 s of its release.
        for _ in range(30):
            client.step(session.id, 5)
            frame = client.latest_frame(session.id)
            if len(np.unique(frame.fields["fragment"])) >= 2:
                break
        labels = np.unique(frame.fields["fragment"])
        assert len(labels) >= 2, labels
        [faces] = frame.crack_surfaces
        assert faces.system == 0 and len(faces.triangles) > 0
        assert faces.normals.shape == faces.vertices.shape
        assert np.abs(np.linalg.norm(faces.normals, axis=1) - 1.0).max() < 1e-3
        snapshot = client.snapshot(session.id)
        copy = client.restore(snapshot)
        client.step(session.id, 20)
        client.step(copy.id, 20)
        a, b = client.latest_frame(session.id), client.latest_frame(copy.id)
        assert a.step == b.step
        assert np.array_equal(a.positions, b.positions)
        assert np.array_equal(a.fields["fragment"], b.fields["fragment"])
        assert np.array_equal(a.crack_surfaces[0].vertices, b.crack_surfaces[0].vertices)


def test_a_resampling_beam_grows_its_frames_and_a_limit_faults_the_session(server):
    """The brittle beam resampling beside its crack (tutorial Eq. 71) over
    gRPC: frames grow, saying how many particles the step added, the old
    ids keep their rows; a snapshot of the grown beam restores and steps
    on identically; a limit it outgrows faults the session with the
    reason."""
    from conftest import ROOT
    from meshless import Client, MeshlessError
    from meshless.v1 import simulation_pb2

    base = (ROOT / "scenes" / "brittle_beam.toml").read_text()
    base = base.replace('fields = ["velocity", "fragment"]', 'fields = ["velocity", "fragment", "id"]')
    scene = base.replace("advance = 0.5 }", "advance = 0.5, resample = { q_min = 10 } }")
    assert scene != base
    with Client(server.grpc_target) as client:
        session = client.create_session(scene)
        assert session.scene.systems[0].solid.fracture.resample.q_min == 10
        first = client.latest_frame(session.id)
        built = first.particle_count
        grown = None
        for _ in range(40):
            client.step(session.id, 1)
            frame = client.latest_frame(session.id)
            if frame.header.added > 0:
                grown = frame
                break
        assert grown is not None, "no particle split in 40 steps"
        assert grown.particle_count == built + grown.header.added
        np.testing.assert_array_equal(grown.ids[:built], first.ids)
        np.testing.assert_array_equal(grown.ids[built:], np.arange(built, grown.particle_count))
        assert grown.solids[0].count == grown.particle_count
        assert grown.fields["velocity"].shape == (grown.particle_count, 3)

        copy = client.restore(client.snapshot(session.id))
        client.step(session.id, 10)
        client.step(copy.id, 10)
        a, b = client.latest_frame(session.id), client.latest_frame(copy.id)
        assert a.particle_count == b.particle_count
        assert np.array_equal(a.positions, b.positions)

        limited = client.create_session(
            base.replace("advance = 0.5 }", f"advance = 0.5, resample = {{ max_particles = {built + 1} }} }}")
        )
        faulted = None
        for _ in range(40):
            try:
                client.step(limited.id, 1)
            except MeshlessError:  # the step that faults
                pass
            status = client.get_session(limited.id).status
            if status.state == simulation_pb2.SESSION_STATE_FAULTED:
                faulted = status
                break
        assert faulted is not None, "the session outgrew its limit without a fault"
        assert "max_particles" in faulted.reason, faulted.reason
        assert client.latest_frame(limited.id).particle_count == built
