"""Two-way coupling in a closed system: the momentum of water plus tentacles (issue 26).

Newton's third law, as the coupling of docs/theory/soft-bell.md §8 builds it: the drag impulse
J a particle takes from the water over a frame goes back to the water, shared over its
neighbours with the weights of Eq. (S2), in the next frame. In a system that nothing outside
acts on, water plus particles then keep their momentum, up to the impulse of the frame not yet
handed back:

    P_water(t_k) + P_particles(t_k) - J_k = P(0).

The closed system is a weightless drop of water with no walls (docs/decisions.md, "A closed
box for the momentum check": in a rigid box the walls are an external force that takes up any
net push at once, since the water's momentum in a full rigid box is zero by continuity). The
particles stand for tentacle particles: a chain's bending and length forces cancel pair by pair
and its root is driven from outside, so free particles are the chain without its external
force. The water conserves what it receives only with a pair-wise antisymmetric pressure
gradient, Eq. (F10c) [Khayyer & Gotoh 2008, Coast. Eng. J. 50, 179-207]; the viscosity and the
collisions are pair-wise already. The standard minimum-pressure gradient, Eq. (F10)
[Koshizuka & Oka 1996], is not, and the same run with it loses the balance by a measurable
amount, which this test also states.
"""

from __future__ import annotations

import math

import numpy as np

from jellysim.coupling.water_at import solver_water_velocity_at, spread_reaction
from jellysim.fluid.frames import FrameStats, advance_to
from jellysim.fluid.geometry import FLUID, water_block
from jellysim.fluid.mps import MPSParameters, MPSSolver
from jellysim.tentacle.kernels import drag_gain

L0 = 0.02  # m
SIZE = 0.3  # m, the drop's side: 15 particles across
FRAME = 0.02  # s
FRAMES = 10
SUBSTEPS = 10  # particle steps a frame
DIAMETER = 0.01  # m, the particles (a thick tentacle)
PARTICLE_DENSITY = 1050.0  # kg/m3
WATER_DENSITY = 1000.0
VISCOSITY = 1e-5  # m2/s, ten times water's: the viscosity acts in a few frames too
THROW = 0.3  # m/s, the particles' start velocity along x


def momentum_balance(gradient: str) -> tuple[float, float, float]:
    """Run the drop with the particles thrown through it; returns the largest |P(t_k) - J_k -
    P(0)| over the frames, |P(0)| and the largest |P_water| reached (N s)."""
    params = MPSParameters(
        dim=3,
        l0=L0,
        density=WATER_DENSITY,
        kinematic_viscosity=VISCOSITY,
        gravity=(0.0, 0.0, 0.0),
        gradient=gradient,
        solver="iccg",
        tolerance=1e-10,
    )
    water = water_block(0.0, SIZE, 0.0, SIZE, L0, 0.0, SIZE)
    solver = MPSSolver(params, water, np.full(len(water), FLUID, dtype=np.int8))
    water_mass = WATER_DENSITY * L0**3
    count = 12
    points = np.zeros((count, 3))
    points[:, 0] = np.linspace(0.09, 0.19, count)
    points[:, 1] = 0.15 + 0.01 * np.sin(np.arange(count))
    points[:, 2] = 0.15 + 0.01 * np.cos(np.arange(count))
    velocity = np.zeros((count, 3))
    velocity[:, 0] = THROW
    mass = PARTICLE_DENSITY * math.pi * DIAMETER**3 / 6.0
    start = mass * velocity.sum(axis=0)
    reaction = np.zeros_like(solver.position)  # force density (N/m3) over the next frame

    def force(time: float, dt: float) -> np.ndarray:
        return reaction

    stats = FrameStats()
    worst, largest_water = 0.0, 0.0
    for frame in range(FRAMES):
        sampled = points.copy()
        flow = solver_water_velocity_at(solver, sampled)
        impulse = np.zeros_like(points)
        h = FRAME / SUBSTEPS
        for _ in range(SUBSTEPS):  # implicit sphere drag, Eq. (T5), in the sampled water
            for i in range(count):
                relative = flow[i] - velocity[i]
                gain = drag_gain(
                    float(np.linalg.norm(relative)), DIAMETER, WATER_DENSITY,
                    VISCOSITY * WATER_DENSITY,
                )  # fmt: skip
                new = (mass * velocity[i] + gain * h * flow[i]) / (mass + gain * h)
                impulse[i] += mass * (new - velocity[i])
                velocity[i] = new
            points += h * velocity
        # the last frame's reaction reaches the water over this frame (BellInFluid)
        advance_to(solver, (frame + 1) * FRAME, FRAME, stats, FRAME / 5, force)
        fluid = np.flatnonzero(solver.alive & (solver.kind == FLUID))
        assert len(fluid) == len(water)  # the drop holds together
        radius = solver.constants.re_number_density
        given = spread_reaction(sampled, impulse, solver.position[fluid], radius)
        reaction[:] = 0.0
        reaction[fluid] = given / (FRAME * L0**3)
        p_water = water_mass * solver.velocity[fluid].sum(axis=0)
        p_particles = mass * velocity.sum(axis=0)
        pending = impulse.sum(axis=0)
        worst = max(worst, float(np.abs(p_water + p_particles - pending - start).max()))
        largest_water = max(largest_water, float(np.abs(p_water).max()))
    return worst, float(np.abs(start).max()), largest_water


def test_water_and_particles_keep_their_momentum_with_the_conservative_gradient() -> None:
    """With Eq. (F10c) the balance holds to round-off: measured 3.5e-18 N s against the
    2.0e-3 N s thrown (2e-15 of it; 2026-11-26). The bound, 1e-12 of the thrown momentum, is
    round-off's scale with a wide margin (each step's pair impulses cancel to a few ulps of
    velocity changes of ~1e-3 m/s, over ~1e5 pairs and 50 steps) and still fails for any lost
    share of J, any impulse given twice or a frame late, or a force that is not pair-wise."""
    worst, thrown, water = momentum_balance("conservative")
    assert water > 0.3 * thrown  # the water has taken a good part of the momentum
    assert worst < 1e-12 * thrown, (worst, thrown)


def test_the_standard_gradient_does_not_keep_the_momentum() -> None:
    """Eq. (F10) weighs a pair by p_j - p_min,i from one side and p_i - p_min,j from the other:
    the same run loses 9.5e-7 N s, 5e-4 of what was thrown (2026-11-26), nine orders of
    magnitude above round-off. The check asserts a tenth of that; it is why the budget needs
    Eq. (F10c), and why a two-way run's momentum is only as well kept as its gradient keeps it
    (docs/soft-bell.md)."""
    worst, thrown, _ = momentum_balance("standard")
    assert worst > 5e-5 * thrown, (worst, thrown)
