"""Scene overrides shared by several test modules (importable: pytest's pythonpath holds tests/).

``SMALL_MOON``: the moon-jelly preset shrunk to issue 6's test scale: l0 = 0.25 m, a bell 8 l0
wide and 5 l0 tall (448 particles) in a 22 x 22 x 18 l0 tank filled 15 l0 deep. Tests add the
duration, frame rate, tentacles and material they need.
"""

from __future__ import annotations

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
