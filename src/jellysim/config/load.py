"""Reading, overriding, validating and writing scenes.

A scene is built from a preset name or a TOML file, with ``KEY=VALUE`` overrides applied on top;
every value is checked against the field metadata of :mod:`jellysim.config.schema`. Problems raise
:class:`~jellysim.errors.InputError` with at most three lines: the key, the value, what is allowed.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import tomli_w

from jellysim.config.schema import (
    DEFAULT_GROUP,
    GROUP_NAME_PATTERN,
    MAX_TURN_PER_SEGMENT,
    Scene,
    TentacleGroup,
    Tentacles,
)
from jellysim.errors import InputError

Tree = dict[str, Any]

# TOML integers are 64-bit signed; larger ones cannot be stored (result attributes, checkpoints).
INT64_MIN, INT64_MAX = -(2**63), 2**63 - 1


def linear_from_srgb(encoded: float) -> float:
    """The linear value of an sRGB-encoded one in [0, 1] (IEC 61966-2-1), the inverse of
    :func:`jellysim.render.materials.srgb`."""
    if encoded <= 0.04045:
        return encoded / 12.92
    return ((encoded + 0.055) / 1.055) ** 2.4


def suggest(name: str, candidates: Iterable[str]) -> str:
    close = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


def _fields(cls: type) -> dict[str, dataclasses.Field[Any]]:
    """The scene keys of a table (internal fields, filled by the loader, are not keys)."""
    return {f.name: f for f in dataclasses.fields(cls) if not f.metadata.get("internal")}


def _is_section(f: dataclasses.Field[Any]) -> bool:
    return "kind" not in f.metadata


def _section_type(cls: type, name: str) -> type:
    return type(getattr(cls(), name))


def _show(value: Any) -> str:
    """A value as the user wrote it (TOML spelling), on one line."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_show(v) for v in value) + "]"
    return str(value)


def quote(name: str) -> str:
    """A key, preset name or path in quotes, escaped so that it stays on one line."""
    return f"'{name}'" if name.isprintable() else repr(name)


def allowed(meta: Mapping[str, Any]) -> str:
    kind = meta["kind"]
    if kind == "choice":
        return "one of " + ", ".join(f"'{c}'" for c in meta["choices"])
    if kind == "vec3":
        return "a list of three finite numbers [x, y, z]"
    if kind == "direction":
        return "'radial' or a non-zero list of three finite numbers [x, y, z]"
    if kind == "color":
        return "[r, g, b] with each in [0, 1], or '#rrggbb'"
    if kind == "str":
        return "a name of letters, digits, '_', '.' and '-'"
    if kind == "bool":
        return "true or false"
    if kind == "angles":
        return "a non-empty list of finite numbers in [-360, 360] (degrees)"
    if kind == "boxes":
        return "a list of boxes [x0, y0, z0, x1, y1, z1] (finite, x0 < x1, y0 < y1, z0 < z1)"
    if kind == "points":
        return "a table of NAME = [x, ...] (1 to 3 finite numbers; NAME of letters, digits, _ -)"
    noun = "an integer" if kind == "int" else "a finite number"
    bounds = [
        f"{op} {meta[key]:g}"
        for key, op in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))
        if key in meta
    ]
    text = noun + (" " + " and ".join(bounds) if bounds else "")
    return text + (" (or left unset)" if meta.get("nullable") else "")


