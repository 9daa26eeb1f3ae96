"""Tentacle groups as the exports draw them (issue 25): each group its own part, in its own
material, threads as tapered tubes or curves, oral arms (``form = "ribbon"``) as ruffled
ribbon meshes.

A group's drawn tentacles come from :func:`jellysim.interpolation.interpolate_groups`, trimmed
to the group's own particle count, so the NaN rows of a padded result never reach a file. Its
look is :func:`jellysim.render.materials.group_look`'s, the one resolution that POV-Ray, the
preview and the viewer share: ``[look]`` key by key under the group's own keys.

Its material is :func:`jellysim.render.materials.group_material`'s: a thread group's the
tentacle material in its colour, a ribbon group's (oral arms) the translucent, glowing tissue
POV-Ray and the preview draw arms in. A one-group scene's group keeps the part name
``tentacles`` and, unless it sets ``color``, the material
:func:`jellysim.render.materials.tentacle_material` gives, so its files are as before groups
existed.
In a scene of several groups the part of group NAME is ``tentacles_NAME``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from jellysim import fields
from jellysim.io.result import Result
from jellysim.render.frame import Look
from jellysim.render.materials import Material, group_look, group_material

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

    def ribbon_subdivisions(self, frames: range) -> int:
        """The centreline stations per particle segment that resolve every arm's ruffles at
        every frame of ``frames`` (the most :func:`~jellysim.render.ribbons.stations_per_segment`
        asks for): passed to :meth:`ribbon_meshes`, the arms keep one vertex count and grid
        over those frames."""
        from jellysim.render.ribbons import SUBDIVISIONS, finite_chain, stations_per_segment

        return max(
            stations_per_segment(finite_chain(chain), self.ruffles, SUBDIVISIONS)
            for frame in frames
            for chain in self.positions[frame]
        )

    def ribbon_meshes(self, frame: int, subdivisions: int | None = None) -> ArmsMesh:
        """Every arm of a ribbon group at ``frame`` as one mesh (built on each call, a few ms,
        so that a long export holds no frame's ribbons but the one it writes); ``subdivisions``
        stations per particle segment at least (None: the renderers' minimum)."""
        from jellysim.render.ribbons import SUBDIVISIONS, ribbon_mesh

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
                subdivisions=SUBDIVISIONS if subdivisions is None else subdivisions,
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
        resolved = group_look(look, t, g.name)
        out.append(
            ExportGroup(
                name=g.name,
                index=g.index,
                part=part,
                form=t.form or "thread",
                material=group_material(look, resolved, part),
                positions=g.positions,
                radii=resolved.radius * np.linspace(1.0, resolved.taper, g.positions.shape[2]),
                width=resolved.ribbon_width,
                taper=resolved.taper,
                ruffles=resolved.ruffles,
                ruffle_depth=resolved.ruffle_depth,
                centres=centres,
            )
        )
    return out
