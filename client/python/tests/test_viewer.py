"""The browser viewer in a real browser (issue 32): headless Chromium
driven by WebDriver loads the page a server serves on ``--http-addr``,
lists a session, receives and renders its frames, pauses and resumes it,
grabs a modal solid and a shell with the mouse, refuses a stranger and an
observer's driving, and decodes frames exactly as the server encoded them.

Chromium and its driver are Debian's (``chromium``, ``chromium-driver``),
which ``scripts/test`` installs; Selenium comes from PyPI
(``requirements-test.txt``). Every wait is bounded (WebDriverWait)."""

from __future__ import annotations

import base64
import io
import shutil
from pathlib import Path

import grpc
import numpy as np
import pytest
from conftest import ROOT, TIMEOUT, fixture, running_server
from PIL import Image
from selenium import webdriver
from selenium.common.exceptions import TimeoutException
from selenium.webdriver.chrome.options import Options
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait

from meshless import Client

OWNER = "owner-token-0123456789"
OBSERVER = "observer-token-0123456"
STRANGER = "stranger-token-012345"

MODAL_BEAM = (ROOT / "scenes" / "modal_beam.toml").read_text()


def _chromium() -> tuple[str, str]:
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    if not browser or not driver:
        raise FileNotFoundError(
            "the viewer's tests need Debian's chromium and chromium-driver: "
            "scripts/test installs them (apt-get install chromium chromium-driver)"
        )
    return browser, driver


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    binary, driver_path = _chromium()
    options = Options()
    options.binary_location = binary
    for argument in (
        "--headless=new",
        "--no-sandbox",
        "--disable-dev-shm-usage",
        "--window-size=1400,900",
        # WebGL2 without a GPU: Chromium's software rasteriser.
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
    ):
        options.add_argument(argument)
    downloads = tmp_path_factory.mktemp("downloads")
    options.add_experimental_option(
        "prefs", {"download.default_directory": str(downloads), "download.prompt_for_download": False}
    )
    driver = webdriver.Chrome(service=Service(driver_path), options=options)
    driver.set_script_timeout(TIMEOUT)
    driver.set_page_load_timeout(TIMEOUT)
    driver.downloads = downloads
    try:
        yield driver
    finally:
        driver.quit()


@pytest.fixture()
def viewer():
    with running_server("--http-addr", "127.0.0.1:0") as running:
        yield running


def until(driver, what: str, predicate, timeout: float = TIMEOUT):
    """Waits for ``predicate(driver)`` to be truthy; fails naming ``what``."""
    return WebDriverWait(driver, timeout, poll_frequency=0.05).until(
        predicate, message=f"timed out waiting for {what}"
    )


def js(driver, script: str, *args):
    return driver.execute_script(script, *args)


def open_page(driver, http: str, session: str | None = None, token: str | None = None) -> None:
    driver.get(f"http://{http}/" + (f"?session={session}" if session else ""))
    if token is not None:
        js(driver, "sessionStorage.setItem('meshless-token', arguments[0])", token)
        driver.refresh()
    until(driver, "the page to start", lambda d: js(d, "return document.body.dataset.ready") == "true")


def stats(driver) -> dict:
    return js(driver, "return {frames: meshless.stats.frames, step: meshless.stats.lastStep, errors: meshless.stats.errors}")


def canvas_pixels(driver) -> np.ndarray:
    png = driver.find_element(By.ID, "canvas").screenshot_as_png
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)


def state_of(client: Client, session_id: str) -> int:
    return client.get_session(session_id).status.state


def test_the_page_lists_a_session_and_renders_its_frames(viewer, browser):
    with Client(viewer.grpc_target) as client:
        session = client.create_session(fixture("python_tank"))
        # Paced, so that frames keep coming for the whole test.
        client.run(session.id, forever=True, realtime_factor=0.05)
        open_page(browser, viewer.http, session.id)

        row = until(
            browser,
            "the session in the list",
            lambda d: [r for r in d.find_elements(By.CSS_SELECTOR, "#sessions tbody tr") if r.get_attribute("data-id") == session.id],
        )[0]
        cells = [c.text for c in row.find_elements(By.TAG_NAME, "td")]
        assert session.id in cells[0]
        assert cells[2] == "fluid"
        assert cells[3] == str(session.particle_count)

        until(browser, "ten frames", lambda d: stats(d)["frames"] >= 10)
        first = canvas_pixels(browser)
        step = stats(browser)["step"]
        until(browser, "frames of later steps", lambda d: stats(d)["step"] >= step + 5)
        second = canvas_pixels(browser)

        background = first[5, 5]
        drawn = np.any(np.abs(first - background) > 8, axis=2).mean()
        assert drawn > 0.005, f"only {drawn:.2%} of the canvas is drawn"
        changed = np.any(np.abs(first - second) > 8, axis=2).mean()
        assert changed > 0.0005, f"the view did not change between steps {step} and later ({changed:.3%})"
        assert stats(browser)["errors"] == []