def _check_value(key: str, value: Any, meta: Mapping[str, Any]) -> Any:
    """Return ``value`` converted to the field's type, or raise InputError."""

    def bad() -> InputError:
        return InputError(f"{key} = {_show(value)} is not allowed: expected {allowed(meta)}")

    kind = meta["kind"]
    if value is None and meta.get("nullable"):
        return None
    if kind == "choice":
        if not isinstance(value, str) or value not in meta["choices"]:
            suggestion = suggest(value, meta["choices"]) if isinstance(value, str) else ""
            raise InputError(
                f"{key} = {_show(value)} is not allowed: expected {allowed(meta)}{suggestion}"
            )
        return value
    if kind == "str":
        if not isinstance(value, str) or not re.fullmatch(meta.get("pattern", ".*"), value):
            raise bad()
        return value
    if kind == "bool":
        if not isinstance(value, bool):
            raise bad()
        return value
    if kind == "angles":
        if (
            not isinstance(value, (list, tuple))
            or not value
            or len(value) > 100_000
            or not all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in value)
            or not all(math.isfinite(c) and -360.0 <= c <= 360.0 for c in value)
        ):
            raise bad()
        return tuple(float(c) for c in value)
    if kind == "boxes":
        return _boxes(value, bad)
    if kind == "points":
        return _points(value, bad)
    if kind == "color":
        if isinstance(value, str) and re.fullmatch(r"#[0-9A-Fa-f]{6}", value):
            # "#rrggbb" is sRGB-encoded, as everywhere (CSS, colour pickers); colours are
            # stored linear (docs/rendering.md), so it is decoded (IEC 61966-2-1).
            return tuple(linear_from_srgb(int(value[i : i + 2], 16) / 255.0) for i in (1, 3, 5))
        if (
            not isinstance(value, (list, tuple))
            or len(value) != 3
            or not all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in value)
            or not all(0.0 <= c <= 1.0 for c in value)
        ):
            raise bad()
        return tuple(float(c) for c in value)
    if kind in ("vec3", "direction"):
        if kind == "direction" and value == "radial":
            return value
        if (
            not isinstance(value, (list, tuple))
            or len(value) != 3
            or not all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in value)
            or not all(math.isfinite(c) for c in value)
        ):
            raise bad()
        vector = tuple(float(c) for c in value)
        if kind == "direction" and not any(vector):
            raise bad()
        return vector
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad()
        if not INT64_MIN <= value <= INT64_MAX:
            raise InputError(
                f"{key} = {value} is not allowed: expected {allowed(meta)} (64-bit integer)"
            )
        number: float = value
    else:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise bad()
        try:
            number = float(value)
        except OverflowError:  # an integer beyond the float range
            raise bad() from None
        if not math.isfinite(number):
            raise bad()
    if (
        ("gt" in meta and not number > meta["gt"])
        or ("ge" in meta and not number >= meta["ge"])
        or ("lt" in meta and not number < meta["lt"])
        or ("le" in meta and not number <= meta["le"])
    ):
        raise bad()
    return value if kind == "int" else float(number)


def _numbers(value: Any, lengths: range) -> bool:
    """Whether ``value`` is a list of finite numbers (not booleans) of one of ``lengths``."""
    return (
        isinstance(value, (list, tuple))
        and len(value) in lengths
        and all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in value)
        and all(math.isfinite(c) for c in value)
    )


def _boxes(value: Any, bad: Any) -> tuple[tuple[float, ...], ...]:
    """Boxes [x0, y0, z0, x1, y1, z1] with lower < upper corners, as tuples of floats."""
    if not isinstance(value, (list, tuple)) or len(value) > 1000:
        raise bad()
    boxes = []
    for box in value:
        if not _numbers(box, range(6, 7)) or not all(box[k] < box[k + 3] for k in range(3)):
            raise bad()
        boxes.append(tuple(float(c) for c in box))
    return tuple(boxes)


def _points(value: Any, bad: Any) -> tuple[tuple[str, tuple[float, ...]], ...]:
    """Named points NAME = [x, ...] as (name, coordinates) pairs in the table's order."""
    if not isinstance(value, Mapping) or len(value) > 1000:
        raise bad()
    points = []
    for name, point in value.items():
        if not re.fullmatch(r"[A-Za-z0-9_-]{1,64}", name) or not _numbers(point, range(1, 4)):
            raise bad()
        points.append((name, tuple(float(c) for c in point)))
    return tuple(points)


def _build(cls: type, tree: Mapping[str, Any], prefix: str) -> Any:
    fields = _fields(cls)
    for key in tree:
        if key not in fields:
            raise _unknown_key(prefix[:-1], key, fields)
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        if name not in tree:
            continue
        value = tree[name]
        if _is_section(f):
            if not isinstance(value, dict):
                raise InputError(
                    f"{prefix}{name} must be a table [{prefix}{name}], got {_show(value)}"
                )
            kwargs[name] = _build(_section_type(cls, name), value, f"{prefix}{name}.")
        else:
            kwargs[name] = _check_value(prefix + name, value, f.metadata)
    return cls(**kwargs)


def _unknown_key(table: str, key: str, fields: Iterable[str]) -> InputError:
    """The error for ``key`` not among ``fields`` of ``table`` ("" for the top level)."""
    where = f"[{table}]" if table else "the scene"
    full = f"{table}.{key}" if table else key
    return InputError(
        f"unknown key {quote(full)} in {where}{suggest(key, fields)}; allowed: {', '.join(fields)}"
    )


