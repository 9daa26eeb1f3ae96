"""Scene overrides shared by several test modules (importable: pytest's pythonpath holds tests/).

``SMALL_MOON``: the moon-jelly preset shrunk to issue 6's test scale: l0 = 0.25 m, a bell 8 l0
wide and 5 l0 tall (448 particles) in a 22 x 22 x 18 l0 tank filled 15 l0 deep. Tests add the
duration, frame rate, tentacles and material they need.

``SWIM``: SMALL_MOON for three 2 s pulses (``SWIM_PERIOD``) at 10 frames a second with two
marginal tentacles (and the preset's four oral arms), k = 31.25 N/m (20 N/m x 0.25 / 0.16,
the paper's material at this spacing) and the paper's uniform muscle band (0.3 of the height, no
taper: the preset's until issue 26); ``MUSCLE_OFF`` the muscle neither contracting nor
stiffening, ``SWIM_OFF`` SWIM with it.

``SMALL_FINE``: moon-jelly-fine's lattice and wall (l0 = 0.16 m / 3, the 0.32 m wall six particles
thick) on a bell 30 l0 wide and 12 l0 tall (4,628 particles, 104,112 springs) in a 36 x 36 x 21 l0
tank filled 18 l0 deep: 18,700 water particles where the preset has 1.5 million.

``one_table(preset)``: a grouped preset's tree with its tentacles as one ``[tentacles]`` table of
the shared keys (the moon-jelly presets before issue 25 gave them oral arms: the scene that
older stored results and checkpoints were made from).
"""

from __future__ import annotations

from typing import Any

from jellysim.config.scenes import scene_source_tree


def one_table(preset: str) -> dict[str, Any]:
    """``preset``'s tree with only the shared ``[tentacles]`` keys: its groups dropped."""
    tree = dict(scene_source_tree(preset))
    tree["tentacles"] = {
        key: value for key, value in tree["tentacles"].items() if not isinstance(value, dict)
    }
    return tree


SMALL_MOON: dict[str, object] = {
    "fluid.spacing": 0.25,
    "bell.height": 1.25,
    "bell.thickness": 0.4,
    "bell.margin_height": 1.0,
    "fluid.tank_width": 5.5,
    "fluid.tank_depth": 5.5,
    "fluid.tank_height": 4.5,
    "fluid.water_height": 3.75,
}

SMALL_FINE: dict[str, object] = {
    "bell.radius": 0.8,
    "bell.height": 0.64,
    "bell.thickness": 0.5,
    "bell.margin_height": 0.16,
    "fluid.tank_width": 1.92,
    "fluid.tank_depth": 1.92,
    "fluid.tank_height": 1.12,
    "fluid.water_height": 0.96,
}

SWIM_PERIOD = 2.0
SWIM: dict[str, object] = {
    **SMALL_MOON,
    "duration": 3 * SWIM_PERIOD,
    "fps": 10.0,
    "tentacles.count": 2,
    "bell.spring_stiffness": 31.25,
    "bell.muscle_band": 0.3,
    "bell.muscle_taper": 0.0,
    "bell.period": SWIM_PERIOD,
}
MUSCLE_OFF: dict[str, object] = {"bell.muscle_ratio": 0.0, "bell.muscle_stiffening": 1.0}
SWIM_OFF: dict[str, object] = {**SWIM, **MUSCLE_OFF}
