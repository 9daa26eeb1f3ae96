"""USD export (usd-core): one stage with the whole animation, for Blender, Houdini, Omniverse.

``OUT/<scene name>.usdc``: ``metersPerUnit = 1``, ``upAxis = Z``, default prim ``/Jellyfish`` (an
Xform), time codes = frame indices at ``timeCodesPerSecond = framesPerSecond = fps``. Children, as
the result has them, each bound to a UsdPreviewSurface material under ``/Jellyfish/Looks`` (the
shared materials of :mod:`jellysim.render.materials`: ``diffuseColor``, ``opacity``,
``emissiveColor``, ``roughness``, ``ior``, linear RGB) and carrying the same colour and opacity as
``displayColor``/``displayOpacity``:

- ``Bell``: a ``Mesh`` (triangles, counter-clockwise seen from outside, right-handed) with
  time-sampled ``points`` and ``extent``;
- ``Tentacles``: ``BasisCurves`` (linear), one curve per drawn tentacle, time-sampled ``points``
  and ``extent``, ``widths`` per vertex tapering from root to tip (the scene's ``[look]``). A
  scene of several tentacle groups (:mod:`jellysim.export.groups`) has a prim per group
  instead, ``Tentacles_NAME`` (``-`` in NAME written ``_``) with its own material of the
  group's colour: a thread group as above (its own particle count, radius and taper), a ribbon
  group (oral arms) a ``Mesh`` of its ruffled ribbons' triangles with time-sampled ``points``,
  ``normals`` (vertex) and, since the triangle count may change, ``faceVertexCounts`` and
  ``faceVertexIndices``, double-sided;
- ``Fluid``: ``Points``, the live fluid particles per time sample, constant width l0.

The root layer's ``customLayerData["jellysim"]`` holds what a renderer needs besides geometry:
the scene's ``[look]`` colours, the exported frames (first, last, step) and fps, the bounding
box of everything over those frames, and the renderers' camera: direction, field of view and
the path ``jellysim render --camera follow`` moves it along
(:mod:`jellysim.export.blender_settings`, as the glTF export writes them).
``OUT/import_into_blender.py`` (the module :mod:`jellysim.export.blender_import`, with those
settings embedded) sets the stage up in Blender: materials, world, a following camera, lights,
frame range and fps, and renders or saves it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from jellysim import fields
from jellysim.export.blender_settings import (
    BLENDER_SCRIPT,
    blender_settings,
    camera_path,
    prim_name,
    write_blender_script,
)
from jellysim.export.groups import ExportGroup, export_groups
from jellysim.io.result import Result
from jellysim.render.materials import Material, bell_material, fluid_material


def _extent(points: np.ndarray, pad: float = 0.0) -> list[tuple[float, float, float]]:
    """Corners of the box around ``points`` (K, 3), grown by ``pad`` on every side."""
    low, high = points.min(axis=0) - pad, points.max(axis=0) + pad
    return [tuple(map(float, low)), tuple(map(float, high))]  # type: ignore[list-item]


def _to_3d(points: np.ndarray) -> np.ndarray:
    if points.shape[-1] == 3:
        return points
    world = np.zeros((*points.shape[:-1], 3))
    world[..., 0], world[..., 2] = points[..., 0], points[..., 1]  # 2-D (x, y up) -> (x, 0, y)
    return world


def _bounds(low: np.ndarray, high: np.ndarray, box: list[tuple[float, float, float]]) -> None:
    """Grow ``low`` and ``high`` (3,) in place to hold ``box`` (an extent)."""
    np.minimum(low, box[0], out=low)
    np.maximum(high, box[1], out=high)


def _bind_material(stage: Any, prim: Any, material: Material) -> None:
    """Give ``prim`` the shared ``material`` as a UsdPreviewSurface (linear RGB, as
    UsdPreviewSurface wants) at ``/Jellyfish/Looks/<name>``, bound to it, and as its
    ``displayColor``/``displayOpacity`` for viewers that read only those."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade, Vt

    path = f"/Jellyfish/Looks/{prim_name(material.name)}"
    shading = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, f"{path}/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    color = Gf.Vec3f(*material.base_color)
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(color)
    shader.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).Set(
        Gf.Vec3f(*material.emissive)
    )
    shader.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(material.opacity)
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(material.roughness)
    shader.CreateInput("ior", Sdf.ValueTypeNames.Float).Set(material.ior)
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    shading.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(shading)
    gprim = UsdGeom.Gprim(prim)
    gprim.CreateDisplayColorAttr(Vt.Vec3fArray([color]))
    gprim.CreateDisplayOpacityAttr(Vt.FloatArray([material.opacity]))


def _write_threads(
    stage: Any, group: ExportGroup, frames: range, low: np.ndarray, high: np.ndarray
) -> None:
    """A thread group as linear ``BasisCurves`` at ``/Jellyfish/<prim_name(part)>``."""
    from pxr import UsdGeom, Vt

    _, count, particles, _ = group.positions.shape
    curves = UsdGeom.BasisCurves.Define(stage, f"/Jellyfish/{prim_name(group.part)}")
    curves.CreateTypeAttr(UsdGeom.Tokens.linear)
    curves.CreateCurveVertexCountsAttr(Vt.IntArray([particles] * count))
    widths = np.tile(2.0 * group.radii, count).astype(np.float32)
    curves.CreateWidthsAttr(Vt.FloatArray.FromNumpy(widths))
    curves.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    _bind_material(stage, curves.GetPrim(), group.material)
    points_attr, extent_attr = curves.CreatePointsAttr(), curves.CreateExtentAttr()
    for frame in frames:
        points = group.positions[frame].reshape(-1, 3).astype(np.float32)
        points_attr.Set(Vt.Vec3fArray.FromNumpy(points), frame)
        box = _extent(points, float(widths.max()) / 2.0)
        extent_attr.Set(Vt.Vec3fArray(box), frame)
        _bounds(low, high, box)