def scene_from_tree(tree: Mapping[str, Any]) -> Scene:
    """Validate a nested mapping (as read from TOML) and build the scene."""
    table = tree.get("tentacles")
    named: dict[str, Mapping[str, Any]] = {}
    if isinstance(table, Mapping):
        named = {k: v for k, v in table.items() if isinstance(v, Mapping)}
        if named:
            tree = {**tree, "tentacles": {k: v for k, v in table.items() if k not in named}}
    scene = _build(Scene, tree, "")
    if named:
        # The shared keys only fill the groups in; the first group stands as [tentacles] for
        # code that reads one table (docs/groups.md).
        groups = _build_groups(tree["tentacles"], named)
        scene = dataclasses.replace(scene, tentacles=groups[0].tentacles, tentacle_groups=groups)
    _check_consistency(scene)
    return scene


def _build_groups(
    shared: Mapping[str, Any], named: Mapping[str, Mapping[str, Any]]
) -> tuple[TentacleGroup, ...]:
    """The named groups ``[tentacles.NAME]``: each group's keys over the shared ones."""
    keys = _fields(Tentacles)
    groups = []
    for name, own in named.items():
        if name in keys:
            raise InputError(
                f"tentacles.{name} is a key of [tentacles], not a group: write "
                f"{name} = VALUE, or name the group otherwise"
            )
        if not re.fullmatch(GROUP_NAME_PATTERN, name):
            raise InputError(
                f"tentacles.{name}: {quote(name)} is not a group name: letters, digits, '_' "
                "and '-', starting with a letter"
            )
        for key, value in own.items():
            if isinstance(value, Mapping):
                raise InputError(
                    f"tentacles.{name}.{key}: groups do not nest; give [tentacles.{name}] "
                    f"its keys ({', '.join(keys)})"
                )
        table = _build(Tentacles, {**shared, **own}, f"tentacles.{name}.")
        groups.append(TentacleGroup(name, table))
    return tuple(groups)


def _check_consistency(scene: Scene) -> None:
    """Rules that involve more than one key."""
    if scene.particle_count > 5_000_000:
        what = (
            "tentacles.count * tentacles.particles"
            if not scene.tentacle_groups
            else "count x particles over the tentacle groups"
        )
        raise InputError(
            f"{what} = {scene.particle_count} is too large: at most 5,000,000 simulated particles"
        )
    for group in scene.groups:
        _check_rest_shape(group)
        _check_layout(scene, group)
    if scene.bell.model != "none" and scene.root_motion.amplitude > 0.0:
        raise InputError(
            f"root_motion.amplitude = {_show(scene.root_motion.amplitude)} forces the roots, which "
            f"only bell.model = 'none' does; with bell.model = {quote(scene.bell.model)} the bell "
            "moves them: set root_motion.amplitude = 0"
        )
    if scene.fluid.model == "none" and scene.tentacle_count == 0:
        raise InputError(
            "tentacles.count = 0 is not allowed: expected an integer >= 1 (0 only in fluid-only "
            "scenes, fluid.model = 'mps')"
        )
    soft = scene.bell.model == "mass-spring"
    if scene.fluid.model == "mps" and scene.tentacle_count > 0 and not soft:
        raise InputError(
            f"fluid.model = 'mps' without a bell runs fluid-only scenes: set tentacles.count = 0 "
            f"(it is {scene.tentacle_count}); tentacles in the fluid come with "
            "bell.model = 'mass-spring'"
        )
    if soft:
        _check_soft_bell(scene)
    if scene.fluid.model == "mps" and scene.fluid.dimensions == 2 and scene.water.gravity[2] != 0:
        raise InputError(
            "water.gravity: a 2-D fluid lives in the (x, y) plane with y up; give gravity as "
            "[0, -9.81, 0]"
        )
    if scene.fluid.model == "mps":
        _check_fluid(scene)
    if scene.flow.model == "fluid" and not scene.has_water_for_tentacles:
        raise InputError(
            "flow.model = 'fluid' takes the water's velocity from the simulated fluid, and this "
            "scene has none: use it with bell.model = 'mass-spring' and fluid.model = 'mps' "
            "(the moon-jelly presets), or flow.model = 'bell' or 'current'"
        )
    if scene.flow.two_way and scene.flow.model != "fluid":
        raise InputError(
            f"flow.two_way = true needs the tentacles in the simulated water: set "
            f"flow.model = 'fluid' (it is {scene.flow.model!r})"
        )
    direction = scene.flow.direction
    largest = max(abs(c) for c in direction)
    if scene.flow.model == "current" and not (0.0 < largest < math.inf):
        raise InputError(
            f"flow.direction = {_show(list(direction))} gives the current no direction: give a "
            "non-zero vector in the world frame, e.g. [1, 0, 0]"
        )
    bell = scene.bell
    if bell.model == "kinematic" and bell.swim_speed > 0.0 and bell.contraction == 0.0:
        raise InputError(
            f"bell.swim_speed = {_show(bell.swim_speed)} needs a pulsing bell: the bell "
            "swims by contracting, and bell.contraction = 0 holds it still"
        )


