"""Where each simulated tentacle's root sits: the groups' root layout (docs/groups.md).

Tentacles are numbered group by group in the scene's order. A root sits on the bell margin at an
angle about the bell axis (from +x towards +y), or, for a group with ``placement = "mouth"``
(oral arms), on a circle of ``mouth_radius x bell.radius`` about the axis in the margin plane,
under the centre of the subumbrella. Every root driver (the kinematic bell, the forced base
point, the soft bell's recorded margin) places the roots from one :class:`RootLayout`.

Angles:
- ``angles`` given: those, in degrees;
- ``arrangement = "even"`` (or unset): ``2 pi k / n`` for k = 0 .. n - 1;
- ``arrangement = "clusters"``: c clusters centred at ``2 pi j / c``, the n roots shared among
  them (the first ``n mod c`` clusters one more), each cluster's roots evenly over its spread
  (default half the gap between centres), centred on the cluster's centre;
plus ``angle_offset`` in every case. A one-table scene's layout is ``2 pi k / n``, computed as the
bell models always did, so its roots are the same to the bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from jellysim.config.schema import Scene, Tentacles

DEFAULT_CLUSTERS = 8
DEFAULT_MOUTH_RADIUS = 0.15  # of bell.radius


@dataclass(frozen=True)
class RootLayout:
    """Per simulated tentacle (T,): ``angles`` (rad) about the bell axis, ``mouth`` (bool: on
    the mouth circle, not the margin), ``mouth_radius`` (fraction of bell.radius, 0 on the
    margin), ``group`` (index into ``names``) and ``particles`` (its chain's particle count).
    ``even_first``: the first group's count when its roots are spread evenly over the margin
    from angle 0, else 0."""

    angles: np.ndarray
    mouth: np.ndarray
    mouth_radius: np.ndarray
    group: np.ndarray
    particles: np.ndarray
    names: tuple[str, ...]
    even_first: int

    @property
    def count(self) -> int:
        return int(self.angles.size)

    @property
    def any_mouth(self) -> bool:
        return bool(np.any(self.mouth))

    @property
    def default(self) -> bool:
        """Every root on the margin at ``2 pi k / T`` (the one-table scene's layout)."""
        return len(self.names) == 1 and self.even_first == self.count

    def slices(self) -> list[slice]:
        """The tentacles of each group, in order."""
        edges = np.searchsorted(self.group, np.arange(len(self.names) + 1))
        return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]

    def margin_sectors(self) -> int:
        """A margin vertex count hint: the first group's count when it is evenly spread over the
        margin from angle 0 (so those roots are vertices), else 1."""
        return max(self.even_first, 1)


def group_angles(t: Tentacles) -> np.ndarray:
    """The root angles (rad) of one group's ``count`` tentacles."""
    n = t.count
    offset = math.radians(t.angle_offset) if t.angle_offset is not None else 0.0
    if t.angles is not None:
        return np.radians(np.asarray(t.angles, dtype=np.float64)) + offset
    if t.arrangement == "clusters":
        c = DEFAULT_CLUSTERS if t.clusters is None else t.clusters
        gap = 2.0 * math.pi / c
        spread = 0.5 * gap if t.cluster_spread is None else math.radians(t.cluster_spread)
        sizes = np.full(c, n // c)
        sizes[: n % c] += 1
        clusters: list[np.ndarray] = []
        for j, m in enumerate(sizes):
            local = np.zeros(1) if m == 1 else (np.arange(m) / (m - 1) - 0.5) * spread
            clusters.append(j * gap + local)
        return np.concatenate(clusters) + offset
    even: np.ndarray = 2.0 * np.pi * np.arange(n) / n
    return even + offset if offset else even


def _is_even_from_zero(t: Tentacles) -> bool:
    return t.angles is None and t.arrangement != "clusters" and not t.angle_offset


def root_layout(scene: Scene) -> RootLayout:
    """The layout of every simulated tentacle of ``scene``."""
    groups = scene.groups
    angles, mouth, radius, group, particles = [], [], [], [], []
    for index, g in enumerate(groups):
        t = g.tentacles
        on_mouth = t.placement == "mouth"
        angles.append(group_angles(t))
        mouth.append(np.full(t.count, on_mouth))
        fraction = DEFAULT_MOUTH_RADIUS if t.mouth_radius is None else t.mouth_radius
        radius.append(np.full(t.count, fraction if on_mouth else 0.0))
        group.append(np.full(t.count, index, dtype=np.int32))
        particles.append(np.full(t.count, t.particles, dtype=np.int32))
    first = groups[0].tentacles
    even = _is_even_from_zero(first) and first.placement != "mouth"
    return RootLayout(
        np.concatenate(angles),
        np.concatenate(mouth).astype(bool),
        np.concatenate(radius),
        np.concatenate(group).astype(np.int32),
        np.concatenate(particles).astype(np.int32),
        tuple(g.name for g in groups),
        first.count if even else 0,
    )