def test_pause_and_resume_from_the_page(viewer, browser):
    with Client(viewer.grpc_target) as client:
        session = client.create_session(fixture("python_tank"))
        client.run(session.id, forever=True, realtime_factor=0.05)
        open_page(browser, viewer.http, session.id)
        until(browser, "frames", lambda d: stats(d)["frames"] >= 3)

        browser.find_element(By.ID, "pause").click()
        until(browser, "the session paused", lambda d: state_of(client, session.id) == 3)
        until(browser, "the page to show it paused", lambda d: d.find_element(By.ID, "t-state").text.startswith("paused"))
        paused_at = client.get_session(session.id).status.step

        browser.find_element(By.ID, "resume").click()
        until(browser, "the session running again", lambda d: state_of(client, session.id) == 2)
        until(browser, "frames after the resume", lambda d: stats(d)["step"] > paused_at)
        assert stats(browser)["errors"] == []


def test_the_page_pulls_frames_as_fast_as_it_can(viewer, browser):
    """`meshless.pull(n)` (what scripts/viewer_screenshot.py --pull times)
    fetches the latest frame n times, decoding and showing each."""
    with Client(viewer.grpc_target) as client:
        session = client.create_session(fixture("python_tank"))
        client.step(session.id, 2)
        open_page(browser, viewer.http, session.id)
        until(browser, "a first frame", lambda d: stats(d)["frames"] >= 1)
        before = stats(browser)["frames"]
        rate = browser.execute_async_script("meshless.pull(arguments[0]).then(arguments[1], (e) => arguments[1](String(e)))", 5)
        assert isinstance(rate, (int, float)) and rate > 0, rate
        assert stats(browser)["frames"] == before + 5
        assert stats(browser)["step"] == client.get_session(session.id).status.step
        assert stats(browser)["errors"] == []


def test_frames_decode_in_the_page_as_the_server_encoded_them(viewer, browser):
    from meshless.v1 import frame_pb2, simulation_pb2

    with Client(viewer.grpc_target) as client:
        for scene in (fixture("python_tank"), MODAL_BEAM):
            session = client.create_session(scene)
            client.step(session.id, 3)
            reply = client.stub.NextFrame(
                simulation_pb2.NextFrameRequest(session_id=session.id, after=0, wait_ms=0),
                metadata=client.metadata,
                timeout=TIMEOUT,
            )
            assert reply.number >= 1 and reply.frame
            open_page(browser, viewer.http)
            decoded = js(
                browser,
                "return meshless.decodeFrameBase64(arguments[0])",
                base64.b64encode(reply.frame).decode(),
            )
            frame = frame_pb2.Frame.FromString(reply.frame)
            assert decoded["header"]["session_id"] == session.id
            assert decoded["header"]["step"] == frame.header.step == 3
            assert decoded["header"]["time"] == frame.header.time
            assert decoded["header"]["particle_count"] == frame.header.particle_count
            assert [f["kind"] for f in decoded["fields"]] == [f.kind for f in frame.fields]
            for mine, theirs in zip(decoded["fields"], frame.fields):
                dtype = "<u4" if theirs.scalar == frame_pb2.SCALAR_TYPE_U32 else "<f4"
                expected = np.frombuffer(theirs.data, dtype=dtype)
                got = np.asarray(mine["values"], dtype=np.float64)
                assert mine["components"] == theirs.components
                np.testing.assert_array_equal(got, expected.astype(np.float64))
            surfaces = decoded["surfaces"]
            assert len(surfaces) == len(frame.solid_surfaces)
            for mine, theirs in zip(surfaces, frame.solid_surfaces):
                np.testing.assert_array_equal(
                    np.asarray(mine["vertices"]), np.frombuffer(theirs.mesh.vertices, "<f4").astype(np.float64)
                )
                np.testing.assert_array_equal(
                    np.asarray(mine["triangles"]), np.frombuffer(theirs.mesh.triangles, "<u4")
                )
            client.delete_session(session.id)