def group_key(group: TentacleGroup, key: str) -> str:
    """The dotted scene key of ``key`` in ``group``: ``tentacles.KEY`` for the one-table
    scene's group, ``tentacles.NAME.KEY`` for a named one."""
    return f"tentacles.{key}" if group.name == DEFAULT_GROUP else f"tentacles.{group.name}.{key}"


def _check_rest_shape(group: TentacleGroup) -> None:
    """A rest curl the discrete chain can draw: at most 0.5 rad of turning per segment, about
    12.6 segments or more per turn of the coil (docs/theory/tentacle.md §6)."""
    t = group.tentacles
    limit = MAX_TURN_PER_SEGMENT
    for key in ("rest_curvature", "rest_curvature_tip", "rest_torsion"):
        value = getattr(t, key)
        if value is not None and abs(value) * t.spacing > limit:
            raise InputError(
                f"{group_key(group, key)} = {_show(value)} is too tight for "
                f"{group_key(group, 'spacing')} = {_show(t.spacing)}: |{key}| x spacing "
                f"must be at most {limit:g} "
                f"(|{key}| <= {limit / t.spacing:.6g} 1/m), or refine the spacing"
            )


def _check_layout(scene: Scene, group: TentacleGroup) -> None:
    """A group's roots exist and fit where they are placed (docs/groups.md)."""
    t = group.tentacles
    if group.name != DEFAULT_GROUP and t.count < 1:
        raise InputError(
            f"{group_key(group, 'count')} = {t.count} gives the group no roots: expected an "
            f"integer >= 1 (leave the group out of the scene to have none)"
        )
    if t.angles is not None and len(t.angles) != t.count:
        raise InputError(
            f"{group_key(group, 'angles')} gives {len(t.angles)} angles for "
            f"{group_key(group, 'count')} = {t.count}: give one angle per tentacle"
        )
    if t.arrangement == "clusters" and t.angles is None:
        clusters = 8 if t.clusters is None else t.clusters
        if clusters > t.count:
            raise InputError(
                f"{group_key(group, 'clusters')} = {clusters} is more than "
                f"{group_key(group, 'count')} = {t.count}: every cluster needs a root"
            )
    if t.placement == "mouth":
        b = scene.bell
        fraction = 0.15 if t.mouth_radius is None else t.mouth_radius
        # The arms' circle plus one arm diameter must stay inside the margin at its most
        # contracted and in its deepest notch (the kinematic bell's Eq. B2-B4).
        room = b.radius * (1.0 - b.contraction) * (1.0 - (b.lobe_depth if b.lobes else 0.0))
        if fraction * b.radius + t.spacing >= room:
            raise InputError(
                f"{group_key(group, 'mouth_radius')} = {_show(fraction)}: the arms do not fit "
                f"under the bell: mouth_radius x bell.radius + spacing must be less than "
                f"{room:.4g} m (the margin's radius at full contraction, in a notch)"
            )


def _check_soft_bell(scene: Scene) -> None:
    """The mass-spring bell lives in a 3-D MPS tank filled with water, inside the water."""
    b, f = scene.bell, scene.fluid
    if f.model != "mps" or f.dimensions != 3 or f.geometry != "hydrostatic":
        raise InputError(
            "bell.model = 'mass-spring' swims in the MPS fluid: set fluid.model = 'mps', "
            "fluid.dimensions = 3 and fluid.geometry = 'hydrostatic' (a filled tank)"
        )
    if b.lobes > 0:
        raise InputError("bell.lobes: the mass-spring bell has a round margin; set bell.lobes = 0")
    if f.lattice != "square":
        raise InputError(
            f"fluid.lattice = {f.lattice!r}: the mass-spring bell is carved out of the cubic "
            "lattice; set fluid.lattice = 'square'"
        )
    cells = b.margin_height / f.spacing
    if abs(cells - round(cells)) > 1e-6 * max(1.0, cells):
        raise InputError(
            f"bell.margin_height = {_show(b.margin_height)} is not a whole number of "
            f"fluid.spacing = {_show(f.spacing)}: the bell is carved out of the fluid's lattice"
        )
    l0 = f.spacing
    if b.thickness * b.height < 1.5 * l0 or b.radius < 4 * l0:
        raise InputError(
            "bell: the shell must be at least 1.5 fluid.spacing thick (bell.thickness x "
            "bell.height) and the radius at least 4 fluid.spacing; refine fluid.spacing"
        )
    if (
        2.0 * (b.radius + 2 * l0) > min(f.tank_width, f.tank_depth)
        or b.margin_height < 2 * l0
        or b.margin_height + b.height + 2 * l0 > f.water_height
    ):
        raise InputError(
            "bell: the bell must stand in the water with 2 fluid.spacing to spare: "
            "2 (radius + 2 l0) <= tank width and depth, margin_height >= 2 l0, "
            "margin_height + height + 2 l0 <= fluid.water_height"
        )