def _write_arms(
    stage: Any, group: ExportGroup, frames: range, low: np.ndarray, high: np.ndarray
) -> None:
    """A ribbon group as a double-sided triangle ``Mesh`` at ``/Jellyfish/<prim_name(part)>``,
    every attribute time-sampled (an arm's triangle count follows its shape)."""
    from pxr import UsdGeom, Vt

    mesh = UsdGeom.Mesh.Define(stage, f"/Jellyfish/{prim_name(group.part)}")
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateDoubleSidedAttr(True)
    _bind_material(stage, mesh.GetPrim(), group.material)
    counts, indices = mesh.CreateFaceVertexCountsAttr(), mesh.CreateFaceVertexIndicesAttr()
    points_attr, normals_attr = mesh.CreatePointsAttr(), mesh.CreateNormalsAttr()
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    extent_attr = mesh.CreateExtentAttr()
    for frame in frames:
        arms = group.ribbon_meshes(frame)
        counts.Set(Vt.IntArray([3] * len(arms.faces)), frame)
        indices.Set(Vt.IntArray.FromNumpy(arms.faces.astype(np.int32).ravel()), frame)
        points = arms.vertices.astype(np.float32)
        points_attr.Set(Vt.Vec3fArray.FromNumpy(points), frame)
        normals_attr.Set(Vt.Vec3fArray.FromNumpy(arms.normals.astype(np.float32)), frame)
        if len(points):
            box = _extent(points)
            extent_attr.Set(Vt.Vec3fArray(box), frame)
            _bounds(low, high, box)


def export_usd(
    result: Result, out: Path, frames: range, interpolation: int | None = None
) -> list[Path]:
    from pxr import Usd, UsdGeom, Vt

    from jellysim.render.pipeline import scene_look

    f = result.file
    scene = result.scene
    path = out / f"{scene.name}.usdc"
    temporary = out / f".{scene.name}.tmp.usdc"
    stage = Usd.Stage.CreateInMemory(str(temporary))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    root = UsdGeom.Xform.Define(stage, "/Jellyfish")
    stage.SetDefaultPrim(root.GetPrim())
    stage.SetStartTimeCode(frames[0])
    stage.SetEndTimeCode(frames[-1])
    stage.SetTimeCodesPerSecond(float(f.attrs["fps"]))
    stage.SetFramesPerSecond(float(f.attrs["fps"]))  # importers play at this rate
    look = scene_look(scene)
    low, high = np.full(3, np.inf), np.full(3, -np.inf)  # everything over the frames, m

    if result.has(fields.BELL_SURFACE_VERTICES):
        bell = UsdGeom.Mesh.Define(stage, "/Jellyfish/Bell")
        faces = result.bell_surface_faces.astype(np.int32)
        bell.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(faces)))
        bell.CreateFaceVertexIndicesAttr(Vt.IntArray(faces.ravel().tolist()))
        bell.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
        bell.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        _bind_material(stage, bell.GetPrim(), bell_material(look))
        points_attr, extent_attr = bell.CreatePointsAttr(), bell.CreateExtentAttr()
        for frame in frames:
            points = result.read(fields.BELL_SURFACE_VERTICES, frame).astype(np.float32)
            points_attr.Set(Vt.Vec3fArray.FromNumpy(points), frame)
            box = _extent(points)
            extent_attr.Set(Vt.Vec3fArray(box), frame)
            _bounds(low, high, box)

    groups = export_groups(result, look, interpolation)
    for group in groups:
        if group.ribbon:
            _write_arms(stage, group, frames, low, high)
        else:
            _write_threads(stage, group, frames, low, high)

    if result.has(fields.FLUID_POSITION):
        cloud = UsdGeom.Points.Define(stage, "/Jellyfish/Fluid")
        spacing = float(f.attrs.get("particle_spacing", 0.01))
        cloud.CreateWidthsAttr(Vt.FloatArray([spacing]))
        cloud.SetWidthsInterpolation(UsdGeom.Tokens.constant)
        _bind_material(stage, cloud.GetPrim(), fluid_material())
        points_attr, extent_attr = cloud.CreatePointsAttr(), cloud.CreateExtentAttr()
        for frame in frames:
            alive = result.read(fields.FLUID_ALIVE, frame)
            points = _to_3d(result.read(fields.FLUID_POSITION, frame)[alive]).astype(np.float32)
            points_attr.Set(Vt.Vec3fArray.FromNumpy(points), frame)
            box = _extent(points, spacing / 2.0)
            extent_attr.Set(Vt.Vec3fArray(box), frame)
            _bounds(low, high, box)

    fps = float(f.attrs["fps"])
    camera = camera_path(result, interpolation)
    settings = blender_settings(scene, frames, fps, low, high, path.name, groups, camera)

    def stored(value: Any) -> Any:
        if isinstance(value, dict):
            return {key: stored(item) for key, item in value.items()}
        if not isinstance(value, list):
            return value
        if value and isinstance(value[0], str):
            return Vt.StringArray(value)
        return Vt.DoubleArray(value)

    stage.GetRootLayer().customLayerData = {
        "jellysim": {key: stored(value) for key, value in settings.items()}
    }
    stage.GetRootLayer().Export(str(path))  # written whole, then visible under its name
    del stage
    temporary.unlink(missing_ok=True)
    return [path, write_blender_script(out / BLENDER_SCRIPT, settings)]
