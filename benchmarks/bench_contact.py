"""Cost of keeping the tentacles out of the bell (``bell.tentacle_contact``, docs/theory/
tentacle.md §8) at the full ``moon-jelly``, in its first contraction, where the margin lies on
the fringe.

    .venv/bin/python benchmarks/bench_contact.py [--frames 14] [--repeats 5]
    .venv/bin/python benchmarks/bench_contact.py --recorded [--repeats 20]

Runs ``moon-jelly`` for ``--frames`` frames (0.7 s: the margin has swept over the fringe since
0.55 s), then times the tentacles' next frame from that state with the contact and without it
(the mean of the repeats, the state restored before each), beside one frame of the bell in its
water; prints how many of the fringe's particles end that frame inside the wall without the
contact. With ``--recorded``, instead: the best of the repeats of each recorded fringe frame of
``tests/data/moon_jelly_fringe_*.npz`` (one tentacle, tests/data/README.md) through the kernel,
with the contact and without it, loading included.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

import jellysim
from jellysim.bell.kinematic import bell_faces
from jellysim.tentacle.contact import inside_shell, no_obstacle, shell_obstacle
from jellysim.tentacle.kernels import ChainModel, Medium, advance_frame

RECORDED = Path(__file__).parents[1] / "tests" / "data"


def recorded_frame(path: Path, contact: bool) -> None:
    """One recorded frame of one fringe tentacle through :func:`advance_frame`."""
    data = np.load(path)

    def fields(prefix: str, names: tuple[str, ...]) -> dict[str, object]:
        values = {name: data[f"{prefix}_{name}"] for name in names}
        return {name: v.item() if v.ndim == 0 else v for name, v in values.items()}

    obstacle = shell_obstacle(data["shell_start"], data["shell_end"], bell_faces(50))
    x = data["positions"][None].copy()
    advance_frame(
        x, data["velocities"][None].copy(), data["root_positions"][:, None],
        data["root_velocities"][:, None], data["root_directions"][:, None],
        data["curl_normals"][:, None], np.zeros_like(x), data["flow"][:, None],
        ChainModel(**fields("model", ChainModel._fields)),
        Medium(**fields("medium", Medium._fields)), float(data["dt"]), np.zeros((1, 3)),
        np.zeros((1, 0, 3)), obstacle if contact else no_obstacle(),
    )  # fmt: skip


def time_recorded(repeats: int) -> None:
    for path in sorted(RECORDED.glob("moon_jelly_fringe_*.npz")):
        best = {}
        for contact in (True, False):
            recorded_frame(path, contact)  # compile, if the cache is cold
            times = []
            for _ in range(repeats):
                begin = time.perf_counter()
                recorded_frame(path, contact)
                times.append(time.perf_counter() - begin)
            best[contact] = min(times)
        print(
            f"{path.stem}: {1e3 * best[True]:.2f} ms with the contact, "
            f"{1e3 * best[False]:.2f} ms without"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=14)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--recorded", action="store_true")
    args = parser.parse_args()
    if args.recorded:
        time_recorded(args.repeats)
        return
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
