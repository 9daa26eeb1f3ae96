"""Render speed: seconds per frame of brown-jelly at 640x480 (issue 4's targets).

    .venv/bin/python benchmarks/bench_render.py [--frames 24] [--renderer povray]

Simulates brown-jelly's marginal group alone (its six tentacles, no oral arms: comparable with
earlier figures) once (10 s), then renders frames 0 to N-1 with 60 and with 300 drawn
tentacles (interpolation 10 and 50) in draft and final quality, frames in parallel over every
core (one POV-Ray thread per frame). Seconds per frame = wall time of the render / N (scene
writing included, video encoding excluded).
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import tempfile
import time
from pathlib import Path

import jellysim
from jellysim.render.pipeline import render


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--renderer", default="povray", choices=("povray", "preview"))
    parser.add_argument("--size", default="640x480")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    version = ""
    if args.renderer == "povray":
        done = subprocess.run(["povray", "--version"], capture_output=True, text=True, check=False)
        lines = (done.stdout + done.stderr).splitlines()
        version = next((line for line in lines if line.startswith("POV-Ray")), "")
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; {version or args.renderer}")
    with tempfile.TemporaryDirectory() as folder:
        marginal = jellysim.load_scene("brown-jelly").group_scene(0)
        result = jellysim.run(marginal, Path(folder) / "sim")
        print(f"{'tentacles':>9} {'quality':>8} {'s/frame':>8}")
        for interpolation in (10, 50):
            for quality in ("draft", "final"):
                out = Path(folder) / f"r{interpolation}{quality}"
                start = time.perf_counter()
                render(
                    [result],
                    out,
                    renderer=args.renderer,
                    quality=quality,
                    size=(width, height),
                    interpolation=interpolation,
                    frames=(0, args.frames),
                    video=False,
                )
                per_frame = (time.perf_counter() - start) / args.frames
                drawn = interpolation * result.scene.tentacles.count
                print(f"{drawn:>9d} {quality:>8} {per_frame:>8.2f}")
        result.close()


if __name__ == "__main__":
    main()
