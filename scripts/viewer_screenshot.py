"""Screenshots the browser viewer showing a scene live, and measures what
the page spends on each frame.

Starts the real server with its viewer (`--http-addr`), creates a session
from a scene file, runs it, opens the page in headless Chromium (Debian's
`chromium` and `chromium-driver`, as the viewer's tests), waits for
`--frames` frames, saves a PNG of the window and prints the page's own
timings: frames received per second, and per frame the decoding of the
message and the upload of its particles to the GPU (`performance.now()`
around each, in the page). With `--pull N` it then measures the page's
capacity apart from the session's pace: the page fetches the latest frame
N times in a row, decoding and uploading each as a new one, and the
frames per second it reached are printed with the same timings.

    .venv/bin/python scripts/viewer_screenshot.py scenes/dam_break.toml \\
        --until 0.6 --frames 60 -o docs/figures/viewer.png

Needs the debug server (`cargo build --workspace --bins`) or
MESHLESS_SERVER_BIN, and the Python package (`pip install ./client/python`).
"""

from __future__ import annotations

import argparse
import http.client
import os
import queue
import shutil
import statistics
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

from selenium import webdriver
from selenium.webdriver.chrome.options import Options
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait

from meshless import Client
from meshless.v1 import simulation_pb2

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT = 60.0


def start_server(priority: str) -> tuple[subprocess.Popen, dict[str, str]]:
    binary = os.environ.get("MESHLESS_SERVER_BIN") or str(ROOT / "target" / "debug" / "meshless-server")
    process = subprocess.Popen(
        [binary, "--grpc-addr", "127.0.0.1:0", "--zenoh-listen", "tcp/127.0.0.1:0", "--http-addr", "127.0.0.1:0",
         "--http-priority", priority],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "MESHLESS_LOG": "warn"},
    )
    lines: queue.Queue[str] = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in process.stdout], daemon=True).start()
    while True:
        line = lines.get(timeout=TIMEOUT)
        if line.startswith("meshless-server ready "):
            return process, dict(p.split("=", 1) for p in line.split()[2:])


def browser(width: int, height: int) -> webdriver.Chrome:
    binary = shutil.which("chromium")
    driver = shutil.which("chromedriver")
    if not binary or not driver:
        sys.exit("needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)")
    options = Options()
    options.binary_location = binary
    for argument in (
        "--headless=new",
        "--no-sandbox",
        "--disable-dev-shm-usage",
        f"--window-size={width},{height}",
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
    ):
        options.add_argument(argument)
    return webdriver.Chrome(service=Service(driver), options=options)


def fetch_outside(address: str, session_id: str, count: int) -> list[float]:
    """Times `count` NextFrame calls over gRPC-web on one HTTP/1.1
    connection, as the page makes them, each answer read whole; ms."""
    host, port = address.rsplit(":", 1)
    body = simulation_pb2.NextFrameRequest(session_id=session_id, after=0, wait_ms=0).SerializeToString()
    framed = b"\0" + struct.pack(">I", len(body)) + body
    headers = {"content-type": "application/grpc-web+proto", "x-grpc-web": "1"}
    connection = http.client.HTTPConnection(host, int(port), timeout=TIMEOUT)
    times = []
    try:
        for _ in range(count):
            started = time.perf_counter()
            connection.request("POST", "/meshless.v1.Simulation/NextFrame", body=framed, headers=headers)
            answer = connection.getresponse()
            data = answer.read()
            times.append((time.perf_counter() - started) * 1000.0)
            if answer.status != 200 or len(data) < 5:
                sys.exit(f"NextFrame over gRPC-web answered HTTP {answer.status} with {len(data)} bytes")
    finally:
        connection.close()
    return times