def _check_fluid(scene: Scene) -> None:
    """The tank and the water must sit on the fluid's lattice, the water inside the tank."""
    f = scene.fluid
    if f.source == "mixed" and f.gradient != "corrected":
        raise InputError(
            "fluid.source = 'mixed' needs fluid.gradient = 'corrected': with the standard "
            "gradient the mixed source is unstable (docs/fluid.md)"
        )
    if f.gradient == "conservative" and f.surface_repulsion:
        raise InputError(
            "fluid.gradient = 'conservative' cannot take fluid.surface_repulsion = true: the "
            "repulsion pushes one particle of a pair only, so the momentum the gradient "
            "conserves would not be; set one of them otherwise"
        )
    if f.surface == "either-density" and f.source != "mixed":
        raise InputError(
            "fluid.surface = 'either-density' needs fluid.source = 'mixed' (it also tests "
            "the number density at the start of the step, which only the mixed source "
            "computes); with another source set fluid.surface = 'standard'"
        )
    if f.lattice == "hexagonal" and f.dimensions != 2:
        raise InputError(
            "fluid.lattice = 'hexagonal' is 2-D only: set fluid.dimensions = 2, or "
            "fluid.lattice = 'fcc' (its 3-D analogue) or 'square'"
        )
    if f.lattice == "fcc" and f.dimensions != 3:
        raise InputError(
            "fluid.lattice = 'fcc' is 3-D only: set fluid.dimensions = 3, or "
            "fluid.lattice = 'hexagonal' (its 2-D analogue) or 'square'"
        )
    _check_obstacles(scene)
    _check_probes(scene)
    lengths = ["tank_width", "tank_height", "water_height"]
    if f.geometry == "dam-break":
        lengths.append("water_width")
    if f.dimensions == 3:
        lengths.append("tank_depth")
    for name in lengths:
        value = getattr(f, name)
        cells = value / f.spacing
        # On the fcc lattice only the tank's width need be whole: its rows and layers are not
        # l0 apart, so depths and heights are cut at the sites inside (docs/decisions.md).
        whole = f.lattice != "fcc" or name == "tank_width"
        if (whole and abs(cells - round(cells)) > 1e-6 * max(1.0, cells)) or cells < 2 - 1e-6:
            raise InputError(
                f"fluid.{name} = {_show(value)} is not a whole number (>= 2) of "
                f"fluid.spacing = {_show(f.spacing)}: the tank and the water sit on its lattice"
                + ("" if whole else " (on the fcc lattice: at least 2 spacings)")
            )
    if f.water_height > f.tank_height or (
        f.geometry == "dam-break" and f.water_width > f.tank_width
    ):
        raise InputError(
            "fluid: the water must fit in the tank (water_width <= tank_width, "
            "water_height <= tank_height)"
        )
    count = (f.tank_width / f.spacing) * (f.tank_height / f.spacing)
    if f.dimensions == 3:
        count *= f.tank_depth / f.spacing
    if count > 20_000_000:
        raise InputError(f"fluid: about {count:.3g} lattice cells in the tank; at most 20,000,000")


def _tank_box(scene: Scene) -> tuple[list[float], list[float]]:
    """The tank's inner lower and upper corners (m), D coordinates, the last one up."""
    f = scene.fluid
    if f.dimensions == 3:
        return [0.0, 0.0, 0.0], [f.tank_width, f.tank_depth, f.tank_height]
    return [0.0, 0.0], [f.tank_width, f.tank_height]


def _water_box(scene: Scene) -> tuple[list[float], list[float]]:
    """The water's lower and upper corners (m) at the start."""
    f = scene.fluid
    lower, upper = _tank_box(scene)
    upper[-1] = f.water_height
    if f.geometry == "dam-break":
        if f.water_side == "left":
            upper[0] = f.water_width
        else:
            lower[0] = f.tank_width - f.water_width
    return lower, upper


