"""USD export (usd-core): one stage with the whole animation, for Blender, Houdini, Omniverse.

``OUT/<scene name>.usdc``: ``metersPerUnit = 1``, ``upAxis = Z``, default prim ``/Jellyfish`` (an
Xform), time codes = frame indices at ``timeCodesPerSecond = fps``. Children, as the result has
them:

- ``Bell``: a ``Mesh`` (triangles, counter-clockwise seen from outside, right-handed) with
  time-sampled ``points`` and ``extent``;
- ``Tentacles``: ``BasisCurves`` (linear), one curve per drawn tentacle, time-sampled ``points``
  and ``extent``, ``widths`` per vertex tapering from root to tip (the scene's ``[look]``);
- ``Fluid``: ``Points``, the live fluid particles per time sample, constant width l0.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jellysim.io.result import Result


def _extent(points: np.ndarray) -> list[tuple[float, float, float]]:
    low, high = points.min(axis=0), points.max(axis=0)
    return [tuple(map(float, low)), tuple(map(float, high))]  # type: ignore[list-item]


def _to_3d(points: np.ndarray) -> np.ndarray:
    if points.shape[-1] == 3:
        return points
    world = np.zeros((*points.shape[:-1], 3))
    world[..., 0], world[..., 2] = points[..., 0], points[..., 1]  # 2-D (x, y up) -> (x, 0, y)
    return world


def export_usd(
    result: Result, out: Path, frames: range, interpolation: int | None = None
) -> list[Path]:
    from pxr import Gf, Usd, UsdGeom, Vt

    from jellysim.render.frame import tentacle_radii
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

    if "bell/surface_vertices" in f:
        bell = UsdGeom.Mesh.Define(stage, "/Jellyfish/Bell")
        faces = np.asarray(f["bell/surface_faces"][:], dtype=np.int32)
        bell.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(faces)))
        bell.CreateFaceVertexIndicesAttr(Vt.IntArray(faces.ravel().tolist()))
        bell.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
        bell.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        color = Gf.Vec3f(*scene.look.bell_color)
        bell.CreateDisplayColorAttr(Vt.Vec3fArray([color]))
        points_attr, extent_attr = bell.CreatePointsAttr(), bell.CreateExtentAttr()
        for frame in frames:
            points = np.asarray(f["bell/surface_vertices"][frame], dtype=np.float32)
            points_attr.Set(Vt.Vec3fArray.FromNumpy(points), frame)
            extent_attr.Set(Vt.Vec3fArray(_extent(points)), frame)

    if "tentacles/position" in f:
        from jellysim.interpolation import interpolate_result

        drawn = interpolate_result(result, interpolation)
        _, count, particles, _ = drawn.shape
        curves = UsdGeom.BasisCurves.Define(stage, "/Jellyfish/Tentacles")
        curves.CreateTypeAttr(UsdGeom.Tokens.linear)
        curves.CreateCurveVertexCountsAttr(Vt.IntArray([particles] * count))
        radii = tentacle_radii(particles, scene_look(scene))
        widths = np.tile(2.0 * radii, count).astype(np.float32)
        curves.CreateWidthsAttr(Vt.FloatArray.FromNumpy(widths))
        curves.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
        color = Gf.Vec3f(*scene.look.tentacle_color)
        curves.CreateDisplayColorAttr(Vt.Vec3fArray([color]))
        points_attr, extent_attr = curves.CreatePointsAttr(), curves.CreateExtentAttr()
        for frame in frames:
            points = drawn[frame].reshape(-1, 3).astype(np.float32)
            points_attr.Set(Vt.Vec3fArray.FromNumpy(points), frame)
            box = _extent(points)
            pad = float(widths.max()) / 2.0
            extent_attr.Set(
                Vt.Vec3fArray([tuple(v - pad for v in box[0]), tuple(v + pad for v in box[1])]),
                frame,
            )

    if "fluid/position" in f:
        cloud = UsdGeom.Points.Define(stage, "/Jellyfish/Fluid")
        spacing = float(f.attrs.get("particle_spacing", 0.01))
        cloud.CreateWidthsAttr(Vt.FloatArray([spacing]))
        cloud.SetWidthsInterpolation(UsdGeom.Tokens.constant)
        points_attr, extent_attr = cloud.CreatePointsAttr(), cloud.CreateExtentAttr()
        for frame in frames:
            alive = np.asarray(f["fluid/alive"][frame], dtype=bool)
            points = _to_3d(np.asarray(f["fluid/position"][frame])[alive]).astype(np.float32)
            points_attr.Set(Vt.Vec3fArray.FromNumpy(points), frame)
            box = _extent(points)
            pad = spacing / 2.0
            extent_attr.Set(
                Vt.Vec3fArray([tuple(v - pad for v in box[0]), tuple(v + pad for v in box[1])]),
                frame,
            )

    stage.GetRootLayer().Export(str(path))  # written whole, then visible under its name
    del stage
    temporary.unlink(missing_ok=True)
    return [path]
