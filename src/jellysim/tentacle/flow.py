"""The water around the tentacles (paper §4.1.2): a uniform flow relative to the bell plus noise,
or a uniform current in the world frame plus noise (``flow.model``).

In the world frame the water moves at ``v_bell - speed * axis + noise`` (DESIGN §3), or, for a
current, at ``speed * direction + noise``. The noise is
smooth and time-correlated, one 3-D process per tentacle: an Ornstein-Uhlenbeck process of
standard deviation ``noise`` and correlation time tau, drawn on knots every tau / 4 from the
scene's seed (tentacle k draws from its own spawned stream) and interpolated by C1 Catmull-Rom
cubics. It is therefore the same whatever the substep, the thread count or a resume.
"""

from __future__ import annotations

import math

import numpy as np

from jellysim.config.schema import Flow, Scene
from jellysim.errors import InputError

KNOTS_PER_CORRELATION_TIME = 4
MAX_NOISE_VALUES = 50_000_000  # knots x tentacles (x 3 components, 8 bytes): 1.2 GB


class FlowNoise:
    """Smooth seeded noise per tentacle: ``sample(times)`` gives (S, T, 3) m/s."""

    def __init__(
        self, amplitude: float, correlation_time: float, duration: float, count: int, seed: int
    ) -> None:
        self.amplitude = amplitude
        self.spacing = correlation_time / KNOTS_PER_CORRELATION_TIME
        n_knots = math.ceil(duration / self.spacing) + 4
        if n_knots * count > MAX_NOISE_VALUES:
            raise InputError(
                f"flow.noise_correlation_time = {correlation_time:g} s is too short for a "
                f"{duration:g} s run of {count} tentacles: at least "
                f"{duration * count * KNOTS_PER_CORRELATION_TIME / MAX_NOISE_VALUES:.3g} s"
            )
        knots = np.zeros((n_knots, count, 3))
        if amplitude > 0.0:
            a = math.exp(-self.spacing / correlation_time)
            kick = math.sqrt(1.0 - a * a)
            streams = np.random.SeedSequence(seed).spawn(count)
            for k, stream in enumerate(streams):
                draws = np.random.default_rng(stream).standard_normal((n_knots, 3))
                knots[0, k] = draws[0]
                for j in range(1, n_knots):
                    knots[j, k] = a * knots[j - 1, k] + kick * draws[j]
            knots *= amplitude
        self.knots = knots  # knot j sits at time (j - 1) * spacing

    def sample(self, times: np.ndarray) -> np.ndarray:
        times = np.asarray(times, dtype=np.float64)
        if self.amplitude == 0.0:
            return np.zeros((times.size, self.knots.shape[1], 3))
        u = times / self.spacing + 1.0
        j = np.clip(np.floor(u).astype(np.int64), 1, self.knots.shape[0] - 3)
        s = np.clip(u - j, 0.0, 1.0)[:, None, None]  # never extrapolate past the knots
        p0, p1, p2, p3 = (self.knots[j + o] for o in (-1, 0, 1, 2))
        # Catmull-Rom: C1, passes through the knots.
        return 0.5 * (
            2.0 * p1
            + (p2 - p0) * s
            + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * s**2
            + (3.0 * p1 - p0 - 3.0 * p2 + p3) * s**3
        )


def flow_noise_for(scene: Scene) -> FlowNoise:
    f = scene.flow
    # Knots cover the last frame, round(duration * fps) / fps, which may pass the duration.
    last_frame = (scene.frame_count - 1) / scene.fps
    span = max(scene.duration, last_frame)
    return FlowNoise(f.noise, f.noise_correlation_time, span, scene.tentacles.count, scene.seed)


def water_velocity(
    speed: float, axis: np.ndarray, bell_velocity: np.ndarray, noise: np.ndarray
) -> np.ndarray:
    """World-frame water velocity at the tentacles, (S, T, 3) m/s, DESIGN §3."""
    uniform = bell_velocity - speed * axis  # (S, 3)
    return uniform[:, None, :] + noise


def current_direction(direction: tuple[float, float, float]) -> np.ndarray:
    """``flow.direction`` as a unit vector (3,) (the scene check refuses a zero one)."""
    vector = np.asarray(direction, dtype=np.float64)
    vector = vector / np.max(np.abs(vector))  # first to order one: no under- or overflow
    return vector / np.linalg.norm(vector)


def flow_at_tentacles(
    flow: Flow, axis: np.ndarray, bell_velocity: np.ndarray, noise: np.ndarray
) -> np.ndarray:
    """The water at the tentacles, (S, T, 3) m/s, by ``flow.model``: 'bell', the paper's
    uniform flow relative to the bell (:func:`water_velocity`); 'current', ``speed`` along the
    world-frame ``direction`` whatever the bell does. Both plus the noise (S, T, 3)."""
    if flow.model == "current":
        return flow.speed * current_direction(flow.direction) + noise
    return water_velocity(flow.speed, axis, bell_velocity, noise)
