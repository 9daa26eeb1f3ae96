"""Render speed of purple-jelly with its oral arms (issue 25's target: at 640x480 on 2 cores, at
most 2 s a frame in draft and 10 s in final quality).

    .venv/bin/python benchmarks/bench_render_purple.py [--duration 2] [--frames 4] [--threads 2]

Simulates purple-jelly (its marginal threads drawn by its preset's interpolation, and 4 ribbon
oral arms), writes the POV-Ray scenes of N frames spread over the run, and times each ``povray``
call alone (wall time, ``--threads`` POV-Ray threads, one frame at a time): parsing and tracing,
not the scene writing. Prints the seconds per frame (mean and worst), the scene's ribbon
triangles and the load average, since the machine may be shared.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

import jellysim
from jellysim.render import povray
from jellysim.render.frame import Frame
from jellysim.render.pipeline import frame_cameras, make_members


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--duration", type=float, default=2.0, help="simulated seconds")
    parser.add_argument("--frames", type=int, default=4, help="frames timed per quality")
    parser.add_argument("--threads", type=int, default=2, help="POV-Ray threads")
    parser.add_argument("--size", default="640x480")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    size = (width, height)
    binary = povray.find_povray()
    if binary is None:
        raise SystemExit("POV-Ray is not installed")
    done = subprocess.run([binary, "--version"], capture_output=True, text=True, check=False)
    version = next(
        (line for line in (done.stdout + done.stderr).splitlines() if line.startswith("POV-Ray")),
        "POV-Ray",
    )
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; {version}")
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder)
        result = jellysim.run("purple-jelly", out / "sim", overrides={"duration": args.duration})
        try:
            members = make_members([result], 1, None, 0, fluid=False)
            count = result.frames
            cameras, extent, _ = frame_cameras(members, count, size, "auto")
            fps = float(result.file.attrs["fps"])
            picked = np.linspace(count // 4, count - 1, args.frames).astype(int)
            print(f"{size[0]}x{size[1]}, frames {picked.tolist()} of {count}")
            print(f"{'quality':>8} {'s/frame':>8} {'worst':>7} {'ribbon tris':>11} {'load':>5}")
            for name in ("draft", "final"):
                quality = povray.QUALITIES[name]
                seconds, triangles = [], 0
                for index in picked:
                    frame = Frame(float(index) / fps, [m.frame(int(index)) for m in members])
                    text = povray.scene_text(frame, cameras[index], size, quality, extent)
                    found = re.findall(r"face_indices \{ (\d+)", text)
                    triangles = int(found[-1]) if len(found) > 1 else 0
                    scene = out / f"{name}_{index}.pov"
                    scene.write_text(text, encoding="utf-8")
                    start = time.perf_counter()
                    povray.render_file(
                        binary, scene, out / f"{name}_{index}.png", size, quality, args.threads
                    )
                    seconds.append(time.perf_counter() - start)
                load = os.getloadavg()[0]
                print(
                    f"{name:>8} {np.mean(seconds):8.2f} {max(seconds):7.2f} {triangles:11d} "
                    f"{load:5.2f}"
                )
        finally:
            result.close()


if __name__ == "__main__":
    main()
