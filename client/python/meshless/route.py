"""Which replica holds a session, from its id alone.

A server started with ``--server-name NAME`` makes session ids ``NAME-``
followed by 16 hex digits; :func:`route` fills a target template such as
``"{server}.meshless-replicas:50051"`` with that name, so each call goes to
the replica that holds its session (the Rust client's ``Route``).
"""

from __future__ import annotations

import re

_NAMED = re.compile(r"^(.+)-[0-9a-fA-F]{16}$")
_MAX_TEMPLATE = 512


def server_of(session_id: str) -> str | None:
    """The name of the server that made ``session_id``, or ``None`` for an
    id of an unnamed server."""
    match = _NAMED.match(session_id)
    return match.group(1) if match else None


def route(template: str, session_id: str) -> str:
    """The target of the replica that holds ``session_id``: ``template``
    with its one ``{server}`` replaced.

    Raises ``ValueError`` for a template without exactly one ``{server}``
    or an id that names no server.
    """
    if len(template) > _MAX_TEMPLATE or template.count("{server}") != 1:
        raise ValueError(
            "a route template holds {server} once, e.g. "
            f"'{{server}}.meshless-replicas:50051' (at most {_MAX_TEMPLATE} characters)"
        )
    server = server_of(session_id)
    if server is None:
        raise ValueError(
            f"session id {session_id[:64]!r} names no server (ids of a server with "
            "--server-name are NAME- and 16 hex digits); connect to its server directly"
        )
    return template.replace("{server}", server)
