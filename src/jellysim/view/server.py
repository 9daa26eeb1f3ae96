"""The viewer's HTTP server: Python's standard library only (docs/viewer.md, "Architecture").

Routes (GET only; anything else is 404, so no path reaches the file system but these):

- ``/`` the page, ``/static/NAME`` its files (those directly in ``static/``, listed at start);
- ``/vendor/three/{three.module.js, three.core.js, OrbitControls.js}`` from the npm package;
- ``/meta.json`` what the page needs to know about the result (:meth:`ResultData.meta`);
- ``/bell-faces`` uint32 (M, 3), ``/fluid-kinds`` uint8 (N,);
- ``/frames?part=bell|tentacles|fluid&start=S&count=C[&interpolation=N]`` float32 frames
  S to S + C - 1: bell (C, V, 3), drawn tentacles (C, T N, P, 3), fluid (C, N, 3) with the
  particles that left the domain as NaN. Binary bodies are little-endian, C order, in metres.
"""

from __future__ import annotations

import base64
import hashlib
import ipaddress
import json
import os
import re
import socket
import sys
import threading
import webbrowser
from collections.abc import Callable
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

import numpy as np

from jellysim import fields
from jellysim.errors import InputError
from jellysim.io.result import Result, open_result

STATIC = Path(__file__).parent / "static"
WEB_MODULES_ENV = "JELLYSIM_WEB_MODULES"
THREE_FILES = {  # served path -> path under node_modules
    "/vendor/three/three.module.js": "three/build/three.module.js",
    "/vendor/three/three.core.js": "three/build/three.core.js",
    "/vendor/three/OrbitControls.js": "three/examples/jsm/controls/OrbitControls.js",
}
CONTENT_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
}
PARTS = ("bell", "tentacles", "fluid")
MAX_CHUNK_FRAMES = 256  # frames one /frames request may ask for
MAX_INTERPOLATION = 50  # the slider's top, lowered for results with many tentacle points
POINT_BUDGET = 250_000  # drawn tentacle points per frame the slider may reach
BOUNDS_SAMPLES = 256  # frames sampled (evenly, both ends included) for the camera's framing
LOOPBACK_NAMES = {"localhost", "127.0.0.1", "::1"}


def find_web_modules() -> Path:
    """The ``node_modules`` folder holding three.js: ``$JELLYSIM_WEB_MODULES``, else
    ``web/node_modules`` of the repository this package was installed from (editable)."""
    setting = os.environ.get(WEB_MODULES_ENV)
    folder = (
        Path(setting) if setting else Path(__file__).resolve().parents[3] / "web" / "node_modules"
    )
    if all((folder / part).is_file() for part in THREE_FILES.values()):
        return folder
    if setting:
        raise InputError(
            f"{WEB_MODULES_ENV}={setting}: three.js not found there "
            "(expected three/build/three.module.js in that node_modules folder)"
        )
    raise InputError(
        "three.js is not installed for jellysim view: run 'make web' (or 'cd web && npm ci') "
        f"in the jellysim repository, or set {WEB_MODULES_ENV} to a node_modules folder"
    )


def _color(rgb: tuple[float, float, float]) -> list[float]:
    return [float(c) for c in rgb]


