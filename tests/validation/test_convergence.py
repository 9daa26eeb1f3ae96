"""Convergence in time: the tip's position after 1 s, as the substep halves (STYLE rule 10).

The integrator is backward Euler with a projection: first order. The error against a reference
run at a 16x smaller still substep must fall by about 2 each time dt halves (observed order >= 0.8).
"""

import numpy as np

import jellysim
from jellysim.simulation import Simulation

BASE = {
    "duration": 1.0,
    "fps": 10.0,
    "tentacles.count": 1,
    "tentacles.particles": 20,
    "tentacles.spacing": 0.02,
    "tentacles.youngs_modulus": 2.4e5,
    "flow.speed": 0.3,
    "flow.noise": 0.05,
    "root_motion.amplitude": 0.05,
    "root_motion.frequency": 1.0,
}


def tip_after_one_second(dt_safety: float) -> np.ndarray:
    scene = jellysim.load_scene("forced-tentacles", {**BASE, "solver.dt_safety": dt_safety})
    simulation = Simulation(scene)
    for _ in range(scene.frame_count - 1):
        simulation.step_frame()
    return simulation.positions[0, -1].copy()


def test_first_order_convergence_when_dt_halves():
    reference = tip_after_one_second(1.0 / 256)
    errors = [np.linalg.norm(tip_after_one_second(s) - reference) for s in (0.25, 0.125, 0.0625)]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert errors[0] > 1e-6  # the test resolves the error
    assert np.all(orders > 0.8), (errors, orders)