def _check_obstacles(scene: Scene) -> None:
    """Obstacles: 3-D, fluid-only, inside the tank, clear of the water, 2 spacings thick."""
    f = scene.fluid
    if not f.obstacles:
        return
    if f.dimensions != 3 or scene.bell.model != "none":
        raise InputError(
            "fluid.obstacles: solid boxes are for 3-D fluid-only scenes (fluid.dimensions = 3, "
            "bell.model = 'none')"
        )
    tank_lower, tank_upper = _tank_box(scene)
    water_lower, water_upper = _water_box(scene)
    for k, box in enumerate(f.obstacles):
        lower, upper = box[:3], box[3:]
        key = f"fluid.obstacles[{k}] = {_show(box)}"
        if any(lo < t - 1e-9 for lo, t in zip(lower, tank_lower, strict=True)) or any(
            hi > t + 1e-9 for hi, t in zip(upper, tank_upper, strict=True)
        ):
            raise InputError(
                f"{key} is not inside the tank: allowed 0 <= x <= {f.tank_width:g}, "
                f"0 <= y <= {f.tank_depth:g}, 0 <= z <= {f.tank_height:g}"
            )
        if min(hi - lo for lo, hi in zip(lower, upper, strict=True)) < 2 * f.spacing - 1e-9:
            raise InputError(
                f"{key} is too thin: each side must be at least 2 fluid.spacing = "
                f"{2 * f.spacing:g} m (walls and dummies inside)"
            )
        if all(
            lo < w_hi and hi > w_lo
            for lo, hi, w_lo, w_hi in zip(lower, upper, water_lower, water_upper, strict=True)
        ):
            raise InputError(f"{key} overlaps the water at the start: move it or the water")


def _check_probes(scene: Scene) -> None:
    """Height probes inside the tank; pressure probes on a face of the tank or an obstacle."""
    f, probes = scene.fluid, scene.probes
    if not (probes.height or probes.pressure):
        return
    if scene.bell.model != "none":
        raise InputError("probes: for fluid-only scenes (bell.model = 'none')")
    dim = f.dimensions
    lower, upper = _tank_box(scene)
    for name, point in probes.height:
        key = f"probes.height.{name} = {_show(point)}"
        if len(point) != dim - 1:
            raise InputError(f"{key}: expected {dim - 1} coordinates (the line's horizontal place)")
        if not all(lo < c < hi for c, lo, hi in zip(point, lower, upper[:-1], strict=False)):
            raise InputError(f"{key} is not inside the tank")
    for name, point in probes.pressure:
        key = f"probes.pressure.{name} = {_show(point)}"
        if len(point) != dim:
            raise InputError(f"{key}: expected {dim} coordinates")
        if wall_distance(scene, point) > 0.5 * f.spacing:
            raise InputError(
                f"{key} is not on a wall: it must lie within half a fluid.spacing of a face of "
                "the tank (x = 0, x = tank_width, the side walls, the floor) or of an obstacle"
            )


def wall_distance(scene: Scene, point: tuple[float, ...]) -> float:
    """How far (m) ``point`` lies from the nearest solid face: a wall or floor of the tank or a
    face of an obstacle, from either side; inf outside the tank."""
    lower, upper = _tank_box(scene)
    if not all(lo - 1e-9 <= c <= hi + 1e-9 for c, lo, hi in zip(point, lower, upper, strict=True)):
        return math.inf
    # the tank's walls (not the open top)
    faces = [c - lo for c, lo in zip(point, lower, strict=True)]
    faces += [hi - c for c, hi in zip(point[:-1], upper[:-1], strict=True)]
    distance = min(faces)
    for box in scene.fluid.obstacles:
        gaps = [max(box[k] - point[k], point[k] - box[k + 3]) for k in range(3)]
        outside = math.sqrt(sum(max(g, 0.0) ** 2 for g in gaps))
        distance = min(distance, outside if outside > 0 else -max(gaps))
    return distance


