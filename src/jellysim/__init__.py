"""jellysim: simulate and animate jellyfish after Hirato & Kawaguchi.

Python API (the same powers as the command line)::

    import jellysim
    scene = jellysim.load_scene("brown-jelly", {"tentacles.youngs_modulus": 2.4e5})
    result = jellysim.run(scene, out="out/stiff", force=True)
    with jellysim.open_result("out/stiff") as r:
        tip_x = r.tentacle_positions[:, 0, -1, 0]
"""

import jellysim._threads  # noqa: F401  (chooses Numba's threading layer before any kernel runs)
from jellysim._version import __version__
from jellysim.config import Scene, load_scene, scene_to_toml
from jellysim.errors import InputError, JellysimError, SimulationUnstable
from jellysim.interpolation import interpolate_result
from jellysim.io.result import Result, open_result
from jellysim.simulation import Simulation, run
from jellysim.species import preset_names
from jellysim.studies import sweep

__all__ = [
    "InputError",
    "JellysimError",
    "Result",
    "Scene",
    "Simulation",
    "SimulationUnstable",
    "__version__",
    "interpolate_result",
    "load_scene",
    "open_result",
    "preset_names",
    "run",
    "scene_to_toml",
    "sweep",
]
