"""``jellysim view`` cannot be turned against its machine (issue 24; docs/viewer.md, "Security"):
answers bounded in size and refused before anything is built, a request budget per client and
in all, idle connections closed, a cap on open connections, and data only for the viewer's own
page (the session's token, not from another site)."""

from __future__ import annotations

import http.client
import socket
import threading
import time
import tracemalloc
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import pytest
from viewing import address, ask, get, serving, status

import jellysim
from jellysim.view.server import TOKEN_HEADER, FrameRequest, ViewLimits, ViewServer

FACTOR = 50  # drawn tentacles per simulated one: the brown jelly's largest
SIMULATED, PARTICLES = 6, 90  # brown-jelly's marginal tentacles (0.9 m since issue 25's retune)


@pytest.fixture(scope="module")
def brown(tmp_path_factory: pytest.TempPathFactory) -> Iterator[jellysim.Result]:
    # brown-jelly's marginal tentacles alone (its oral arms are a second group)
    folder = tmp_path_factory.mktemp("brown")
    scene = jellysim.load_scene("brown-jelly", {"duration": 0.6, "fps": 20.0}).group_scene(0)
    result = jellysim.run(scene, folder)
    yield result
    result.close()


@pytest.fixture(scope="module")
def view(brown: jellysim.Result) -> Iterator[ViewServer]:
    with serving(brown.folder) as server:
        yield server


def tentacle_bytes(frames: int) -> int:
    return frames * SIMULATED * FACTOR * PARTICLES * 3 * 4


@contextmanager
def traced() -> Iterator[dict[str, int]]:
    """The peak of memory allocated by Python and NumPy (every thread) inside the block."""
    box = {"peak": 0}
    tracemalloc.start()
    try:
        yield box
        box["peak"] = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_an_answer_over_the_limit_is_refused_before_anything_is_built(
    brown: jellysim.Result, view: ViewServer
) -> None:
    assert brown.scene.tentacles.particles == PARTICLES
    whole = tentacle_bytes(brown.frames)  # 13 frames: 4.2 MB
    limit = tentacle_bytes(4) + 100  # four frames fit
    query = f"/frames?part=tentacles&start=0&count={brown.frames}&interpolation={FACTOR}"
    with serving(brown.folder, ViewLimits(max_response_bytes=limit)) as small:
        with traced() as refused:
            answer = ask(small, query)
        assert answer.status == 413
        message = answer.body.decode("utf-8")
        assert message.count("\n") == 1 and f"{whole} bytes" in message and str(limit) in message
        # The most frames under the limit pass; one more is refused.
        ok = f"/frames?part=tentacles&start=0&count=4&interpolation={FACTOR}"
        assert len(get(small, ok)) == tentacle_bytes(4)
        one_more = f"/frames?part=tentacles&start=0&count=5&interpolation={FACTOR}"
        assert status(small, one_more) == 413
        # Static arrays are under the same limit.
        with serving(brown.folder, ViewLimits(max_response_bytes=100)) as tiny:
            assert status(tiny, "/bell-faces") == 413
    # The same request answered where the limit allows it: tracemalloc sees the arrays it takes
    # (several times the answer), so the refusal's small peak means nothing was built.
    with traced() as answered:
        assert len(get(view, query)) == whole
    assert answered["peak"] > 3 * whole
    assert refused["peak"] < whole // 10, refused


def test_the_answer_size_is_planned_exactly(brown: jellysim.Result, view: ViewServer) -> None:
    # The size checked against the limit is the size sent, for every part and factor.
    data = view.data
    for request in (
        FrameRequest("bell", 0, brown.frames, 1),
        FrameRequest("tentacles", 2, 9, 1),
        FrameRequest("tentacles", 5, 6, 7),
    ):
        assert len(data.chunk(request)) == data.chunk_bytes(request)
    assert len(data.bell_faces()) == data.bell_faces_bytes()


def test_data_requests_need_the_sessions_token(view: ViewServer) -> None:
    token = view.token
    for path in ("/meta.json", "/bell-faces", "/frames?part=bell&start=0&count=1"):
        assert ask(view, path).status == 200
        refused = ask(view, path, token=False)
        assert refused.status == 403 and TOKEN_HEADER.encode() in refused.body
        assert ask(view, path, {TOKEN_HEADER: token[:-1]}).status == 403
        assert ask(view, path, {TOKEN_HEADER: token + "x"}).status == 403
    # The page itself only at the address printed; its code and three.js stay open.
    assert ask(view, f"/?token={token}", token=False).status == 200
    for path in ("/", "/?token=", f"/?token={token[:-1]}", f"/?other={token}"):
        assert ask(view, path, token=False).status == 403, path
    assert ask(view, "/static/viewer.js", token=False).status == 200
    assert ask(view, "/vendor/three/three.module.js", token=False).status == 200
    # A new session, a new token.
    with serving(view.data.result.folder) as other:
        assert other.token != token and len(other.token) >= 40
        assert status(other, "/meta.json", {TOKEN_HEADER: token}) == 403