# The Python tests' small shell (a 40 cm x 20 cm sheet clamped along its
# short edge at x = 0, hanging under gravity) under linear mechanics, so
# that a step is one solve.
SHELL_SHEET = fixture("small_shell") + 'mechanics = "linear"\n'


@pytest.mark.parametrize(
    ("scene", "reach", "tolerance"),
    [
        # The node at the beam's free end's upper edge; it reaches its
        # target within 2 mm (the beam is 27 cm long; the drag moves the
        # target by several centimetres).
        pytest.param(MODAL_BEAM, "p[3 * i] + p[3 * i + 1]", 0.002, id="modal_solid"),
        # The node on the sheet nearest its free edge (x = 0.4 m, |z| <=
        # 0.1 m): the quadtree's nodes past its edges are not on the
        # surface, and a grab there holds the surface's point nearest them.
        # A shell's node is a coefficient of its moving-least-squares fit,
        # not a point of the surface: the grab holds the surface's point
        # at the node's rest position, and the node itself comes within
        # 6 mm (3 mm when the drag lifts the 40 cm sheet's edge 9 cm).
        pytest.param(
            SHELL_SHEET,
            "p[3 * i] < 0.4 && Math.abs(p[3 * i + 2]) < 0.1 ? p[3 * i] : -1",
            0.006,
            id="shell",
        ),
    ],
)
def test_dragging_a_body_grabs_it(viewer, browser, scene, reach, tolerance):
    """A scripted mouse drag on a modal beam's tip and on a hanging
    sheet's free edge: the page grabs the node under the pointer (its rest
    position from `ModalModes` or `ShellNodes`), moves the grab's target
    with the mouse, and the frames show the node at the target; releasing
    the button lets go."""
    with Client(viewer.grpc_target) as client:
        session = client.create_session(scene)
        client.run(session.id, forever=True, realtime_factor=1.0)
        open_page(browser, viewer.http, session.id)
        until(browser, "frames", lambda d: stats(d)["frames"] >= 3)
        # Paused, and the page showing the session's last step, so that the
        # node the test aims at is where the page picks (a swinging sheet
        # moves centimetres between frames, and under load the page's pick
        # can come frames after the aim). Constraints edit while paused;
        # the run resumes once the drag has set its target.
        client.pause(session.id)
        until(browser, "the session paused", lambda d: state_of(client, session.id) == 3)
        paused_at = client.get_session(session.id).status.step
        until(browser, "the page at the paused step", lambda d: stats(d)["step"] == paused_at)

        # The node farthest along `reach`, and where it is on screen.
        tip = js(
            browser,
            """
            const p = meshless.view.positions;
            const reach = (i) => """
            + reach
            + """;
            let best = 0;
            for (let i = 0; i < p.length / 3; i++) {
              if (reach(i) > reach(best)) best = i;
            }
            const at = meshless.project([p[3 * best], p[3 * best + 1], p[3 * best + 2]]);
            const rect = document.getElementById('canvas').getBoundingClientRect();
            return {
              index: best, x: at.x, y: at.y, width: rect.width, height: rect.height,
              position: [p[3 * best], p[3 * best + 1], p[3 * best + 2]],
            };
            """,
        )
        canvas = browser.find_element(By.ID, "canvas")
        drag = ActionChains(browser)
        drag.move_to_element_with_offset(canvas, int(tip["x"] - tip["width"] / 2), int(tip["y"] - tip["height"] / 2))
        drag.click_and_hold()
        for _ in range(4):
            drag.move_by_offset(0, -15)
        drag.perform()

        def grab_target(d):
            for c in js(d, "return meshless.view.constraints"):
                if c["name"] == "grab" and c.get("grab", {}).get("position"):
                    return c["grab"]["position"]
            return None

        until(browser, "the grab constraint", grab_target)
        # The last move's edit lands after the first: wait for the page to
        # have none in flight, then read the target it left, from the
        # server (the page's own list is read again after each edit and
        # may still hold an earlier one).
        until(browser, "the edits to settle", lambda d: js(d, "return !meshless.editing"))
        grabs = [c.grab for c in client.list_constraints(session.id) if c.name == "grab"]
        assert len(grabs) == 1 and grabs[0].HasField("position"), grabs
        target = np.array([grabs[0].position.x, grabs[0].position.y, grabs[0].position.z])
        # The node the page grabbed: the one at the grab's rest point. It
        # need not be the node picked above: nodes in front of and behind
        # it can project to nearly the same pixel, and the page picks the
        # nearer to the pointer as the body moves.
        point = [grabs[0].point.x, grabs[0].point.y, grabs[0].point.z]
        index = js(
            browser,
            """
            const r = meshless.view.rest.get(arguments[0]);
            let best = 0, nearest = Infinity;
            for (let i = 0; i < r.length / 3; i++) {
              const d = (r[3 * i] - arguments[1][0]) ** 2 + (r[3 * i + 1] - arguments[1][1]) ** 2
                + (r[3 * i + 2] - arguments[1][2]) ** 2;
              if (d < nearest) { nearest = d; best = i; }
            }
            return best;
            """,
            grabs[0].system,
            point,
        )
        moved = np.linalg.norm(target - np.array(tip["position"]))
        assert moved > 0.01, f"the drag moved the target only {moved:.4f} m"

        def distance(d):
            p = js(d, "const p = meshless.view.positions; return [p[3*arguments[0]], p[3*arguments[0]+1], p[3*arguments[0]+2]]", index)
            return float(np.linalg.norm(np.array(p) - target))

        client.resume(session.id)
        seen = []

        def arrived(d):
            seen.append(distance(d))
            return seen[-1] < tolerance

        try:
            until(browser, "the grabbed node at its target", arrived)
        except TimeoutException:
            pytest.fail(
                f"node {index} (rest {point}) stayed {min(seen):.4f}-{max(seen):.4f} m from the grab's "
                f"target {target.tolist()} (last {seen[-1]:.4f} m; tolerance {tolerance} m)"
            )
        names = [c.name for c in client.list_constraints(session.id)]
        assert names == ["grab"]

        ActionChains(browser).release().perform()
        until(browser, "the grab released", lambda d: client.list_constraints(session.id) == [])
        assert stats(browser)["errors"] == []


