"""A relaxed soft bell in water under gravity stays where it is (issue 6: "a relaxed bell in
still water stays still"; neutral buoyancy in an open-top tank with gravity, paper §4.2.2).

The bell's particles are water particles, so the bell is neutrally buoyant by construction;
whether it stays still is a question of whether the water does. The coarse moon-jelly
configuration of tests/scenes.py (l0 = 0.25 m, 448 bell particles) with gravity, the muscle
off, 2 s, the mixed source (Tanaka & Masunaga 2010) and the corrected gradient (Khayyer &
Gotoh 2011). Measured 2026-11-24: the bell's centre stays within 0.16 l0 of its start (0 across),
no bell particle moves more than 0.63 l0, the water's particles 0.54 l0 on average. With the
standard scheme the same bell (no tentacles) is thrown 17 l0 upwards within the 2 s
(docs/soft-bell.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scenes

import jellysim

RELAXED_IN_GRAVITY = {
    **scenes.SMALL_MOON,
    "duration": 2.0,
    "fps": 10.0,
    "tentacles.count": 2,
    "bell.spring_stiffness": 31.25,
    "bell.muscle_ratio": 0.0,
    "bell.muscle_stiffening": 1.0,
    "water.gravity": [0.0, 0.0, -9.81],
    "fluid.source": "mixed",
    "fluid.gradient": "corrected",
}


def test_relaxed_bell_stays_still_in_water_under_gravity(tmp_path: Path) -> None:
    l0 = float(RELAXED_IN_GRAVITY["fluid.spacing"])  # type: ignore[arg-type]
    with jellysim.run("moon-jelly", tmp_path, overrides=RELAXED_IN_GRAVITY) as result:
        assert result.complete
        time = np.asarray(result.time)
        frames = len(time)
        centre = np.asarray(result.file["bell/centre"][:frames])
        bell = np.asarray(result.file["bell/position"][:frames])
        water = np.asarray(result.file["fluid/position"][:frames])
        fluid = np.asarray(result.file["fluid/kind"][:]) == 0
        alive = np.asarray(result.file["fluid/alive"][frames - 1])
    assert time[-1] >= 2.0 - 1e-9
    centre_drift = np.abs(centre - centre[0]).max(axis=0) / l0
    particle_drift = np.sqrt(((bell - bell[0]) ** 2).sum(axis=-1)).max() / l0
    kept = fluid & alive
    water_drift = np.sqrt(((water[-1, kept] - water[0, kept]) ** 2).sum(axis=-1)) / l0
    print(
        f"bell centre drift (x, y, z) {centre_drift.round(3)} l0, largest bell particle move "
        f"{particle_drift:.2f} l0, water drift mean {water_drift.mean():.2f} l0"
    )
    assert np.all(centre_drift < 0.25)
    assert particle_drift < 1.0
    assert water_drift.mean() < 1.0
