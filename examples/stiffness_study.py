"""A parameter study in a script: how far the tentacles of the forced-tentacles scene bend and
trail as Young's modulus varies (the paper's Fig. 5 question), with the sweep API, the per-group
motion measures and a tidy table (pandas) written as CSV.

    .venv/bin/python examples/stiffness_study.py [OUT.csv] [--duration S]

Each value is one run in memory (``jellysim.sweep`` for the root and tip traces) plus one run to a
folder for the motion measures; the table has one row per value: E, the tip's x range, and the
tentacles' chord, mean bend and root-to-tip lag over the second half of the run.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import pandas as pd

import jellysim
from jellysim.io.motion import motion_by_group

SCENE = "forced-tentacles"
MODULI = (100.0, 1e3, 1e4, 2.4e5)  # Pa: the presets' soft tentacles to the paper's stiffest Case 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default="out/stiffness_study.csv")
    parser.add_argument("--duration", type=float, default=4.0, help="simulated seconds per run")
    args = parser.parse_args()
    base = {"duration": args.duration, "tentacles.count": 2}
    traces = jellysim.sweep(SCENE, "tentacles.youngs_modulus", MODULI, base)
    rows = []
    for modulus, trace in zip(MODULI, traces, strict=True):
        scene = jellysim.load_scene(SCENE, {**base, "tentacles.youngs_modulus": modulus})
        with tempfile.TemporaryDirectory() as folder:
            with jellysim.run(scene, folder) as result:
                (motion,) = motion_by_group(result).values()  # the scene's one group
        rows.append(
            {
                "youngs_modulus_Pa": modulus,
                "tip_x_range_m": float(trace.tip_x.max() - trace.tip_x.min()),
                "chord_per_length": motion.chord,
                "mean_bend_per_length": motion.bend,
                "root_to_tip_lag_s": motion.lag,
            }
        )
    table = pd.DataFrame(rows)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out, index=False)
    print(table.to_string(index=False))
    print(args.out)


if __name__ == "__main__":
    main()
