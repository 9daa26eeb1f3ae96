"""``jellysim view`` served in a thread, and plain requests to it: shared by the viewer's tests."""

from __future__ import annotations

import http.client
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

from jellysim.view import serve
from jellysim.view.server import TOKEN_HEADER, ViewLimits, ViewServer


@contextmanager
def serving(folder: str | Path, limits: ViewLimits | None = None) -> Iterator[ViewServer]:
    """``serve`` in a thread on a free port; yields the listening server."""
    started = threading.Event()
    box: dict[str, object] = {}

    def ready(server: ViewServer) -> None:
        box["server"] = server
        started.set()

    def run() -> None:
        try:
            serve(folder, port=0, browser=False, ready=ready, limits=limits)
        except BaseException as err:  # handed to the test
            box["error"] = err
            started.set()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    assert started.wait(60)
    if "error" in box:
        raise box["error"]  # type: ignore[misc]
    server = box["server"]
    assert isinstance(server, ViewServer)
    try:
        yield server
    finally:
        server.shutdown()
        thread.join(10)


class Answer(NamedTuple):
    status: int
    headers: http.client.HTTPMessage
    body: bytes


def address(server: ViewServer) -> tuple[str, int]:
    host, port = server.server_address[:2]
    return str(host), int(port)


def ask(
    server: ViewServer,
    path: str,
    headers: dict[str, str] | None = None,
    token: bool = True,
    source: str | None = None,
) -> Answer:
    """A GET of ``path`` sent exactly as written (no client-side normalising), with the
    session's token unless ``token`` is False, from the address ``source`` if given."""
    host, port = address(server)
    connection = http.client.HTTPConnection(
        host, port, timeout=30, source_address=None if source is None else (source, 0)
    )
    sent = {TOKEN_HEADER: server.token} if token else {}
    try:
        connection.request("GET", path, headers={**sent, **(headers or {})})
        response = connection.getresponse()
        return Answer(response.status, response.headers, response.read())
    finally:
        connection.close()


def status(server: ViewServer, path: str, headers: dict[str, str] | None = None) -> int:
    return ask(server, path, headers).status


def get(server: ViewServer, path: str) -> bytes:
    """The body of a GET of ``path`` with the token; fails on anything but 200."""
    answer = ask(server, path)
    assert answer.status == 200, (path, answer.status, answer.body[:200])
    return answer.body
