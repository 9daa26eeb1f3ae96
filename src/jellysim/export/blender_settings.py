"""What the Blender import script needs of an export, written by the USD and the glTF exporter.

``jellysim export --format usd`` stores these settings in the stage's layer metadata
(``customLayerData["jellysim"]``), ``--format gltf`` in each part's glTF scene ``extras``
(``extras["jellysim"]``); both write ``import_into_blender.py`` (the module
:mod:`jellysim.export.blender_import`) beside the files, with one export's settings embedded.
The settings are plain values: each object's material as every output draws it (``materials``:
per prim name, the :class:`~jellysim.render.materials.Material` that
:mod:`jellysim.render.materials` resolves from the scene's ``[look]``), the water colour, the
exported frames and fps, the bounding box of everything over those frames and the renderers'
camera (direction, field of view and the path of ``jellysim render --camera follow``).
"""

from __future__ import annotations

import os
import pprint
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from jellysim import fields
from jellysim.export.groups import ExportGroup
from jellysim.io.result import Result
from jellysim.render.materials import (
    Material,
    bell_material,
    fluid_material,
    tentacle_material,
)

BLENDER_SCRIPT = "import_into_blender.py"


def prim_name(part: str) -> str:
    """The USD prim (and material) name of an exported part: ``bell`` -> ``Bell``,
    ``tentacles_oral-arms`` -> ``Tentacles_oral_arms`` (USD names take no ``-``); the Blender
    script finds a glTF object of the part by this name too (ignoring case and ``-``)."""
    return part[:1].upper() + part[1:].replace("-", "_")


def material_settings(material: Material) -> dict[str, Any]:
    """``material`` as plain values: ``base_color`` and ``emissive`` linear RGB, ``opacity``,
    ``roughness``, ``ior``."""
    return {
        "base_color": [float(v) for v in material.base_color],
        "opacity": float(material.opacity),
        "emissive": [float(v) for v in material.emissive],
        "roughness": float(material.roughness),
        "ior": float(material.ior),
    }


def blender_settings(
    scene: Any,
    frames: range,
    fps: float,
    low: np.ndarray,
    high: np.ndarray,
    file_name: str,
    groups: Sequence[ExportGroup] = (),
    camera: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The settings of one exported file (plain values): ``frames`` it holds at ``fps``, the
    box ``low`` to ``high`` (3,) m, z up, around everything in them, ``file_name`` (the key
    ``stage_file``: the stage or the glTF part), ``camera`` (:func:`camera_path`) the path of
    the renderers' camera; ``materials`` (:func:`material_settings`) per prim name: the bell's,
    each of ``groups``' (the tentacle groups exported; none: the tentacles' of ``[look]``) and
    the fluid's."""
    from jellysim._version import __version__
    from jellysim.render.pipeline import FIELD_OF_VIEW, VIEW_DIRECTION, scene_look

    look = scene_look(scene)
    tentacles = {prim_name(g.part): g.material for g in groups} or {
        "Tentacles": tentacle_material(look)
    }
    materials = {"Bell": bell_material(look), **tentacles, "Fluid": fluid_material()}
    return {
        "generator": f"jellysim {__version__}",
        "scene": scene.name,
        "stage_file": file_name,
        "first_frame": frames[0],
        "last_frame": frames[-1],
        "frame_step": frames.step,
        "fps": fps,
        "bounds_min": [float(v) for v in low],
        "bounds_max": [float(v) for v in high],
        "materials": {name: material_settings(m) for name, m in materials.items()},
        "tentacle_radius": float(look.tentacle_radius),
        "water_color": [float(v) for v in look.water_color],
        "view_direction": [float(v) for v in VIEW_DIRECTION],
        "field_of_view": float(FIELD_OF_VIEW),
        **(camera or {}),
    }


def camera_path(result: Result, interpolation: int | None) -> dict[str, Any]:
    """Where ``jellysim render --camera follow`` looks (:func:`~jellysim.render.pipeline.
    camera_targets`), as plain values: the point looked at in frame 0 (``camera_origin``, m), how
    far it moves each frame (``camera_velocity``, m; the path is a straight line) and the
    half-size of the box about it that holds the jellyfish in every frame (``camera_half``, m).
    A result without a jellyfish (a fluid alone) takes ``--camera auto``'s choice, as a render
    does; ``camera_mode`` names the mode used."""
    from jellysim.render.pipeline import camera_targets, make_members

    jellyfish = result.has(fields.TENTACLE_POSITION) or result.has(fields.BELL_SURFACE_VERTICES)
    members = make_members([result], 1, interpolation, 0, fluid=not jellyfish)
    frames = result.frames
    targets, half, mode = camera_targets(members, frames, "follow" if jellyfish else "auto")
    velocity = (targets[-1] - targets[0]) / (frames - 1) if frames > 1 else np.zeros(3)
    return {
        "camera_mode": mode,
        "camera_origin": [float(v) for v in targets[0]],
        "camera_velocity": [float(v) for v in velocity],
        "camera_half": [float(v) for v in half],
    }


def write_blender_script(path: Path, settings: dict[str, Any]) -> Path:
    """``import_into_blender.py``: the module :mod:`jellysim.export.blender_import` with
    ``settings`` embedded (written to a temporary name, then renamed)."""
    from jellysim.export import blender_import

    source = Path(blender_import.__file__).read_text(encoding="utf-8")
    marker = "EMBEDDED_SETTINGS: dict[str, Any] | None = None"
    assert source.count(marker) == 1
    embedded = "EMBEDDED_SETTINGS: dict[str, Any] | None = " + pprint.pformat(
        settings, sort_dicts=False, width=96
    )
    temporary = path.with_name(f".{path.name}.tmp")
    temporary.write_text(source.replace(marker, embedded), encoding="utf-8")
    os.replace(temporary, path)
    return path
