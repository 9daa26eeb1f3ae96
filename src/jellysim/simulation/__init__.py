"""Simulations frame by frame (DESIGN §1): the loop contract and its registry (:mod:`.loop`), the
three loops (:mod:`.tentacles`, :mod:`.fluid`, :mod:`.soft`) and the run that stores any of them
(:mod:`.run`).

``Simulation(scene)`` builds the loop for any scene the schema accepts; ``run(scene, out=...)``
runs it to ``result.h5``.
"""

from jellysim.simulation import fluid, soft, tentacles  # noqa: F401  (register the loops)
from jellysim.simulation.loop import LOOPS, FrameLoop, Observer, Simulation, loop_name, make_loop
from jellysim.simulation.run import SCENE_FILE, default_out, run

__all__ = [
    "LOOPS",
    "SCENE_FILE",
    "FrameLoop",
    "Observer",
    "Simulation",
    "default_out",
    "loop_name",
    "make_loop",
    "run",
]
