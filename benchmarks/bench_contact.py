"""Cost of keeping the tentacles out of the bell (``bell.tentacle_contact``, docs/theory/
tentacle.md §8) at the full ``moon-jelly``, in its first contraction, where the margin lies on
the fringe.

    .venv/bin/python benchmarks/bench_contact.py [--frames 14] [--repeats 5]

Runs ``moon-jelly`` for ``--frames`` frames (0.7 s: the margin has swept over the fringe since
0.55 s), then times the tentacles' next frame from that state with the contact and without it
(the mean of the repeats, the state restored before each), beside one frame of the bell in its
water; prints how many of the fringe's particles end that frame inside the wall without the
contact.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

import jellysim
from jellysim.tentacle.contact import inside_shell, shell_obstacle


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=14)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    simulation = jellysim.Simulation(jellysim.load_scene("moon-jelly", {"duration": 2.0}))
    simulation.prepare()
    for _ in range(args.frames):
        simulation.step_frame()
    c = simulation.coupling  # type: ignore[attr-defined]
    tentacles = simulation.tentacles  # type: ignore[attr-defined]
    start_surface = c.skin.surface(c.position)
    begin = time.perf_counter()
    c.advance((simulation.frame + 1) * simulation.frame_dt, simulation.frame_dt)
    c.record(simulation.frame + 1)
    bell_frame = time.perf_counter() - begin
    obstacle = shell_obstacle(start_surface, c.skin.surface(c.position), c.skin.faces)
    water = [tentacles._water(group) for group in tentacles.groups]
    saved = [(g.positions.copy(), g.velocities.copy()) for g in tentacles.groups]

    def frame(with_contact: bool) -> float:
        total = 0.0
        for _ in range(args.repeats):
            for group, (x, v) in zip(tentacles.groups, saved, strict=True):
                group.positions[:] = x
                group.velocities[:] = v
            begin = time.perf_counter()
            for group, w in zip(tentacles.groups, water, strict=True):
                group.step_frame(tentacles.frame, w, obstacle if with_contact else None)
            total += time.perf_counter() - begin
        return total / args.repeats

    frame(True)  # compile, if the cache is cold
    with_contact, without = frame(True), frame(False)
    # What the contact prevents: the fringe's particles inside the wall after the frame without it.
    corners = np.empty((3, 3))
    fringe = tentacles.groups[0].positions[:, 1:].reshape(-1, 3)
    inside = sum(bool(inside_shell(p, obstacle, 1.0, corners)) for p in fringe)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; "
        f"t = {simulation.time + simulation.frame_dt:.2f} s, {len(c.skin.faces)} triangles\n"
        f"tentacles' frame: {1e3 * without:.2f} ms without the contact, "
        f"{1e3 * with_contact:.2f} ms with it (+{1e3 * (with_contact - without):.2f} ms); "
        f"the bell in its water: {bell_frame:.2f} s a frame "
        f"({100 * (with_contact - without) / bell_frame:.2f} % of it); "
        f"without it {inside} of the {len(fringe)} free fringe particles end the frame "
        "inside the wall"
    )


if __name__ == "__main__":
    main()
