"""Tentacle groups as the exports draw them (issue 25): each group its own part, in its own
material, threads as tapered tubes or curves, oral arms (``form = "ribbon"``) as ruffled
ribbon meshes.

A group's drawn tentacles come from :func:`jellysim.interpolation.interpolate_groups`, trimmed
to the group's own particle count, so the NaN rows of a padded result never reach a file. Its
look falls back to ``[look]`` key by key: ``color`` to ``tentacle_color``, ``drawn_radius`` to
``tentacle_radius``, ``taper`` to ``tentacle_taper``; a ribbon's ``ribbon_width`` to 4
``spacing``, ``ruffles`` to ``1 / (2 ribbon_width)``, ``ruffle_depth`` to
:data:`DEFAULT_RUFFLE_DEPTH` (the schema's documented defaults).

A one-group scene's group keeps the part name ``tentacles`` and, unless it sets ``color``, the
material :func:`jellysim.render.materials.tentacle_material` gives, so its files are as before
groups existed.
In a scene of several groups the part of group NAME is ``tentacles_NAME``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from jellysim import fields
from jellysim.config.schema import Tentacles
from jellysim.io.result import Result
from jellysim.render.frame import Look
from jellysim.render.materials import Material, tentacle_material

DEFAULT_RUFFLE_DEPTH = 0.3  # a ribbon's ruffle_depth when unset (schema: "unset: 0.3")
RIBBON_WIDTH_SPACINGS = 4.0  # a ribbon's width when unset, in particle spacings
ARM_PHASE = 2.399963  # rad: arm k's ruffles are shifted by k times this (the golden angle)


class ArmsMesh(NamedTuple):
    """A ribbon group's arms at one frame as one triangle mesh: ``vertices`` (V, 3) m,
    ``faces`` (M, 3) int64 (one consistent winding), ``normals`` (V, 3) unit, ``arm`` (V,) int32
    the drawn arm each vertex belongs to."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    arm: np.ndarray


@dataclass(frozen=True)
class ExportGroup:
    """One group as the exports draw it.

    ``positions`` (F, D, P, 3) m: the group's D drawn tentacles over every frame of the result,
    P its own particles (no NaN). ``part`` the name of its object in a file, ``index`` its number
    in the result's ``tentacle_groups``. Threads: ``radii`` (P,) m from root to tip. Ribbons:
    ``width`` m at the root, ``taper``, ``ruffles`` per m, ``ruffle_depth``; ``centres`` (F, 3) m
    the bell's margin centre per frame (an arm's width starts radially out from it)."""

    name: str
    index: int
    part: str
    form: str
    material: Material
    positions: np.ndarray
    radii: np.ndarray
    width: float
    taper: float
    ruffles: float
    ruffle_depth: float
    centres: np.ndarray

    @property
    def ribbon(self) -> bool:
        return self.form == "ribbon"

    def ribbon_meshes(self, frame: int) -> ArmsMesh:
        """Every arm of a ribbon group at ``frame`` as one mesh (built on each call, a few ms,
        so that a long export holds no frame's ribbons but the one it writes)."""
        from jellysim.render.ribbons import ribbon_mesh

        vertices, faces, normals, arm = [], [], [], []
        offset = 0
        centre = self.centres[frame]
        for k, chain in enumerate(self.positions[frame]):
            outward = chain[0] - centre
            outward[2] = 0.0
            if not np.linalg.norm(outward) > 0.0:
                outward = np.array([1.0, 0.0, 0.0])
            mesh = ribbon_mesh(
                chain,
                outward,
                self.width,
                self.taper,
                self.ruffles,
                self.ruffle_depth,
                phase=ARM_PHASE * k,
            )
            vertices.append(mesh.vertices)
            normals.append(mesh.normals)
            faces.append(mesh.faces.astype(np.int64) + offset)
            arm.append(np.full(len(mesh.vertices), k, dtype=np.int32))
            offset += len(mesh.vertices)
        if not vertices:
            empty = np.empty((0, 3))
            return ArmsMesh(empty, np.empty((0, 3), np.int64), empty, np.empty(0, np.int32))
        return ArmsMesh(*(np.concatenate(a) for a in (vertices, faces, normals, arm)))


class GroupLook(NamedTuple):
    """How a group is drawn, its keys resolved against ``[look]``: ``color`` linear RGB,
    ``radius`` m and ``taper`` (a thread's root radius, tip / root), ``width`` m at the root,
    ``ruffles`` per m and ``ruffle_depth`` (a ribbon's)."""

    color: tuple[float, float, float]
    radius: float
    taper: float
    width: float
    ruffles: float
    ruffle_depth: float


def export_look(look: Look, t: Tentacles) -> GroupLook:
    """The group ``t``'s look, each key unset falling back to ``look`` or its default."""
    width = RIBBON_WIDTH_SPACINGS * t.spacing if t.ribbon_width is None else t.ribbon_width
    return GroupLook(
        color=look.tentacle_color if t.color is None else tuple(map(float, t.color)),  # type: ignore[arg-type]
        radius=float(look.tentacle_radius if t.drawn_radius is None else t.drawn_radius),
        taper=float(look.tentacle_taper if t.taper is None else t.taper),
        width=float(width),
        ruffles=1.0 / (2.0 * width) if t.ruffles is None else float(t.ruffles),
        ruffle_depth=float(DEFAULT_RUFFLE_DEPTH if t.ruffle_depth is None else t.ruffle_depth),
    )


def group_material(look: Look, color: tuple[float, float, float], part: str) -> Material:
    """The shared tentacle material of ``look`` in the group's ``color``, named ``part`` (a
    one-group scene's: :func:`~jellysim.render.materials.tentacle_material` itself)."""
    shared = tentacle_material(look)
    return Material(part, color, shared.opacity, shared.emissive, shared.roughness)


def export_groups(result: Result, look: Look, interpolation: int | None) -> list[ExportGroup]:
    """The result's tentacle groups, drawn (``interpolation`` drawn per simulated tentacle,
    None: each group's own), empty when the result has no tentacles."""
    if not result.has(fields.TENTACLE_POSITION):
        return []
    from jellysim.interpolation import interpolate_groups

    drawn = interpolate_groups(result, interpolation)
    centres = result.read(fields.BELL_MARGIN).mean(axis=1)
    several = len(drawn) > 1
    out = []
    for g in drawn:
        t = g.tentacles
        part = f"tentacles_{g.name}" if several else "tentacles"
        resolved = export_look(look, t)
        out.append(
            ExportGroup(
                name=g.name,
                index=g.index,
                part=part,
                form=t.form or "thread",
                material=group_material(look, resolved.color, part),
                positions=g.positions,
                radii=resolved.radius * np.linspace(1.0, resolved.taper, g.positions.shape[2]),
                width=resolved.width,
                taper=resolved.taper,
                ruffles=resolved.ruffles,
                ruffle_depth=resolved.ruffle_depth,
                centres=centres,
            )
        )
    return out