def report(stats: dict) -> None:
    """Prints the median, p95 and largest of the page's timings per frame."""
    decode, upload, shown = stats["decodeMs"], stats["uploadMs"], stats["showMs"]
    both = [a + b for a, b in zip(decode, upload)]
    rows = (
        ("fetch", stats.get("fetchMs", [])),
        ("decode", decode),
        ("upload to GPU", upload),
        ("decode + upload", both),
        ("whole frame", [a + b for a, b in zip(decode, shown)]),
    )
    for name, values in rows:
        if values:
            q = statistics.quantiles(values, n=20, method="inclusive") if len(values) >= 2 else [values[0]] * 19
            print(f"  {name:16} median {statistics.median(values):6.2f} ms  p95 {q[18]:6.2f} ms  max {max(values):6.2f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", type=Path, help="scene TOML file")
    parser.add_argument("--until", type=float, default=0.5, help="simulated seconds to run")
    parser.add_argument("--realtime-factor", type=float, default=None, help="pace the run (simulated s per s)")
    parser.add_argument("--frames", type=int, default=30, help="frames the page receives before the shot")
    parser.add_argument("--field", default="FIELD_KIND_VELOCITY", help="field to colour by")
    parser.add_argument("--pull", type=int, default=0, help="then fetch the latest frame this many times as fast as the page can")
    parser.add_argument("--warmup", type=int, default=10,
                        help="frames pulled, untimed, before those --pull times (the page's first large fetches stall once)")
    parser.add_argument("-o", "--output", type=Path, default=Path("viewer.png"))
    parser.add_argument("--size", default="1400x860", help="window size, WIDTHxHEIGHT")
    parser.add_argument("--http-priority", choices=("idle", "normal"), default="idle",
                        help="the server's --http-priority: when its viewer thread runs")
    args = parser.parse_args()

    width, height = (int(v) for v in args.size.split("x"))
    server, addresses = start_server(args.http_priority)
    driver = None
    try:
        with Client(addresses["grpc"]) as client:
            session = client.create_session(args.scene)
            driver = browser(width, height)
            driver.set_script_timeout(TIMEOUT)
            driver.get(f"http://{addresses['http']}/?session={session.id}")
            wait = WebDriverWait(driver, TIMEOUT, poll_frequency=0.05)
            wait.until(lambda d: d.execute_script("return document.body.dataset.ready") == "true")
            wait.until(lambda d: d.execute_script("return meshless.stats.frames") >= 1)
            started = time.monotonic()
            client.run(session.id, until=args.until, realtime_factor=args.realtime_factor)
            wait.until(
                lambda d: d.execute_script("return meshless.stats.frames") >= args.frames
                or client.get_session(session.id).status.state == 4,
                message="the page received too few frames",
            )
            elapsed = time.monotonic() - started
            select = driver.find_element(By.ID, "field-select")
            if driver.execute_script(f"return [...arguments[0].options].some(o => o.value === '{args.field}')", select):
                driver.execute_script(f"arguments[0].value = '{args.field}'; arguments[0].dispatchEvent(new Event('change'))", select)
            args.output.parent.mkdir(parents=True, exist_ok=True)
            driver.save_screenshot(str(args.output))
            stats = driver.execute_script("return meshless.stats")
            print(f"{session.name}: {session.particle_count} particles, {stats['frames']} frames in {elapsed:.2f} s "
                  f"({stats['frames'] / elapsed:.1f} frames/s received)")
            report(stats)
            if args.pull > 0:
                # Paused, the session adds no frame of its own: every frame
                # timed from here on is a pulled one.
                if client.get_session(session.id).status.state == 2:
                    try:
                        client.pause(session.id)
                    except Exception:
                        # Refused only if the run ended in between.
                        if client.get_session(session.id).status.state == 2:
                            raise
                pull = "meshless.pull(arguments[0]).then(arguments[1], (e) => arguments[1](String(e)))"
                if args.warmup > 0:
                    warm = driver.execute_async_script(pull, args.warmup)
                    if isinstance(warm, str):
                        sys.exit(f"the page could not pull frames: {warm}")
                rate = driver.execute_async_script(pull, args.pull)
                if isinstance(rate, str):
                    sys.exit(f"the page could not pull frames: {rate}")
                stats = driver.execute_script("return meshless.stats")
                print(f"pulled {args.pull} frames: {rate:.1f} frames/s fetched, decoded and uploaded")
                taken = min(args.pull, len(stats["decodeMs"]))
                report({key: stats[key][-taken:] for key in ("fetchMs", "decodeMs", "uploadMs", "showMs")})
                # The same call from outside the browser: the server's part
                # and the loopback's, which the page's fetch includes.
                times = fetch_outside(addresses["http"], session.id, args.pull)
                print(
                    f"the same NextFrame over gRPC-web from Python: median {statistics.median(times):.2f} ms, "
                    f"max {max(times):.2f} ms"
                )
            if stats["errors"]:
                sys.exit(f"the page reported errors: {stats['errors']}")
            print(f"wrote {args.output}")
    finally:
        if driver is not None:
            driver.quit()
        server.terminate()
        server.wait(timeout=TIMEOUT)


if __name__ == "__main__":
    main()
