"""Preview renderer speed: one synthetic frame, a bell of about 6,000 triangles and 300 tentacles
of 60 particles, rendered to a PNG at 640 x 480.

    .venv/bin/python benchmarks/bench_preview.py [--repeats N] [--quality draft|final] [--keep F]

Reports the wall time per frame (best, median) of ``render_preview`` (projection, shading, depth
sort, Agg rasterisation and the PNG write), after one warm-up call.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import tempfile
import time
from pathlib import Path

import matplotlib
import numpy as np

from jellysim.render.frame import Camera, Frame, Jellyfish, Look
from jellysim.render.preview import render_preview

RINGS, SECTORS = 31, 96  # 2 * SECTORS * (RINGS - 1) + SECTORS = 5,856 triangles
TENTACLES, PARTICLES = 300, 60


def dome(radius: float, height: float) -> tuple[np.ndarray, np.ndarray]:
    """An open UV hemisphere (apex up, margin at z = 0): vertices (V, 3) m and faces (M, 3),
    counter-clockwise seen from outside."""
    polar = np.linspace(0.0, 0.5 * np.pi, RINGS + 1)[1:]
    azimuth = 2.0 * np.pi * np.arange(SECTORS) / SECTORS
    rho = radius * np.sin(polar)[:, None] * np.ones(SECTORS)
    rings = np.stack(
        [rho * np.cos(azimuth), rho * np.sin(azimuth), height * np.cos(polar)[:, None] + 0 * rho],
        axis=-1,
    ).reshape(-1, 3)
    vertices = np.concatenate([[[0.0, 0.0, height]], rings])
    j = np.arange(SECTORS)
    jn = (j + 1) % SECTORS
    faces = [np.stack([np.zeros(SECTORS, int), 1 + j, 1 + jn], axis=1)]
    for ring in range(RINGS - 1):
        a, b = 1 + ring * SECTORS, 1 + (ring + 1) * SECTORS
        faces.append(np.stack([a + j, b + j, b + jn], axis=1))
        faces.append(np.stack([a + j, b + jn, a + jn], axis=1))
    return vertices, np.concatenate(faces)


def synthetic_frame() -> Frame:
    vertices, faces = dome(0.15, 0.1)
    angle = 2.0 * np.pi * np.arange(TENTACLES) / TENTACLES
    s = np.linspace(0.0, 1.0, PARTICLES)
    sway = 0.03 * np.sin(3.0 * angle)[:, None] * s**2
    radial = 0.14 + sway
    tentacles = np.stack(
        [
            radial * np.cos(angle)[:, None],
            radial * np.sin(angle)[:, None],
            -0.6 * s + 0 * radial,
        ],
        axis=-1,
    )
    return Frame(0.0, [Jellyfish(tentacles, vertices, faces, Look())])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--quality", default="draft")
    parser.add_argument("--keep", type=Path, help="also write the image here")
    args = parser.parse_args()
    frame = synthetic_frame()
    jellyfish = frame.jellyfish[0]
    assert jellyfish.bell_faces is not None
    camera = Camera(np.array([0.9, -0.6, 0.1]), np.array([0.0, 0.0, -0.2]), angle=50.0)
    print(
        f"machine: {platform.processor() or platform.machine()}; matplotlib "
        f"{matplotlib.__version__}, numpy {np.__version__}; {len(jellyfish.bell_faces)} "
        f"triangles, {TENTACLES} x {PARTICLES} tentacle particles, 640 x 480, {args.quality}"
    )
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "frame.png"
        render_preview(frame, camera, (640, 480), path, args.quality)  # warm-up
        times = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            render_preview(frame, camera, (640, 480), path, args.quality)
            times.append(time.perf_counter() - start)
        if args.keep:
            args.keep.write_bytes(path.read_bytes())
    print(f"per frame: best {min(times):.3f} s, median {statistics.median(times):.3f} s")


if __name__ == "__main__":
    main()