class ResultData:
    """A result as the page reads it: metadata and float32 chunks of frames.

    Reads the file on each request (h5py serialises access between the server's threads); the
    drawn tentacles come from :func:`jellysim.interpolation.interpolate_result` for the frames
    asked for, the interpolation factor chosen by the page.
    """

    def __init__(self, result: Result) -> None:
        from jellysim.render.pipeline import fluid_radius, scene_look

        f = result.file
        self.result = result
        self.frames = result.frames
        if self.frames == 0:
            raise InputError(f"{result.path}: the result holds no frames yet")
        scene = result.scene
        self.has_bell = result.has(fields.BELL_SURFACE_VERTICES) and result.has(
            fields.BELL_SURFACE_FACES
        )
        self.has_tentacles = (
            result.has(fields.TENTACLE_POSITION)
            and result.has(fields.BELL_MARGIN)
            and result.dataset(fields.TENTACLE_POSITION).shape[1] > 0
        )
        self.has_fluid = result.has(fields.FLUID_POSITION)
        tentacles = result.dataset(fields.TENTACLE_POSITION).shape if self.has_tentacles else None
        self.simulated = 0 if tentacles is None else int(tentacles[1])
        self.particles = 0 if tentacles is None else int(tentacles[2])
        per_factor = max(1, self.simulated * self.particles)
        self.max_interpolation = max(1, min(MAX_INTERPOLATION, POINT_BUDGET // per_factor))
        self.interpolation = min(int(scene.tentacles.interpolation), self.max_interpolation)
        fluid = result.dataset(fields.FLUID_POSITION).shape if self.has_fluid else None
        self.fluid_count = 0 if fluid is None else int(fluid[1])
        look = scene_look(scene)
        self._meta: dict[str, Any] = {
            "name": str(scene.name),
            "fps": float(f.attrs.get("fps", scene.fps)),
            "frames": self.frames,
            "complete": bool(f.attrs.get("frames_expected", self.frames) == self.frames),
            "time": [float(t) for t in result.time],
            "look": {
                "bell_color": _color(look.bell_color),
                "tentacle_color": _color(look.tentacle_color),
                "bell_transparency": float(look.bell_transparency),
                "water_color": _color(look.water_color),
                "tentacle_radius": float(look.tentacle_radius),
                "tentacle_taper": float(look.tentacle_taper),
            },
            "bell": {
                "present": self.has_bell,
                "vertices": (
                    int(result.dataset(fields.BELL_SURFACE_VERTICES).shape[1])
                    if self.has_bell
                    else 0
                ),
                "faces": (
                    int(result.dataset(fields.BELL_SURFACE_FACES).shape[0]) if self.has_bell else 0
                ),
            },
            "tentacles": {
                "present": self.has_tentacles,
                "simulated": self.simulated,
                "particles": self.particles,
                "interpolation": self.interpolation,
                "max_interpolation": self.max_interpolation,
            },
            "fluid": {
                "present": self.has_fluid,
                "particles": self.fluid_count,
                "dimensions": 0 if fluid is None else int(fluid[2]),
                "radius": fluid_radius(result) if self.has_fluid else 0.0,
            },
            **self._bounds(),
        }

    def meta(self) -> dict[str, Any]:
        """``name``, ``fps``, ``frames``, ``complete``, ``time`` (F,) s, ``look`` (linear RGB
        colours, m), ``bell``/``tentacles``/``fluid`` (present, sizes), ``bounds`` [[low],
        [high]] m of the whole animation, ``extent`` m (the largest box of one frame) and
        ``travels`` (whether the centre moves further than that: the page then follows it)."""
        return self._meta

    def _bounds(self) -> dict[str, Any]:
        result = self.result
        sample = sorted({round(x) for x in np.linspace(0, self.frames - 1, BOUNDS_SAMPLES)})
        low = np.full((len(sample), 3), np.inf)
        high = np.full((len(sample), 3), -np.inf)
        parts = []
        if self.has_bell:
            parts.append(result.read(fields.BELL_SURFACE_VERTICES, sample).astype(np.float64))
        if self.has_tentacles:
            positions = result.read(fields.TENTACLE_POSITION, sample).astype(np.float64)
            parts.append(positions.reshape(len(sample), -1, 3))
        if self.has_fluid:
            parts.append(self._fluid_world(sample))
        for points in parts:
            low = np.fmin(low, np.nanmin(points, axis=1))
            high = np.fmax(high, np.nanmax(points, axis=1))
        if not np.all(np.isfinite(low)) or not np.all(np.isfinite(high)):
            raise InputError(f"{self.result.path}: nothing to show (no finite positions)")
        extent = float(np.max(high - low))
        centres = 0.5 * (low + high)
        travel = float(np.linalg.norm(centres[-1] - centres[0]))
        return {
            "bounds": [low.min(axis=0).tolist(), high.max(axis=0).tolist()],
            "extent": max(extent, 1e-6),
            "travels": travel > extent,
        }

    def _fluid_world(self, frames: list[int] | slice) -> np.ndarray:
        """Fluid particles (C, N, 3) m as drawn: 2-D (x, y up) as (x, 0, y), dead ones NaN."""
        from jellysim.render.pipeline import to_world

        result = self.result
        points = to_world(result.read(fields.FLUID_POSITION, frames).astype(np.float64))
        if result.has(fields.FLUID_ALIVE):
            points[~result.read(fields.FLUID_ALIVE, frames)] = np.nan
        return points

    def bell_faces(self) -> bytes:
        if not self.has_bell:
            raise LookupError("the result has no bell")
        return self.result.bell_surface_faces.astype("<u4").tobytes()

    def fluid_kinds(self) -> bytes:
        """Particle kinds (N,) uint8: 0 fluid, 1 wall, 2 dummy (all 0 when not stored)."""
        if not self.has_fluid:
            raise LookupError("the result has no fluid")
        if not self.result.has(fields.FLUID_KIND):
            return bytes(self.fluid_count)
        return self.result.fluid_kind.astype("<u1").tobytes()

    def chunk(self, part: str, start: int, count: int, interpolation: int | None) -> bytes:
        """Frames ``start`` to ``start + count - 1`` of ``part`` as little-endian float32."""
        if part not in PARTS:
            raise ValueError(f"part={part}: expected one of {', '.join(PARTS)}")
        if not (0 <= start < self.frames and 1 <= count <= MAX_CHUNK_FRAMES):
            raise ValueError(
                f"start={start}, count={count}: the result has frames 0 to {self.frames - 1}, "
                f"at most {MAX_CHUNK_FRAMES} per request"
            )
        stop = min(self.frames, start + count)
        if part == "bell":
            if not self.has_bell:
                raise LookupError("the result has no bell")
            data = self.result.read(fields.BELL_SURFACE_VERTICES, slice(start, stop))
        elif part == "fluid":
            if not self.has_fluid:
                raise LookupError("the result has no fluid")
            data = self._fluid_world(slice(start, stop))
        else:
            if not self.has_tentacles:
                raise LookupError("the result has no tentacles")
            factor = self.interpolation if interpolation is None else interpolation
            if not 1 <= factor <= self.max_interpolation:
                raise ValueError(f"interpolation={factor}: expected 1 to {self.max_interpolation}")
            from jellysim.interpolation import interpolate_result

            data = interpolate_result(self.result, factor, frames=(start, stop))
        return np.ascontiguousarray(data, dtype="<f4").tobytes()


def _import_map_hash(page: str) -> str:
    """CSP source for the page's inline import map (the only inline script it has)."""
    found = re.search(r'<script type="importmap">(.*?)</script>', page, re.DOTALL)
    if found is None:
        raise RuntimeError("static/index.html has no import map")
    digest = hashlib.sha256(found.group(1).encode("utf-8")).digest()
    return "'sha256-" + base64.b64encode(digest).decode("ascii") + "'"


class ViewServer(ThreadingHTTPServer):
    """Serves one result's page and data on ``(host, port)`` (port 0: a free one)."""

    daemon_threads = True

    def __init__(self, data: ResultData, web_modules: Path, host: str, port: int) -> None:
        self.data = data
        self.files: dict[str, Path] = {"/": STATIC / "index.html"}
        for path in sorted(STATIC.iterdir()):
            if path.is_file() and path.suffix in CONTENT_TYPES:
                self.files[f"/static/{path.name}"] = path
        for served, relative in THREE_FILES.items():
            self.files[served] = web_modules / relative
        page = (STATIC / "index.html").read_text(encoding="utf-8")
        self.policy = (
            "default-src 'self'; "
            f"script-src 'self' {_import_map_hash(page)}; "
            "img-src 'self' data:; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"
        )
        self.loopback = _is_loopback(host)
        if ":" in host:
            self.address_family = socket.AF_INET6
        try:
            super().__init__((host, port), _Handler)
        except (OSError, OverflowError) as err:
            reason = getattr(err, "strerror", None) or str(err)
            raise InputError(
                f"--host {host} --port {port}: cannot listen there ({reason})"
            ) from None

    @property
    def url(self) -> str:
        host, port = str(self.server_address[0]), int(self.server_address[1])
        if ipaddress.ip_address(host).is_unspecified:
            host = socket.gethostname()
        elif ":" in str(host):
            host = f"[{host}]"
        return f"http://{host}:{port}/"


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _Handler(BaseHTTPRequestHandler):
    server: ViewServer
    protocol_version = "HTTP/1.1"

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 (the base's name)
        """Quiet: the page reports its own errors."""

    def _send(self, status: int, body: bytes, content_type: str, cache: bool = False) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "max-age=3600" if cache else "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("Content-Security-Policy", self.server.policy)
        self.end_headers()
        self.wfile.write(body)

    def _fail(self, status: HTTPStatus, message: str) -> None:
        self._send(status, (message + "\n").encode("utf-8"), "text/plain; charset=utf-8")

    def _host_allowed(self) -> bool:
        """On a loopback address, only requests naming a loopback host (DNS rebinding)."""
        if not self.server.loopback:
            return True
        host = urlsplit("//" + self.headers.get("Host", "")).hostname or ""
        return host in LOOPBACK_NAMES

    def do_GET(self) -> None:  # noqa: N802 (http.server's name)
        url = urlsplit(self.path)
        try:
            if not self._host_allowed():
                self._fail(HTTPStatus.FORBIDDEN, "jellysim view answers to localhost only")
            elif url.path in self.server.files:
                path = self.server.files[url.path]
                vendor = url.path.startswith("/vendor/")
                self._send(HTTPStatus.OK, path.read_bytes(), CONTENT_TYPES[path.suffix], vendor)
            elif url.path in self._data_routes:
                self._data_routes[url.path](self, parse_qs(url.query))
            else:
                self._fail(HTTPStatus.NOT_FOUND, f"not found: {url.path}")
        except (BrokenPipeError, ConnectionResetError):
            pass  # the page moved on (a scrub) before the answer arrived
        except Exception as err:  # one line to the page; the server keeps serving
            self._fail(HTTPStatus.INTERNAL_SERVER_ERROR, f"{type(err).__name__}: {err}")

    def _meta(self, query: dict[str, list[str]]) -> None:
        body = json.dumps(self.server.data.meta()).encode("utf-8")
        self._send(HTTPStatus.OK, body, "application/json")

    def _binary(self, make: Callable[[], bytes]) -> None:
        try:
            body = make()
        except LookupError as err:
            self._fail(HTTPStatus.NOT_FOUND, str(err))
            return
        except ValueError as err:
            self._fail(HTTPStatus.BAD_REQUEST, str(err))
            return
        self._send(HTTPStatus.OK, body, "application/octet-stream")

    def _bell_faces(self, query: dict[str, list[str]]) -> None:
        self._binary(self.server.data.bell_faces)

    def _fluid_kinds(self, query: dict[str, list[str]]) -> None:
        self._binary(self.server.data.fluid_kinds)

    def _frames(self, query: dict[str, list[str]]) -> None:
        def make() -> bytes:
            values = {key: query.get(key, [""])[-1] for key in ("part", "start", "count")}
            factor = query.get("interpolation", [None])[-1]
            try:
                start, count = int(values["start"]), int(values["count"])
                interpolation = None if factor is None else int(factor)
            except ValueError:
                raise ValueError(
                    "expected /frames?part=P&start=S&count=C[&interpolation=N], integers"
                ) from None
            return self.server.data.chunk(values["part"], start, count, interpolation)

        self._binary(make)

    _data_routes: dict[str, Callable[[_Handler, dict[str, list[str]]], None]] = {
        "/meta.json": _meta,
        "/bell-faces": _bell_faces,
        "/fluid-kinds": _fluid_kinds,
        "/frames": _frames,
    }


def serve(
    folder: str | os.PathLike[str],
    host: str = "127.0.0.1",
    port: int = 0,
    browser: bool = True,
    ready: Callable[[ViewServer], None] | None = None,
) -> int:
    """Serve the result in ``folder`` until Ctrl-C (exit status 0), printing the address and
    opening the default browser unless ``browser`` is False. ``ready`` is called with the
    listening server (tests stop it with ``server.shutdown()``)."""
    if not 0 <= port <= 65535:
        raise InputError(f"--port {port}: expected 0 (a free port) to 65535")
    with open_result(folder) as result:
        web_modules = find_web_modules()
        server = ViewServer(ResultData(result), web_modules, host, port)
        try:
            url = server.url
            print(f"jellysim view: serving {folder} at {url} (Ctrl-C to stop)", flush=True)
            if browser:  # in a daemon thread: a text-mode browser may block
                threading.Thread(target=webbrowser.open, args=(url,), daemon=True).start()
            if ready is not None:
                ready(server)
            try:
                server.serve_forever()
            except KeyboardInterrupt:
                print("jellysim view: stopped", file=sys.stderr)
        finally:
            server.server_close()
    return 0
