"""The viewer's HTTP server: Python's standard library only (docs/viewer.md, "Architecture").

Routes (GET only; anything else is 404, so no path reaches the file system but these):

- ``/?token=TOKEN`` the page, ``/static/NAME`` its files (those directly in ``static/``, listed
  at start);
- ``/vendor/three/{three.module.js, three.core.js, OrbitControls.js}`` from the npm package;
- ``/meta.json`` what the page needs to know about the result (:meth:`ResultData.meta`);
- ``/bell-faces`` uint32 (M, 3), ``/fluid-kinds`` uint8 (N,);
- ``/frames?part=bell|tentacles|fluid&start=S&count=C[&interpolation=N]`` float32 frames
  S to S + C - 1: bell (C, V, 3), drawn tentacles (C, T N, P, 3), fluid (C, N, 3) with the
  particles that left the domain as NaN. Binary bodies are little-endian, C order, in metres.
  In a scene of several tentacle groups a tentacle frame holds each group's drawn tentacles in
  turn, (D_g, P_g, 3) each, of the group's own particle count P_g (never NaN-padded): a thread
  group drawn N per simulated tentacle (D_g = T_g N on a ring, the sum of (m - 1) N + 1 over
  clusters of m), a ribbon group (oral arms) as simulated (D_g = T_g), whatever N; the groups
  are listed in ``/meta.json`` (``tentacles.groups``).

What one session may cost the machine is bounded (:class:`ViewLimits`, docs/viewer.md,
"Security"): the data routes answer only requests carrying the session's token in the
``X-Jellysim-Token`` header and not sent from another site; an answer's size is known from the
query before anything is read or computed, and one over ``max_response_bytes`` is refused (413);
data requests being answered are counted per client address and in all (429 beyond); idle
connections are closed, and connections beyond ``connections`` are refused (503).
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import ipaddress
import json
import os
import re
import secrets
import socket
import sys
import threading
import webbrowser
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any, NamedTuple
from urllib.parse import parse_qs, quote, urlsplit

import numpy as np

from jellysim import fields
from jellysim.errors import InputError
from jellysim.io.plots import flow_label
from jellysim.io.result import Result, open_result

STATIC = Path(__file__).parent / "static"
# three.js ships in the package (jellysim/view/vendor: web/node_modules' files, same layout), so
# a wheel needs no checkout and no npm (issue 27); `make web` is for development (tests) only.
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
TOKEN_HEADER = "X-Jellysim-Token"  # the session's token on every data request
OWN_FETCH_SITES = {"same-origin", "none"}  # Sec-Fetch-Site values a data request may carry
FLOAT32_BYTES = 4
RETRY_AFTER_S = 1  # what a 429 or 503 asks the client to wait


@dataclass(frozen=True)
class ViewLimits:
    """What one viewer session may cost the machine (docs/viewer.md, "Security";
    docs/decisions.md, "Viewer limits (issue 24)").

    ``max_response_bytes``: the largest body a data route sends, bytes; ``requests_per_client``
    and ``data_requests``: data requests answered at once from one client address and in all;
    ``connections``: connections open at once (each holds a thread); ``idle_timeout``: seconds
    a connection may wait for a request, or take to send one or receive an answer.
    """

    max_response_bytes: int = 32 * 2**20
    requests_per_client: int = 2
    data_requests: int = 4
    connections: int = 32
    idle_timeout: float = 15.0


class FrameRequest(NamedTuple):
    """A checked ``/frames`` query: frames ``start`` to ``stop - 1`` of ``part``, tentacles
    drawn ``interpolation`` per simulated one (1 for the other parts)."""

    part: str
    start: int
    stop: int
    interpolation: int


def find_web_modules() -> Path:
    """The ``node_modules``-like folder holding three.js: ``$JELLYSIM_WEB_MODULES`` when set,
    else the copy the package ships (``jellysim/view/vendor``), else ``web/node_modules`` of the
    repository this package runs from."""
    setting = os.environ.get(WEB_MODULES_ENV)
    if setting:
        folder = Path(setting)
        if _holds_three(folder):
            return folder
        raise InputError(
            f"{WEB_MODULES_ENV}={setting}: three.js not found there "
            "(expected three/build/three.module.js in that node_modules folder)"
        )
    packaged = Path(__file__).resolve().parent / "vendor"
    repository = Path(__file__).resolve().parents[3] / "web" / "node_modules"
    for folder in (packaged, repository):
        if _holds_three(folder):
            return folder
    raise InputError(
        "three.js is missing from this jellysim installation (jellysim/view/vendor): reinstall "
        "jellysim; in a checkout, 'make web' (or 'cd web && npm ci') installs it, or set "
        f"{WEB_MODULES_ENV} to a node_modules folder"
    )


def _holds_three(folder: Path) -> bool:
    return all((folder / part).is_file() for part in THREE_FILES.values())


def _color(rgb: tuple[float, float, float]) -> list[float]:
    return [float(c) for c in rgb]


@dataclass(frozen=True)
class ViewGroup:
    """One tentacle group as the page draws it: ``rows`` its simulated tentacles in the result,
    ``particles`` its own, ``clusters`` the sizes of its rows of roots (one: a closed ring),
    ``ribbon`` drawn as its simulated arms' ribbons (else as interpolated threads)."""

    name: str
    rows: slice
    particles: int
    clusters: tuple[int, ...]
    ribbon: bool

    def drawn(self, interpolation: int) -> int:
        """Tentacles drawn at ``interpolation`` per simulated one (as interpolate_groups)."""
        if self.ribbon:
            return self.rows.stop - self.rows.start
        if len(self.clusters) == 1:
            return self.clusters[0] * interpolation
        return sum((m - 1) * interpolation + 1 for m in self.clusters)