def test_a_stranger_sees_nothing_and_an_observer_cannot_drive(tmp_path, browser):
    tokens = tmp_path / "tokens"
    tokens.write_text(f"owner {OWNER}\nobserver {OBSERVER}\nstranger {STRANGER}\n")
    with running_server("--tokens-file", str(tokens), "--http-addr", "127.0.0.1:0") as server:
        with Client(server.grpc_target, token=OWNER) as owner:
            session = owner.create_session(fixture("python_tank"), observers=["observer"])
            owner.run(session.id, forever=True, realtime_factor=0.05)

            # No token: the page asks for one and shows nothing.
            open_page(browser, server.http, session.id, token="")
            until(browser, "the token request", lambda d: "needs a token" in d.find_element(By.ID, "banner").text)
            assert browser.find_elements(By.CSS_SELECTOR, "#sessions tbody tr") == []
            assert stats(browser)["frames"] == 0

            # A stranger's token: no session listed, none readable.
            open_page(browser, server.http, token=STRANGER)
            assert browser.find_elements(By.CSS_SELECTOR, "#sessions tbody tr") == []
            js(browser, "return meshless.select(arguments[0])", session.id)
            until(browser, "the refusal", lambda d: "PERMISSION_DENIED" in " ".join(stats(d)["errors"]))
            assert stats(browser)["frames"] == 0

            # The observer sees it live but cannot pause it.
            open_page(browser, server.http, session.id, token=OBSERVER)
            until(browser, "the observer's frames", lambda d: stats(d)["frames"] >= 3)
            browser.find_element(By.ID, "pause").click()
            until(browser, "the observer refused", lambda d: "not allowed" in d.find_element(By.ID, "banner").text)
            assert state_of(owner, session.id) == 2, "the session still runs"