def parse_toml(text: str, source: str) -> Tree:
    """Parse TOML text; a syntax error names the source and the line."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        detail = str(err)
        if detail.endswith("(at end of document)"):  # tomllib gives no line there: the last one
            detail = detail[: -len(")")] + f", line {max(1, len(text.splitlines()))})"
        raise InputError(f"{source}: TOML syntax error: {detail}") from None


# A scene is a few kB of TOML: a file larger than this is not one (``/dev/zero``, a video), and
# reading it whole would only exhaust the memory.
MAX_SCENE_BYTES = 1 << 20


def read_scene_file(path: str | Path) -> Tree:
    """Read a TOML scene file into a tree (not yet validated); at most MAX_SCENE_BYTES are read."""
    p = Path(path)
    try:
        with open(p, "rb") as handle:
            data = handle.read(MAX_SCENE_BYTES + 1)
        text = data.decode("utf-8")
    except (OSError, UnicodeDecodeError) as err:
        reason = err.strerror if isinstance(err, OSError) and err.strerror else str(err)
        raise InputError(f"cannot read scene file {quote(str(p))}: {reason}") from None
    if len(data) > MAX_SCENE_BYTES:
        raise InputError(
            f"{quote(str(p))} is not a scene file: it is larger than 1 MiB "
            "(a scene is a few kB of TOML)"
        )
    if "\0" in text:
        raise InputError(f"{quote(str(p))} is not a scene file: it holds binary data, not TOML")
    return parse_toml(text, str(p))


def parse_value(raw: str, option: str) -> Any:
    """A command-line VALUE: a TOML value, or a bare word or a colour ``#rrggbb`` taken as a
    string (TOML would read ``#`` as the start of a comment); an error names ``option``."""
    raw = raw.strip()
    if re.fullmatch(r"#[0-9A-Fa-f]{6}", raw):
        return raw
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.+-]*", raw):
            return raw
        raise InputError(f"{option}: cannot read the value {raw!r} as a TOML value") from None


def parse_override(item: str) -> tuple[str, Any]:
    """Split ``KEY=VALUE``; VALUE as :func:`parse_value` reads it."""
    if "=" not in item:
        raise InputError(f"--set {item!r}: expected KEY=VALUE, e.g. tentacles.youngs_modulus=1e5")
    key, raw = item.split("=", 1)
    key = key.strip()
    if not key:
        raise InputError(f"--set {item!r}: the key is empty")
    return key, parse_value(raw, f"--set {quote(key)}")


def apply_overrides(tree: Mapping[str, Any], overrides: Mapping[str, Any]) -> Tree:
    """Return a copy of ``tree`` with dotted-key overrides applied; unknown keys are errors."""
    _shadowed_overrides(tree, overrides)
    result = _deep_copy(tree)
    for dotted, value in overrides.items():
        parts = dotted.split(".")
        cls: type = Scene
        node = result
        in_group = False
        for depth, part in enumerate(parts):
            fields = _fields(cls)
            prefix = ".".join(parts[:depth])
            if cls is Tentacles and not in_group and depth < len(parts) - 1:
                # tentacles.GROUP.KEY reaches a key of a named group; --set never makes one.
                groups = [k for k, v in node.items() if isinstance(v, Mapping)]
                if part not in groups:
                    raise _unknown_group(dotted, part, groups)
                node = node[part]
                in_group = True
                continue
            if part not in fields:
                raise _unknown_key(prefix, part, fields)
            f = fields[part]
            last = depth == len(parts) - 1
            if _is_section(f):
                if last:
                    raise InputError(f"--set {dotted}: '{dotted}' is a table; set one of its keys")
                cls = _section_type(cls, part)
                node = node.setdefault(part, {})
                if not isinstance(node, dict):
                    name = ".".join(parts[: depth + 1])
                    raise InputError(f"{name} must be a table [{name}], got {_show(node)}")
            else:
                if f.metadata["kind"] == "points" and depth == len(parts) - 2:
                    # probes.height.NAME = [x, y]: one named point, added or replaced
                    points = node.setdefault(part, {})
                    if not isinstance(points, dict):
                        raise InputError(f"--set {dotted}: '{part}' is not a table of points")
                    points[parts[-1]] = value
                    break
                if not last:
                    raise InputError(f"--set {dotted}: '{part}' is a value, not a table")
                node[part] = value
    return result


def _unknown_group(dotted: str, name: str, groups: list[str]) -> InputError:
    """The error for ``--set tentacles.NAME.KEY`` where the scene has no group NAME."""
    if not groups:
        return InputError(
            f"--set {dotted}: the scene has no tentacle group {quote(name)} (it has one "
            "[tentacles] table; set tentacles.KEY)"
        )
    return InputError(
        f"--set {dotted}: unknown tentacle group {quote(name)}{suggest(name, groups)}; the "
        f"scene's groups: {', '.join(groups)}"
    )


def _shadowed_overrides(tree: Mapping[str, Any], overrides: Mapping[str, Any]) -> None:
    """A shared ``tentacles.KEY`` that every named group sets itself would change nothing."""
    table = tree.get("tentacles")
    if not isinstance(table, Mapping):
        return
    groups = {k: v for k, v in table.items() if isinstance(v, Mapping)}
    for dotted in overrides:
        parts = dotted.split(".")
        if len(parts) == 2 and parts[0] == "tentacles" and groups:
            if all(parts[1] in own for own in groups.values()):
                raise InputError(
                    f"--set {dotted} changes nothing: every tentacle group sets {parts[1]} "
                    f"itself; set tentacles.GROUP.{parts[1]} (groups: {', '.join(groups)})"
                )


