"""Swim per pulse of the soft bell with tentacles that act on the water, with tentacles that only
follow it, with the paper's assumed flow, and with no tentacles (issue 26; docs/soft-bell.md,
"Tentacles in the simulated water").

    .venv/bin/python benchmarks/swim_with_tentacles.py [--full] [--set KEY=VALUE ...]

By default at the tests' coarse scale (``tests/scenes.py`` SWIM: the weightless moon jelly at
l0 = 0.25 m, three 2 s pulses, ten marginal tentacles and the four oral arms); ``--full`` runs
``moon-jelly-weightless`` as it is (13-15 minutes a case on 2 cores). Prints per case the rise of
the bell's centre in each pulse (m and bell diameters) and in all. ``--set`` applies to every
case (e.g. ``fluid.courant=0.15``: another step sequence, to see what is round-off's);
``--case NAME`` runs only the named cases (the one-way cases cannot change the bell: they give
the no-tentacle rise to the bit).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import scenes  # noqa: E402
from _input import run_main  # benchmarks/: bad input in one line, exit 2

import jellysim  # noqa: E402
from jellysim.bell.swimming import swim_cycles  # noqa: E402
from jellysim.config.load import parse_override  # noqa: E402

CASES = {
    "no tentacles": {"tentacles.count": 0},
    "assumed flow (paper)": {},
    "simulated water, one-way": {"flow.model": "fluid"},
    "simulated water, two-way": {"flow.model": "fluid", "flow.two_way": True},
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true")
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    parser.add_argument(
        "--case", dest="cases", action="append", choices=list(CASES),
        help="run only this case (repeatable); default: all four",
    )  # fmt: skip
    args = parser.parse_args()
    base: dict[str, object] = {} if args.full else {**scenes.SWIM, "tentacles.count": 10}
    base.update(parse_override(item) for item in args.overrides)
    period = 2.0 if args.full else scenes.SWIM_PERIOD
    print("| case | rise per pulse [m] | in diameters | total [m] | wall [s] |")
    print("| --- | --- | --- | ---: | ---: |")
    for name, overrides in CASES.items():
        if args.cases and name not in args.cases:
            continue
        tree: str | dict[str, object] = "moon-jelly-weightless"
        if overrides.get("tentacles.count") == 0:
            tree = scenes.one_table("moon-jelly-weightless")  # a bell with no tentacle group
        scene = jellysim.load_scene(tree, {**base, **overrides})
        with tempfile.TemporaryDirectory() as folder:
            start = time.perf_counter()
            with jellysim.run(scene, folder) as r:
                wall = time.perf_counter() - start
                height = r.bell_centre[:, 2]
                pulses = swim_cycles(r.time, height, r.bell_contraction, period)
        diameter = 2.0 * scene.bell.radius
        rises = ", ".join(f"{p.rise:.3f}" for p in pulses)
        relative = ", ".join(f"{p.rise / diameter:.3f}" for p in pulses)
        print(
            f"| {name} | {rises} | {relative} | {height[-1] - height[0]:.3f} | {wall:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    run_main(main)
