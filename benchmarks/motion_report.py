"""How far each preset's tentacles bend away from straight, and their root-to-tip lag (issue 25,
"Motion that reads on screen"): the table in docs/figures.md.

    python benchmarks/motion_report.py [PRESET ...] [--set KEY=VALUE ...] [--out DIR]
    python benchmarks/motion_report.py --read RUN_DIR [--read RUN_DIR ...]

Runs each preset with its own defaults (the whole duration; the moon-jelly presets take 10-15
minutes each on 2 cores) and prints one Markdown row per preset and tentacle group, from
:func:`jellysim.io.motion.motion_by_group` over the second half of the run (a one-table preset
has one group, "tentacles"). A lag of "-" is a group whose roots do not move sideways relative
to the bell (no root motion to follow: coherence 0). ``--read`` measures finished runs instead
(their "run" column is "-").
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from _input import run_main  # benchmarks/: bad input in one line, exit 2

import jellysim
from jellysim.io.motion import motion_by_group

JELLYFISH = (
    "brown-jelly",
    "purple-jelly",
    "lions-mane",
    "forced-tentacles",
    "moon-jelly",
    "moon-jelly-real-size",
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("presets", nargs="*", default=list(JELLYFISH))
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    parser.add_argument("--out", default="out/motion-report")
    parser.add_argument("--read", action="append", default=[], help="a finished run's folder")
    args = parser.parse_args()
    columns = (
        "preset",
        "group",
        "tentacles",
        "analysed",
        "chord / length",
        "bend (mean, peak)",
        "root-to-tip lag",
        "coherence",
        "run",
    )
    print("| " + " | ".join(columns) + " |")
    print("|" + " --- |" * len(columns))
    for preset in args.read or args.presets:
        start = time.perf_counter()
        if args.read:
            opened = jellysim.open_result(preset)
        else:
            opened = jellysim.run(
                preset, Path(args.out) / preset, overrides=args.overrides or None, force=True
            )
        with opened as r:
            motions = motion_by_group(r)
            counts = {name: r.group_tentacles(name).size for name in motions}
        took = "-" if args.read else f"{time.perf_counter() - start:.0f} s"
        for name, m in motions.items():
            lag = f"{m.lag:.3g} s of {m.period:.3g} s" if m.coherence > 0.0 else "-"
            print(
                f"| `{preset}` | {name} | {counts[name]} | {m.start:.3g}-{m.end:.3g} s | "
                f"{m.chord:.3f} | {100 * m.bend:.1f} %, {100 * m.bend_peak:.1f} % | {lag} | "
                f"{m.coherence:.2f} | {took} |",
                flush=True,
            )


if __name__ == "__main__":
    run_main(main)