def _deep_copy(tree: Mapping[str, Any]) -> Tree:
    return {k: _deep_copy(v) if isinstance(v, Mapping) else v for k, v in tree.items()}


def scene_to_tree(scene: Scene) -> Tree:
    """The resolved scene as a nested mapping with every key explicit."""

    def convert(obj: Any) -> Any:
        if dataclasses.is_dataclass(obj):
            out = {}
            for f in dataclasses.fields(obj):
                value = getattr(obj, f.name)
                if value is None or f.metadata.get("internal"):
                    continue  # TOML has no null; an unset optional key stays unset
                if f.metadata.get("kind") == "points":  # (name, point) pairs: a table
                    out[f.name] = {name: list(point) for name, point in value}
                    continue
                out[f.name] = convert(value)
            return out
        if isinstance(obj, tuple):
            return [convert(item) for item in obj]
        return obj

    tree: Tree = convert(scene)
    if scene.tentacle_groups:  # [tentacles.NAME] each, every key explicit
        tree["tentacles"] = {g.name: convert(g.tentacles) for g in scene.tentacle_groups}
    return tree


def scene_to_toml(scene: Scene) -> str:
    """The resolved scene as TOML text (loads back to an equal scene)."""
    return tomli_w.dumps(scene_to_tree(scene))


# The mass-spring bell's keys whose defaults changed (issue 25), with what a soft bell did
# before the key existed.
SOFT_BELL_KEYS_BEFORE = (("root_placement", "particles"), ("arm_anchor", "margin"))


def recorded_tree(text: str) -> Tree:
    """The tree of a scene text that a result or a checkpoint recorded, read as the run that
    wrote it ran: a text without ``flow.model`` predates the key (issue 26; every text written
    since records every key), and the one flow then was the paper's, "bell" (not the "auto"
    default, which gives a soft bell in MPS water the simulated water); one with a mass-spring
    bell but no ``bell.root_placement`` hung its tentacles from its particles ("particles",
    issue 25), one without ``bell.arm_anchor`` its oral arms from the margin plane ("margin",
    issue 25), and where the bell is not a mass-spring one these keys, which do nothing there,
    are dropped (read at today's default); one with a bell but no ``bell.tentacle_contact`` let
    them pass into it (false)."""
    tree = tomllib.loads(text)
    flow = tree.get("flow")
    if flow is None or (isinstance(flow, dict) and "model" not in flow):
        tree["flow"] = {**(flow or {}), "model": "bell"}
    bell = tree.get("bell")
    soft = isinstance(bell, dict) and bell.get("model") == "mass-spring"
    # issue 25: before the keys, a soft bell's roots hung from its particles and its arms from
    # the margin plane; the keys act on a mass-spring bell alone: elsewhere whatever default a
    # text recorded ("surface" before "edge") reads as today's, so those runs still resume
    for name, before in SOFT_BELL_KEYS_BEFORE:
        if soft and isinstance(bell, dict) and name not in bell:
            bell = tree["bell"] = {**bell, name: before}
        elif isinstance(bell, dict) and not soft and name in bell:
            bell = tree["bell"] = {key: value for key, value in bell.items() if key != name}
    bell = tree.get("bell")
    if isinstance(bell, dict) and bell.get("model", "none") != "none":
        if "tentacle_contact" not in bell:
            # issues 25-26: before the key, nothing kept the tentacles out of the bell
            tree["bell"] = {**bell, "tentacle_contact": False}
    return tree


def same_scene(first: str, second: str) -> bool:
    """Whether two scene texts (TOML, as results and checkpoints record them) describe one scene
    under today's schema: a key that one text lacks takes its default. A key added to jellysim
    later is written into every new text at its default, which keeps the older behaviour; that
    changes the text, not the scene (docs/decisions.md, "Slender drag and currents"), except
    ``flow.model``, ``bell.root_placement``, ``bell.arm_anchor`` and ``bell.tentacle_contact``,
    whose defaults are no longer what older texts ran (:func:`recorded_tree`). A text that does
    not read as a scene is no match. ``fluid.device`` says where the fluid is stepped, not what
    is simulated: a run checkpointed on a GPU resumes on the CPU and the other way round."""
    if first == second:
        return True
    try:
        scenes = [scene_from_tree(recorded_tree(text)) for text in (first, second)]
    except (InputError, tomllib.TOMLDecodeError):
        return False
    on_cpu = [
        dataclasses.replace(s, fluid=dataclasses.replace(s.fluid, device="cpu")) for s in scenes
    ]
    return on_cpu[0] == on_cpu[1]
