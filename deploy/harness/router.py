"""A zenoh router for the local topology: zenoh's own router (the same
routing code as zenohd, from the eclipse-zenoh package) with
deploy/config/zenohd.json5's settings, listening on the TLS endpoint given
with the certificate and key given, until SIGTERM.

    python deploy/harness/router.py tls/127.0.0.1:7447 CERT KEY
"""

import json
import signal
import sys
import threading
from pathlib import Path

import zenoh

CONFIG = Path(__file__).resolve().parents[1] / "config" / "zenohd.json5"


def main() -> None:
    endpoint, cert, key = sys.argv[1:]
    config = zenoh.Config.from_file(str(CONFIG))
    config.insert_json5("listen/endpoints", json.dumps([endpoint]))
    config.insert_json5("transport/link/tls/listen_certificate", json.dumps(cert))
    config.insert_json5("transport/link/tls/listen_private_key", json.dumps(key))
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    with zenoh.open(config):
        stop.wait()


if __name__ == "__main__":
    main()