def _view_groups(scene: Any) -> list[ViewGroup]:
    # The clusters as jellysim.interpolation draws them (its helper, one source of truth).
    from jellysim.interpolation import cluster_sizes
    from jellysim.tentacle.layout import root_layout

    return [
        ViewGroup(
            group.name,
            rows,
            int(group.tentacles.particles),
            tuple(cluster_sizes(group.tentacles)),
            group.tentacles.form == "ribbon",
        )
        for group, rows in zip(scene.groups, root_layout(scene).slices(), strict=True)
    ]


class ResultData:
    """A result as the page reads it: metadata and float32 chunks of frames.

    Reads the file on each request (h5py serialises access between the server's threads); the
    drawn tentacles come from :func:`jellysim.interpolation.interpolate_result` for the frames
    asked for, the interpolation factor chosen by the page, or in a scene of several groups (or
    a ribbon group) from :func:`~jellysim.interpolation.interpolate_groups`, group by group.
    """

    def __init__(self, result: Result) -> None:
        from jellysim.render.materials import (
            STRIPE_TRANSMIT,
            bell_material,
            phong_shininess,
            stripe_color,
            tentacle_face_color,
            tentacle_material,
        )
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
        self.groups = _view_groups(scene) if self.has_tentacles else []
        # Drawn group by group (else as interpolate_result draws them, as before groups).
        self.grouped = len(self.groups) > 1 or any(g.ribbon for g in self.groups)
        # Drawn points per frame: fixed + per_factor x interpolation.
        fixed = self._points(0) if self.groups else 0
        per_factor = max(1, self._points(1) - fixed if self.groups else 0)
        self.max_interpolation = max(
            1, min(MAX_INTERPOLATION, (POINT_BUDGET - fixed) // per_factor)
        )
        own = [int(g.tentacles.interpolation) for g in scene.groups if g.tentacles.form != "ribbon"]
        self.interpolation = min(max(own, default=1), self.max_interpolation)
        fluid = result.dataset(fields.FLUID_POSITION).shape if self.has_fluid else None
        self.fluid_count = 0 if fluid is None else int(fluid[1])
        self.bell_vertices = (
            int(result.dataset(fields.BELL_SURFACE_VERTICES).shape[1]) if self.has_bell else 0
        )
        self.bell_face_count = (
            int(result.dataset(fields.BELL_SURFACE_FACES).shape[0]) if self.has_bell else 0
        )
        look = scene_look(scene)
        bell, tentacle = bell_material(look), tentacle_material(look)
        tentacles_meta: dict[str, Any] = {
            "present": self.has_tentacles,
            "simulated": self.simulated,
            "particles": self.particles,
            "interpolation": self.interpolation,
            "max_interpolation": self.max_interpolation,
            "frame_bytes": self.frame_bytes("tentacles", 1),
        }
        if self.grouped:
            tentacles_meta["groups"] = self._groups_meta(look)
        self._meta: dict[str, Any] = {
            "name": str(scene.name),
            # What water the tentacles felt, as the plots' titles name it (issue 26).
            "flow": flow_label(scene) if self.has_tentacles else "",
            "fps": float(f.attrs.get("fps", scene.fps)),
            "frames": self.frames,
            "complete": bool(f.attrs.get("frames_expected", self.frames) == self.frames),
            "time": [float(t) for t in result.time],
            "look": {
                "bell_color": _color(bell.base_color),
                "tentacle_color": _color(tentacle.base_color),
                "bell_transparency": float(look.bell_transparency),
                "bell_emissive": _color(bell.emissive),
                "bell_shininess": phong_shininess(bell),
                "tentacle_face_color": _color(tentacle_face_color(look)),
                "rim": float(look.rim),
                "stripes": int(look.stripes),
                "stripe_color": _color(stripe_color(look)),
                "stripe_transmit": STRIPE_TRANSMIT,
                "water_color": _color(look.water_color),
                "tentacle_radius": float(look.tentacle_radius),
                "tentacle_taper": float(look.tentacle_taper),
            },
            "bell": {
                "present": self.has_bell,
                "vertices": self.bell_vertices,
                "faces": self.bell_face_count,
                "frame_bytes": self.frame_bytes("bell"),
            },
            "tentacles": tentacles_meta,
            "fluid": {
                "present": self.has_fluid,
                "particles": self.fluid_count,
                "dimensions": 0 if fluid is None else int(fluid[2]),
                "radius": fluid_radius(result) if self.has_fluid else 0.0,
                "frame_bytes": self.frame_bytes("fluid"),
            },
            **self._bounds(),
        }

    def meta(self) -> dict[str, Any]:
        """``name``, ``fps``, ``frames``, ``complete``, ``time`` (F,) s, ``look`` (linear RGB
        colours, m), ``bell``/``tentacles``/``fluid`` (present, sizes, ``frame_bytes``: one
        frame's bytes, the tentacles' at one drawn per simulated; in a scene of several
        tentacle groups ``tentacles.groups`` lists them, :meth:`_groups_meta`), ``bounds``
        [[low], [high]]
        m of the whole animation, ``extent`` m (the largest box of one frame) and ``travels``
        (whether the centre moves further than that: the page then follows it)."""
        return self._meta

    def _points(self, interpolation: int) -> int:
        """Tentacle points of one frame drawn at ``interpolation``."""
        return sum(g.drawn(interpolation) * g.particles for g in self.groups)

    def _groups_meta(self, look: Any) -> list[dict[str, Any]]:
        """Per group: ``name``, ``form`` ("thread" or "ribbon"), ``color`` and ``face_color``
        (linear RGB: its colour, and seen face-on as a line, ``tentacle_face_color``),
        ``opacity``, ``emissive`` (linear RGB) and ``shininess`` (Phong) of its material
        (:func:`~jellysim.render.materials.group_material`), ``particles``, ``simulated``,
        ``clusters`` (sizes of its rows of roots, one: a ring),
        ``radius`` m and ``taper`` (threads), ``width`` m at the root (ribbons)."""
        from jellysim.render.materials import (
            group_look,
            group_material,
            phong_shininess,
            tentacle_face_color,
        )

        out = []
        for g, group in zip(self.groups, self.result.scene.groups, strict=True):
            drawn = group_look(look, group.tentacles, g.name)
            material = group_material(look, drawn, g.name)
            out.append(
                {
                    "name": g.name,
                    "form": "ribbon" if g.ribbon else "thread",
                    "color": _color(drawn.color),
                    "face_color": _color(
                        tentacle_face_color(replace(look, tentacle_color=drawn.color))
                    ),
                    "opacity": material.opacity,
                    "emissive": _color(material.emissive),
                    "shininess": phong_shininess(material),
                    "particles": g.particles,
                    "simulated": g.rows.stop - g.rows.start,
                    "clusters": list(g.clusters),
                    "radius": drawn.radius,
                    "taper": drawn.taper,
                    "width": drawn.ribbon_width,
                }
            )
        return out

    def frame_bytes(self, part: str, interpolation: int = 1) -> int:
        """Bytes of one frame of ``part`` as ``/frames`` sends it (0 for a part not there)."""
        points = {
            "bell": self.bell_vertices,
            "tentacles": self._points(interpolation),
            "fluid": self.fluid_count,
        }[part]
        return points * 3 * FLOAT32_BYTES

    def bell_faces_bytes(self) -> int:
        return self.bell_face_count * 3 * FLOAT32_BYTES

    def fluid_kinds_bytes(self) -> int:
        return self.fluid_count

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

    def frame_request(
        self, part: str, start: int, count: int, interpolation: int | None
    ) -> FrameRequest:
        """The query checked, nothing read: ValueError for a bad one, LookupError for a part
        the result does not have."""
        if part not in PARTS:
            raise ValueError(f"part={part}: expected one of {', '.join(PARTS)}")
        if not (0 <= start < self.frames and 1 <= count <= MAX_CHUNK_FRAMES):
            raise ValueError(
                f"start={start}, count={count}: the result has frames 0 to {self.frames - 1}, "
                f"at most {MAX_CHUNK_FRAMES} per request"
            )
        present = {"bell": self.has_bell, "tentacles": self.has_tentacles, "fluid": self.has_fluid}
        if not present[part]:
            raise LookupError(f"the result has no {'tentacles' if part == 'tentacles' else part}")
        factor = 1
        if part == "tentacles":
            factor = self.interpolation if interpolation is None else interpolation
            if not 1 <= factor <= self.max_interpolation:
                raise ValueError(f"interpolation={factor}: expected 1 to {self.max_interpolation}")
        return FrameRequest(part, start, min(self.frames, start + count), factor)

    def chunk_bytes(self, request: FrameRequest) -> int:
        """The size of :meth:`chunk`'s answer, known before it is built."""
        return (request.stop - request.start) * self.frame_bytes(
            request.part, request.interpolation
        )

    def _group_frames(self, request: FrameRequest) -> np.ndarray:
        """(C, points) m: each frame's groups in turn, threads interpolated, ribbons as
        simulated."""
        from jellysim.interpolation import interpolate_groups

        window = (request.start, request.stop)
        count = request.stop - request.start
        simulated = self.result.read(fields.TENTACLE_POSITION, slice(*window))
        pieces = []
        for g, drawn in zip(
            self.groups,
            interpolate_groups(self.result, request.interpolation, frames=window),
            strict=True,
        ):
            own = simulated[:, g.rows, : g.particles] if g.ribbon else drawn.positions
            pieces.append(np.asarray(own).reshape(count, -1))
        return np.concatenate(pieces, axis=1)

    def chunk(self, request: FrameRequest) -> bytes:
        """The frames of ``request`` as little-endian float32."""
        frames = slice(request.start, request.stop)
        if request.part == "bell":
            data = self.result.read(fields.BELL_SURFACE_VERTICES, frames)
        elif request.part == "fluid":
            data = self._fluid_world(frames)
        elif not self.grouped:
            from jellysim.interpolation import interpolate_result

            window = (request.start, request.stop)
            data = interpolate_result(self.result, request.interpolation, frames=window)
        else:
            data = self._group_frames(request)
        return np.ascontiguousarray(data, dtype="<f4").tobytes()


def _import_map_hash(page: str) -> str:
    """CSP source for the page's inline import map (the only inline script it has)."""
    found = re.search(r'<script type="importmap">(.*?)</script>', page, re.DOTALL)
    if found is None:
        raise RuntimeError("static/index.html has no import map")
    digest = hashlib.sha256(found.group(1).encode("utf-8")).digest()
    return "'sha256-" + base64.b64encode(digest).decode("ascii") + "'"


class RequestBudget:
    """Data requests being answered, counted per client address and in all: a request that
    would go beyond either count is not answered now (429) instead of waiting in a thread."""

    def __init__(self, per_client: int, total: int) -> None:
        self.per_client = per_client
        self.total = total
        self.refused = 0  # requests turned away so far
        self._busy: dict[str, int] = {}
        self._answering = 0
        self._lock = threading.Lock()

    @contextmanager
    def slot(self, client: str) -> Iterator[bool]:
        """Whether a request of ``client`` may be answered now; if so its slot is held until
        the block ends (the answer sent)."""
        with self._lock:
            busy = self._busy.get(client, 0)
            granted = busy < self.per_client and self._answering < self.total
            if granted:
                self._busy[client] = busy + 1
                self._answering += 1
            else:
                self.refused += 1
        try:
            yield granted
        finally:
            if granted:
                with self._lock:
                    self._answering -= 1
                    self._busy[client] -= 1
                    if self._busy[client] == 0:
                        del self._busy[client]


class ViewServer(ThreadingHTTPServer):
    """Serves one result's page and data on ``(host, port)`` (port 0: a free one) within
    ``limits``; the page's address, :attr:`page_url`, carries the session's token."""

    daemon_threads = True

    def __init__(
        self,
        data: ResultData,
        web_modules: Path,
        host: str,
        port: int,
        limits: ViewLimits | None = None,
    ) -> None:
        self.data = data
        self.limits = ViewLimits() if limits is None else limits
        self.token = secrets.token_urlsafe(32)
        self.budget = RequestBudget(self.limits.requests_per_client, self.limits.data_requests)
        self.open_connections = 0
        self._connections_lock = threading.Lock()
        full = f"jellysim view: {self.limits.connections} connections are open already\n"
        self._connections_full = (
            "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain; charset=utf-8\r\n"
            f"Content-Length: {len(full)}\r\nRetry-After: {RETRY_AFTER_S}\r\n"
            f"Connection: close\r\n\r\n{full}"
        ).encode("ascii")
        self.meta_body = json.dumps(
            {
                **data.meta(),
                "limits": {
                    "max_response_bytes": self.limits.max_response_bytes,
                    "max_frames_per_request": MAX_CHUNK_FRAMES,
                    "requests_per_client": self.limits.requests_per_client,
                },
            }
        ).encode("utf-8")
        page = (STATIC / "index.html").read_text(encoding="utf-8")
        self.page = page.encode("utf-8")
        self.files: dict[str, Path] = {}
        for path in sorted(STATIC.iterdir()):
            if path.is_file() and path.suffix in CONTENT_TYPES:
                self.files[f"/static/{path.name}"] = path
        for served, relative in THREE_FILES.items():
            self.files[served] = web_modules / relative
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

    @property
    def page_url(self) -> str:
        """The page's address with this session's token: what the user opens."""
        return f"{self.url}?token={quote(self.token)}"

    def token_matches(self, given: str) -> bool:
        return hmac.compare_digest(given.encode("utf-8"), self.token.encode("ascii"))

    # A thread per connection (ThreadingMixIn), at most limits.connections of them: a
    # connection beyond is answered 503 and closed without a thread.
    def process_request(self, request: Any, client_address: Any) -> None:
        with self._connections_lock:
            admitted = self.open_connections < self.limits.connections
            if admitted:
                self.open_connections += 1
        if not admitted:
            try:
                request.setblocking(False)  # a fresh socket's buffer takes these few bytes
                request.send(self._connections_full)
            except OSError:
                pass
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:
            self._connection_closed()
            raise

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        try:
            super().process_request_thread(request, client_address)
        finally:
            self._connection_closed()

    def _connection_closed(self) -> None:
        with self._connections_lock:
            self.open_connections -= 1


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


# A data route's plan: the answer's size in bytes (known before it is built), a function that
# builds it, and its content type. A route raises ValueError for a bad query, LookupError for
# something the result does not have.
Planned = tuple[int, Callable[[], bytes], str]
Route = Callable[["_Handler", dict[str, list[str]]], Planned]
BINARY = "application/octet-stream"


class _Handler(BaseHTTPRequestHandler):
    server: ViewServer
    protocol_version = "HTTP/1.1"

    def setup(self) -> None:
        super().setup()
        # Every read (waiting for a request included) and every answer's send give up after
        # idle_timeout: http.server then closes the connection and its thread ends.
        self.connection.settimeout(self.server.limits.idle_timeout)

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 (the base's name)
        """Quiet: the page reports its own errors."""

    def _send(
        self,
        status: int,
        body: bytes,
        content_type: str,
        cache: bool = False,
        retry: bool = False,
    ) -> None:
        try:
            self.send_response(status)
            self.send_header("Content-Type", content_type)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "max-age=3600" if cache else "no-store")
            self.send_header("X-Content-Type-Options", "nosniff")
            self.send_header("Referrer-Policy", "no-referrer")
            self.send_header("Content-Security-Policy", self.server.policy)
            if retry:
                self.send_header("Retry-After", str(RETRY_AFTER_S))
            self.end_headers()
            self.wfile.write(body)
        except OSError:  # the page moved on (a scrub), or stopped reading (idle_timeout)
            self.close_connection = True

    def _fail(self, status: HTTPStatus, message: str, retry: bool = False) -> None:
        body = (message + "\n").encode("utf-8")
        self._send(status, body, "text/plain; charset=utf-8", retry=retry)

    def _host_allowed(self) -> bool:
        """On a loopback address, only requests naming a loopback host (DNS rebinding)."""
        if not self.server.loopback:
            return True
        host = urlsplit("//" + self.headers.get("Host", "")).hostname or ""
        return host in LOOPBACK_NAMES

    def _refusal(self) -> str | None:
        """Why a data request does not come from the viewer's own page, or None."""
        site = self.headers.get("Sec-Fetch-Site")
        if site is not None and site not in OWN_FETCH_SITES:
            return f"refused: a {site} request (only the viewer's own page may ask)"
        origin = self.headers.get("Origin")
        if origin is not None and origin != f"http://{self.headers.get('Host', '')}":
            return f"refused: a request from {origin} (only the viewer's own page may ask)"
        if not self.server.token_matches(self.headers.get(TOKEN_HEADER, "")):
            return f"refused: no valid {TOKEN_HEADER} (open the address jellysim view printed)"
        return None

    def do_GET(self) -> None:  # noqa: N802 (http.server's name)
        url = urlsplit(self.path)
        query = parse_qs(url.query)
        try:
            if not self._host_allowed():
                self._fail(HTTPStatus.FORBIDDEN, "jellysim view answers to localhost only")
            elif url.path == "/":
                if self.server.token_matches(query.get("token", [""])[-1]):
                    self._send(HTTPStatus.OK, self.server.page, CONTENT_TYPES[".html"])
                else:
                    self._fail(
                        HTTPStatus.FORBIDDEN,
                        "open the address that jellysim view printed: it carries this "
                        "session's token",
                    )
            elif url.path in self.server.files:
                path = self.server.files[url.path]
                vendor = url.path.startswith("/vendor/")
                self._send(HTTPStatus.OK, path.read_bytes(), CONTENT_TYPES[path.suffix], vendor)
            elif url.path in self._data_routes:
                refusal = self._refusal()
                if refusal is not None:
                    self._fail(HTTPStatus.FORBIDDEN, refusal)
                else:
                    self._answer(self._data_routes[url.path], query)
            else:
                self._fail(HTTPStatus.NOT_FOUND, f"not found: {url.path}")
        except Exception as err:  # one line to the page; the server keeps serving
            self._fail(HTTPStatus.INTERNAL_SERVER_ERROR, f"{type(err).__name__}: {err}")

    def _answer(self, route: Route, query: dict[str, list[str]]) -> None:
        """A data route's answer within the limits: its size checked before it is built, and
        built only while the client and the server have a slot free."""
        try:
            size, make, content_type = route(self, query)
        except LookupError as err:
            self._fail(HTTPStatus.NOT_FOUND, str(err))
            return
        except ValueError as err:
            self._fail(HTTPStatus.BAD_REQUEST, str(err))
            return
        limits = self.server.limits
        if size > limits.max_response_bytes:
            self._fail(
                HTTPStatus.REQUEST_ENTITY_TOO_LARGE,
                f"the answer would be {size} bytes, over the {limits.max_response_bytes} one "
                "answer may carry: ask for fewer frames",
            )
            return
        with self.server.budget.slot(self.client_address[0]) as granted:
            if not granted:
                self._fail(
                    HTTPStatus.TOO_MANY_REQUESTS,
                    f"busy: at most {limits.requests_per_client} data requests at once from one "
                    f"client and {limits.data_requests} in all; retry after {RETRY_AFTER_S} s",
                    retry=True,
                )
                return
            body = make()
            if len(body) != size:
                raise RuntimeError(f"an answer of {len(body)} bytes where {size} were planned")
            self._send(HTTPStatus.OK, body, content_type)

    def _meta(self, query: dict[str, list[str]]) -> Planned:
        body = self.server.meta_body
        return len(body), lambda: body, "application/json"

    def _bell_faces(self, query: dict[str, list[str]]) -> Planned:
        data = self.server.data
        if not data.has_bell:
            raise LookupError("the result has no bell")
        return data.bell_faces_bytes(), data.bell_faces, BINARY

    def _fluid_kinds(self, query: dict[str, list[str]]) -> Planned:
        data = self.server.data
        if not data.has_fluid:
            raise LookupError("the result has no fluid")
        return data.fluid_kinds_bytes(), data.fluid_kinds, BINARY

    def _frames(self, query: dict[str, list[str]]) -> Planned:
        values = {key: query.get(key, [""])[-1] for key in ("part", "start", "count")}
        factor = query.get("interpolation", [None])[-1]
        try:
            start, count = int(values["start"]), int(values["count"])
            interpolation = None if factor is None else int(factor)
        except ValueError:
            raise ValueError(
                "expected /frames?part=P&start=S&count=C[&interpolation=N], integers"
            ) from None
        data = self.server.data
        request = data.frame_request(values["part"], start, count, interpolation)
        return data.chunk_bytes(request), lambda: data.chunk(request), BINARY

    _data_routes: dict[str, Route] = {
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
    limits: ViewLimits | None = None,
) -> int:
    """Serve the result in ``folder`` until Ctrl-C (exit status 0), printing the page's address
    (with the session's token) and opening it in the default browser unless ``browser`` is
    False. ``ready`` is called with the listening server (tests stop it with
    ``server.shutdown()``); ``limits`` default to :class:`ViewLimits`'."""
    if not 0 <= port <= 65535:
        raise InputError(f"--port {port}: expected 0 (a free port) to 65535")
    with open_result(folder) as result:
        web_modules = find_web_modules()
        server = ViewServer(ResultData(result), web_modules, host, port, limits)
        try:
            url = server.page_url
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
