"""The asyncio client over a real server: the same calls as coroutines,
streams as async iterators, frames through ``async for``, several calls
in flight at once on one channel."""

from __future__ import annotations

import asyncio

import grpc
import numpy as np
import pytest

from conftest import ROOT, TIMEOUT, fixture
from meshless import AsyncClient, MeshlessError, load_scene, state_name

TANK = load_scene(ROOT / "tests" / "fixtures" / "python_tank.toml")


def run(coroutine):
    return asyncio.run(asyncio.wait_for(coroutine, TIMEOUT * 4))


def test_sessions_steps_status_and_errors(shared_server):
    async def main():
        async with AsyncClient(shared_server.grpc_target) as client:
            info = await client.server_info()
            assert info.zenoh_locators == shared_server.zenoh_endpoints
            sessions = await asyncio.gather(*(client.create_session(TANK) for _ in range(3)))
            assert len({s.id for s in sessions}) == 3
            listed = {s.id for s in await client.list_sessions()}
            assert {s.id for s in sessions} <= listed
            stepped = await asyncio.gather(*(client.step(s, k + 1) for k, s in enumerate(sessions)))
            assert [s.status.step for s in stepped] == [1, 2, 3]

            with pytest.raises(MeshlessError) as refused:
                await client.get_session("missing")
            assert refused.value.code == grpc.StatusCode.NOT_FOUND
            bad = dict(TANK, time={"dt": -1.0})
            with pytest.raises(MeshlessError) as refused:
                await client.create_session(bad)
            assert refused.value.code == grpc.StatusCode.INVALID_ARGUMENT
            assert "time.dt" in refused.value.details

            session = sessions[0]
            seen = []
            async with client.watch_status(session) as statuses:
                # The current status first, so the watch is in place before
                # the run starts (the call goes out when first awaited).
                updates = aiter(statuses)
                seen.append(state_name(await anext(updates)))
                await client.run(session, until=0.05)
                async for status in updates:
                    seen.append(state_name(status))
                    if seen[-1] == "finished":
                        break
            # Stepped once: paused at step 1, then the run.
            assert seen[0] == "paused" and seen[-1] == "finished", seen
            assert (await client.wait_for(session, ["finished"])).time == pytest.approx(0.05)
            assert (await client.reset(session)).status.step == 0
            for s in sessions:
                await client.delete_session(s)

    run(main())


def test_frames_long_runs_and_snapshots(shared_server):
    async def main():
        async with AsyncClient(shared_server.grpc_target, timeout=TIMEOUT) as client:
            session = await client.create_session(TANK)
            async with await client.frames(session) as frames:
                assert frames.latest is not None and frames.latest.step == 0
                progress = []
                last = await client.simulate(session, 3, on_progress=progress.append)
                assert last.done and last.status.step == 3 and progress[-1] == last
                steps = []
                async for frame in frames:
                    steps.append(frame.step)
                    if frame.step == 3:
                        break
                assert steps == [1, 2, 3]
                assert (await frames.query_latest()).step == 3
            latest = await client.latest_frame(session)
            assert latest.step == 3 and isinstance(latest.fields["position"].base, bytes)
            number, polled = await client.next_frame(session, 0, wait=0)
            assert polled is not None and polled.step == 3
            assert await client.next_frame(session, number, wait=0.1) == (number, None)

            snapshot = await client.snapshot(session)
            copy = await client.restore(snapshot)
            await asyncio.gather(client.step(session, 2), client.step(copy, 2))
            a, b = await asyncio.gather(client.latest_frame(session), client.latest_frame(copy))
            assert a.step == b.step == 5
            assert a.fields["position"].tobytes() == b.fields["position"].tobytes()
            for s in (session, copy):
                await client.delete_session(s)

    run(main())


def test_design_over_asyncio(shared_server):
    async def main():
        async with AsyncClient(shared_server.grpc_target) as client:
            session = await client.create_session(fixture("small_column"))
            region = {"min": [0.3, 0.3, 0.64], "max": [0.7, 0.7, 0.75]}
            await client.edit_constraints(
                session,
                add=[
                    {
                        "name": "bottom",
                        "type": "handle",
                        "points": {"region": {"min": [0.3, 0.3, 0.25], "max": [0.7, 0.7, 0.36]}},
                        "target": {"transform": {}},
                    },
                    {
                        "name": "top",
                        "type": "handle",
                        "points": {"region": region},
                        "target": {"transform": {"translation": [0.0, 0.0, 0.1]}},
                    },
                ],
            )
            assert [c.name for c in await client.list_constraints(session)] == ["bottom", "top"]
            progress = []
            design = await client.optimize(
                session=session, design={"particles": 40}, on_progress=progress.append
            )
            assert progress and design.info.converged
            assert abs(design.displacements[0, :, 2].max() - 0.1) < 0.02
            again = await client.get_design(session)
            np.testing.assert_array_equal(again.positions(0), design.positions(0))
            assert await client.cancel_optimize(session) is False
            await client.delete_session(session)

    run(main())


def test_no_server_is_unavailable():
    async def main():
        with pytest.raises(MeshlessError) as refused:
            async with AsyncClient("127.0.0.1:1", timeout=0.5):
                pass
        assert refused.value.code == grpc.StatusCode.UNAVAILABLE

    run(main())