def test_create_snapshot_restore_and_delete_from_the_page(viewer, browser):
    with Client(viewer.grpc_target) as client:
        open_page(browser, viewer.http)
        select = browser.find_element(By.ID, "scene-select")
        select.send_keys("dam_break_2d")
        browser.find_element(By.ID, "create-shipped").click()
        until(browser, "the new session", lambda d: len(client.list_sessions()) == 1)
        created = client.list_sessions()[0]
        until(browser, "its first frame", lambda d: stats(d)["frames"] >= 1)

        browser.find_element(By.ID, "step").click()
        until(browser, "the step", lambda d: client.get_session(created.id).status.step == 1)

        browser.find_element(By.ID, "snapshot").click()
        snapshot = until(
            browser,
            "the snapshot download",
            lambda d: [p for p in Path(d.downloads).glob("*.snapshot") if p.stat().st_size > 0],
        )[0]
        browser.find_element(By.ID, "restore-file").send_keys(str(snapshot))
        until(browser, "the restored session", lambda d: len(client.list_sessions()) == 2)
        restored = [s for s in client.list_sessions() if s.id != created.id][0]
        assert restored.status.step == 1 and restored.name == created.name

        until(browser, "the page to show the restored session", lambda d: js(d, "return meshless.view && meshless.view.id") == restored.id)
        browser.find_element(By.ID, "delete").click()
        until(browser, "the deletion", lambda d: [s.id for s in client.list_sessions()] == [created.id])
        with pytest.raises(Exception) as gone:
            client.get_session(restored.id)
        assert getattr(gone.value, "code", None) == grpc.StatusCode.NOT_FOUND


def test_design_handles_drag_and_the_optimiser_runs_from_the_page(viewer, browser):
    """Design mode: a click on the column's top corner adds a handle
    there, a drag moves its target, and *optimise shape* runs the
    optimiser on the session's solid with its progress shown; the designed
    shape moves the handle's particle towards the target."""
    with Client(viewer.grpc_target) as client:
        session = client.create_session(fixture("small_column"))
        open_page(browser, viewer.http, session.id)
        until(browser, "the first frame", lambda d: stats(d)["frames"] >= 1)
        browser.find_element(By.ID, "design-mode").click()

        corner = js(
            browser,
            """
            const p = meshless.view.positions;
            let best = 0;
            for (let i = 0; i < p.length / 3; i++) {
              if (p[3 * i + 2] + p[3 * i] > p[3 * best + 2] + p[3 * best]) best = i;
            }
            const at = meshless.project([p[3 * best], p[3 * best + 1], p[3 * best + 2]]);
            const rect = document.getElementById('canvas').getBoundingClientRect();
            return {index: best, x: at.x, y: at.y, width: rect.width, height: rect.height,
                    position: [p[3 * best], p[3 * best + 1], p[3 * best + 2]]};
            """,
        )
        canvas = browser.find_element(By.ID, "canvas")
        drag = ActionChains(browser)
        drag.move_to_element_with_offset(canvas, int(corner["x"] - corner["width"] / 2), int(corner["y"] - corner["height"] / 2))
        drag.click_and_hold()
        for _ in range(4):
            drag.move_by_offset(12, -12)
        drag.release()
        drag.perform()
        until(browser, "the edits to settle", lambda d: js(d, "return !meshless.editing"))
        handles = [c for c in client.list_constraints(session.id) if c.WhichOneof("kind") == "handle"]
        assert [h.handle.points.particles.indices[0] for h in handles] == [corner["index"]]
        target = handles[0].handle.target.positions.positions[0]
        target = np.array([target.x, target.y, target.z])
        assert np.linalg.norm(target - np.array(corner["position"])) > 0.02

        browser.find_element(By.ID, "optimise").click()
        until(
            browser,
            "the optimiser's result",
            lambda d: d.find_element(By.ID, "design-progress").text.startswith(("converged", "stopped")),
            timeout=120,
        )
        design = client.get_design(session.id)
        rest = design.rest_positions.reshape(-1, 3)
        shaped = rest + design.displacements.reshape(-1, rest.shape[0], 3)[0]
        # The design particle nearest the handle moved well towards the
        # handle's target (the rigidity energy holds the rest back).
        nearest = int(np.argmin(np.linalg.norm(rest - np.array(corner["position"]), axis=1)))
        before = np.linalg.norm(rest[nearest] - target)
        after = np.linalg.norm(shaped[nearest] - target)
        assert after < 0.6 * before, f"{before:.4f} m from the target before, {after:.4f} m after"
        # The page drew the same design.
        assert js(browser, "return meshless.view.design.rest.length") == rest.size
        assert stats(browser)["errors"] == []
