"""``bell.model = "none"``: the paper's forced base point (Figs. 5, 7 and 8).

The roots sit on a still circle of ``bell.radius`` at z = 0 (root k at angle 2 pi k / T, one root
at (radius, 0, 0) when T = 1) and each moves as ``amplitude sin(2 pi f t) direction``, the
direction radial by default. The tentacles hang along -z, which is also the clamp direction.
"""

from __future__ import annotations

import numpy as np

from jellysim.bell import BellModel, register
from jellysim.config.schema import Scene
from jellysim.tentacle.layout import RootLayout, root_layout
from jellysim.tentacle.roots import NO_FORCING, Forcing

MARGIN_POINTS_PER_ROOT = 8
Z_AXIS = np.array([0.0, 0.0, 1.0])


class ForcedRoots(BellModel):
    """Roots on a still margin, oscillated forcibly (:class:`jellysim.bell.BellModel`)."""

    def __init__(
        self,
        radius: float,
        layout: RootLayout,
        amplitude: float,
        frequency: float,
        direction: str | tuple[float, float, float],
    ) -> None:
        self.radius = radius
        self.amplitude = amplitude
        self.omega = 2.0 * np.pi * frequency
        self.direction = direction
        angles = layout.angles
        count = angles.size
        self.base = radius * np.stack([np.cos(angles), np.sin(angles), np.zeros(count)], axis=1)
        if layout.any_mouth:  # oral arms on their circle, forced like the margin
            self.base[layout.mouth] *= layout.mouth_radius[layout.mouth, None]
        self.directions = self._directions(angles)

    def _directions(self, angles: np.ndarray) -> np.ndarray:
        """Unit direction of the oscillation at each angle, (n, 3)."""
        if isinstance(self.direction, str):  # "radial"
            return np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
        vector = np.asarray(self.direction, dtype=np.float64)
        return np.broadcast_to(vector / np.linalg.norm(vector), (angles.size, 3)).copy()

    def roots(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        phase = self.omega * np.asarray(times)[:, None, None]
        positions = self.base[None] + self.amplitude * np.sin(phase) * self.directions[None]
        velocities = self.amplitude * self.omega * np.cos(phase) * self.directions[None]
        hang = np.broadcast_to(-Z_AXIS, positions.shape).copy()
        return positions, velocities, hang

    def forcing(self) -> Forcing:
        if self.amplitude == 0.0 or self.omega == 0.0:
            return NO_FORCING
        return Forcing(
            self.amplitude * self.omega, self.amplitude * self.omega**2, 2.0 * np.pi / self.omega
        )

    def bell_velocity(self, times: np.ndarray) -> np.ndarray:
        return np.zeros((np.size(times), 3))

    def axis(self, times: np.ndarray) -> np.ndarray:
        return np.broadcast_to(Z_AXIS, (np.size(times), 3)).copy()

    def margin(self, time: float) -> np.ndarray:
        """The circle with every point moved by the same law, so the roots lie on it."""
        n = MARGIN_POINTS_PER_ROOT * self.base.shape[0]
        angles = 2.0 * np.pi * np.arange(n) / n
        circle = self.radius * np.stack([np.cos(angles), np.sin(angles), np.zeros(n)], axis=1)
        return circle + self.amplitude * np.sin(self.omega * time) * self._directions(angles)


@register("none")
def _forced(scene: Scene) -> ForcedRoots:
    rm = scene.root_motion
    return ForcedRoots(
        scene.bell.radius, root_layout(scene), rm.amplitude, rm.frequency, rm.direction
    )