def test_requests_from_another_site_are_refused(view: ViewServer) -> None:
    host, port = address(view)
    own = f"http://{host}:{port}"
    assert status(view, "/meta.json", {"Origin": own, "Sec-Fetch-Site": "same-origin"}) == 200
    assert status(view, "/meta.json", {"Sec-Fetch-Site": "none"}) == 200  # typed by the user
    for headers in (
        {"Origin": "http://evil.example"},
        {"Origin": "null"},
        {"Origin": f"http://localhost:{port}"},  # another origin, though the same machine
        {"Sec-Fetch-Site": "cross-site"},
        {"Sec-Fetch-Site": "same-site"},  # another port of 127.0.0.1
        {"Origin": own, "Sec-Fetch-Site": "cross-site"},
    ):
        answer = ask(view, "/frames?part=bell&start=0&count=1", headers)
        assert answer.status == 403, headers
        assert answer.body.startswith(b"refused: ") and answer.body.count(b"\n") == 1
    # A page elsewhere may send the token header only after asking (a CORS preflight): no answer.
    connection = http.client.HTTPConnection(*address(view), timeout=30)
    try:
        connection.request("OPTIONS", "/meta.json", headers={"Origin": "http://evil.example"})
        preflight = connection.getresponse()
        assert preflight.status == 501
        assert preflight.getheader("Access-Control-Allow-Origin") is None
    finally:
        connection.close()


def test_the_request_budget_per_client_and_in_all(
    view: ViewServer, monkeypatch: pytest.MonkeyPatch
) -> None:
    limits = ViewLimits(requests_per_client=2, data_requests=3)
    with serving(view.data.result.folder, limits) as server:
        entered = threading.Semaphore(0)
        release = threading.Event()
        chunk = server.data.chunk

        def slow_chunk(request: FrameRequest) -> bytes:
            entered.release()
            assert release.wait(30)
            return chunk(request)

        monkeypatch.setattr(server.data, "chunk", slow_chunk)
        path = "/frames?part=bell&start=0&count=2"
        answers: list[int] = []

        def in_background(source: str) -> threading.Thread:
            thread = threading.Thread(
                target=lambda: answers.append(ask(server, path, source=source).status)
            )
            thread.start()
            assert entered.acquire(timeout=30)  # it is being answered
            return thread

        running = [in_background("127.0.0.1"), in_background("127.0.0.1")]
        busy = ask(server, path, source="127.0.0.1")  # a third from the same client
        assert busy.status == 429 and busy.headers["Retry-After"] == "1"
        assert busy.body.count(b"\n") == 1 and b"at most 2" in busy.body
        running.append(in_background("127.0.0.2"))  # another client has its own two
        assert ask(server, path, source="127.0.0.3").status == 429  # but 3 in all
        assert server.budget.refused == 2
        release.set()
        for thread in running:
            thread.join(30)
        assert answers == [200, 200, 200]
        assert ask(server, path, source="127.0.0.1").status == 200  # the slots are free again


def _threads() -> int:
    """The server's connection threads alive now."""
    return sum("process_request_thread" in thread.name for thread in threading.enumerate())


def _wait_for(condition: Callable[[], bool], seconds: float = 10.0) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def test_idle_connections_are_closed(view: ViewServer) -> None:
    with serving(view.data.result.folder, ViewLimits(idle_timeout=1.0)) as server:
        before = _threads()
        silent = socket.create_connection(address(server), timeout=10)
        half = socket.create_connection(address(server), timeout=10)
        half.sendall(b"GET /static/style.css HTTP/1.1\r\nHost: 127.0.0.1\r\n")  # never ended
        kept = socket.create_connection(address(server), timeout=10)
        kept.sendall(b"GET /static/style.css HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")  # keep-alive
        _wait_for(lambda: server.open_connections == 3)
        assert _threads() <= before + 3
        started = time.monotonic()
        assert silent.recv(1024) == b""  # closed by the server
        assert half.recv(1024) == b""
        answer = b""
        while chunk := kept.recv(65536):  # the answer, then the close
            answer += chunk
        assert answer.startswith(b"HTTP/1.1 200")
        assert 0.5 < time.monotonic() - started < 5.0
        _wait_for(lambda: server.open_connections == 0 and _threads() <= before)
        for connection in (silent, half, kept):
            connection.close()


def test_connections_beyond_the_cap_are_refused_without_a_thread(view: ViewServer) -> None:
    with serving(view.data.result.folder, ViewLimits(connections=4)) as server:
        before = _threads()
        held = [socket.create_connection(address(server), timeout=10) for _ in range(4)]
        _wait_for(lambda: server.open_connections == 4)
        extra = [socket.create_connection(address(server), timeout=10) for _ in range(40)]
        for connection in extra:
            refusal = b""
            while chunk := connection.recv(1024):
                refusal += chunk
            assert refusal.startswith(b"HTTP/1.1 503") and b"Retry-After: 1" in refusal
            connection.close()
        assert server.open_connections == 4 and _threads() <= before + 4
        for connection in held:
            connection.close()
        _wait_for(lambda: server.open_connections == 0)
        assert status(server, "/meta.json") == 200  # served again once they are gone
