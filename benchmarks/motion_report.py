"""How far each preset's tentacles bend away from straight, and their root-to-tip lag (issue 25,
"Motion that reads on screen"): the table in docs/figures.md.

    python benchmarks/motion_report.py [PRESET ...] [--set KEY=VALUE ...] [--out DIR]

Runs each preset with its own defaults (the whole duration; the moon-jelly presets take 10-15
minutes each on 2 cores) and prints one Markdown row per preset, from
:func:`jellysim.io.motion.tentacle_motion` over the second half of the run.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jellysim
from jellysim.io.motion import tentacle_motion

JELLYFISH = ("brown-jelly", "forced-tentacles", "moon-jelly", "moon-jelly-real-size")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("presets", nargs="*", default=list(JELLYFISH))
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    parser.add_argument("--out", default="out/motion-report")
    args = parser.parse_args()
    columns = ("preset", "analysed", "chord / length", "bend (mean, peak)", "root-to-tip lag")
    print("| " + " | ".join((*columns, "coherence", "run")) + " |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for preset in args.presets:
        start = time.perf_counter()
        with jellysim.run(
            preset, Path(args.out) / preset, overrides=args.overrides or None, force=True
        ) as r:
            m = tentacle_motion(r)
        took = time.perf_counter() - start
        print(
            f"| `{preset}` | {m.start:.3g}-{m.end:.3g} s | {m.chord:.3f} | "
            f"{100 * m.bend:.1f} %, {100 * m.bend_peak:.1f} % | {m.lag:.3g} s of {m.period:.3g} s "
            f"| {m.coherence:.2f} | {took:.0f} s |",
            flush=True,
        )


if __name__ == "__main__":
    main()
