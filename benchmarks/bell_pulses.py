"""Does the moon-jelly bell re-open and keep swimming? Five 2 s pulses of the tests' coarse moon
jelly (tests/scenes.py SWIM: l0 = 0.25 m, 448 bell particles) at several multiples of the paper's
spring stiffness (issue 26; the table in docs/soft-bell.md, "A bell that pulses").

    python benchmarks/bell_pulses.py [FACTOR ...] [--out DIR]

For each factor F the springs are F x 31.25 N/m (the paper's k = 20 N/m at l0 = 0.16 m, scaled to
this spacing); printed per pulse: the peak contraction, the lowest contraction after it within
the pulse, and the rise of the bell's centre; the muscle is the preset's. The preset's factor is 16.

``--full`` runs the ``moon-jelly`` preset itself (l0 = 0.16 m, its 320 N/m springs, five 2 s
pulses; 35-65 minutes on 2 cores) and ignores the factors; ``--preset NAME`` runs another
soft-bell preset so (``moon-jelly-fine``: its 1.5 million water particles want a GPU);
``--set KEY=VALUE`` (repeatable) changes a key of it as ``jellysim run --set`` does, e.g.
``--set bell.spring_stiffness=320`` or ``--set fluid.device='"cuda"'``. ``--pulses N`` runs N
pulses instead of five; ``--no-tentacles`` leaves the preset's tentacle groups out (the bell
alone: with ``flow.two_way`` false, the preset's, tentacles do not act on the bell or the
water). The time printed is the whole run's wall time, set-up and compilation included; the
run's log (stderr) ends with its time per phase.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from _input import run_main  # benchmarks/: bad input in one line, exit 2
from scenes import SWIM, SWIM_PERIOD  # noqa: E402

import jellysim  # noqa: E402
from jellysim.cli.main import log_to_stderr  # noqa: E402
from jellysim.config.load import parse_override  # noqa: E402

PULSES = 5
PAPER_K_COARSE = 31.25  # N/m: 20 N/m x 0.25 / 0.16
PERIOD = 2.0  # s, the pulse of the moon-jelly presets (moon-jelly-fine's too)


def pulses(
    factor: float | None,
    out: Path,
    changes: dict[str, object] | None = None,
    count: int = PULSES,
    scene: str = "moon-jelly",
) -> list[tuple[float, float, float]]:
    """(peak, lowest after it, rise in m) for each of ``count`` pulses of the run at ``factor``
    (None: the ``moon-jelly`` preset, or the scene file ``scene``, with ``changes``)."""
    overrides: dict[str, object] = {"duration": count * PERIOD, **(changes or {})}
    if factor is not None:
        # SWIM's material is the paper's; the factor sets the springs, the preset the muscle
        coarse = {k: v for k, v in SWIM.items() if not k.startswith("bell.muscle_")}
        overrides.update(coarse, duration=count * SWIM_PERIOD)
        overrides["bell.spring_stiffness"] = PAPER_K_COARSE * factor
    period = PERIOD if factor is None else SWIM_PERIOD
    with jellysim.run(scene, out, overrides=overrides, force=True) as result:
        t = np.asarray(result.time)
        contraction = result.bell_contraction
        height = result.bell_centre[:, 2]
    rows = []
    for k in range(count):
        first = int(np.argmin(np.abs(t - k * period)))
        last = int(np.argmin(np.abs(t - (k + 1) * period)))
        peak = first + int(np.argmax(contraction[first : last + 1]))
        rows.append(
            (
                float(contraction[peak]),
                float(contraction[peak : last + 1].min()),
                float(height[last] - height[first]),
            )
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("factors", nargs="*", type=float, default=[1.0, 16.0, 64.0, 256.0])
    parser.add_argument("--out", default="out/bell-pulses")
    parser.add_argument("--full", action="store_true")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--pulses", type=int, default=PULSES)
    parser.add_argument("--no-tentacles", action="store_true")
    parser.add_argument("--preset", default="moon-jelly")
    args = parser.parse_args()
    if args.set and not args.full:
        parser.error("--set changes the preset's own run: use it with --full")
    # the run's notices, among them its time per phase at the end (the springs' implicit solve,
    # the water's phases), as `jellysim run` shows them
    log_to_stderr()
    scene = args.preset
    if args.no_tentacles:
        import tomli_w

        from jellysim.config.scenes import scene_source_tree

        tree = {**scene_source_tree(args.preset), "tentacles": {"count": 0}}
        Path(args.out).mkdir(parents=True, exist_ok=True)
        scene = str(Path(args.out) / f"{args.preset}-bell-only.toml")
        Path(scene).write_text(tomli_w.dumps(tree))
    changes: dict[str, object] = dict(parse_override(item) for item in args.set)
    factors: list[float | None] = [None] if args.full else list(args.factors)
    for factor in factors:
        start = time.perf_counter()
        name = "full" if factor is None else f"k{factor:g}"
        rows = pulses(
            factor,
            Path(args.out) / name,
            changes if factor is None else None,
            args.pulses,
            scene,
        )
        label = (
            (f"{Path(scene).stem} as it is" + "".join(f", {item}" for item in args.set))
            if factor is None
            else (f"factor {factor:g} (k = {PAPER_K_COARSE * factor:g} N/m)")
        )
        print(f"{label}, {time.perf_counter() - start:.0f} s", flush=True)
        for k, (peak, lowest, rise) in enumerate(rows):
            print(f"  pulse {k}: peak {peak:.3f}, lowest after it {lowest:.3f}, rise {rise:+.3f} m",
                  flush=True)  # fmt: skip


if __name__ == "__main__":
    run_main(main)
