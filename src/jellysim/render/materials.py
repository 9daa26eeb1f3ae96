"""One look, every output (issue 25): the materials every renderer and export derives from a
:class:`~jellysim.render.frame.Look`, so POV-Ray, the preview renderer, the viewer, USD and glTF
cannot drift apart in colour.

Colours are linear RGB in [0, 1] throughout; :func:`srgb` encodes them only where a format
stores sRGB (the preview's PNG). glTF's ``baseColorFactor``/``emissiveFactor``, USD's
UsdPreviewSurface inputs and three.js colours set in ``LinearSRGBColorSpace`` take linear values.

The view-dependent terms (the bell's Fresnel-like rim, its radial stripes, a tentacle seen
face-on through ``tentacle_transparency``) are defined here once too, for the outputs that can
draw them (docs/rendering.md, "Which output honours which key").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from jellysim.render.frame import FLUID_COLOR, RGB, Look

GLOW_EMISSION = 0.6  # emitted light of the bell at glow 1, fraction of its colour
BELL_ROUGHNESS = 0.3  # the bell's (and the oral arms') mesoglea: glossy
TENTACLE_ROUGHNESS = 0.6  # the thread tentacles: duller
BELL_IOR = 1.02  # the bell's index of refraction: mesoglea is nearly water
PHONG_SHININESS = 12.0  # a Phong exponent (the viewer's) is this over the roughness
ARM_CLEARING = 0.5  # an oral arm is this fraction as transparent as the bell,
ARM_RIM = 0.3  # with this rim: a thicker, frillier tissue that reads against the threads
STRIPE_TENTACLE_SHARE = 0.65  # a stripe's colour: this much tentacle colour, the rest bell
DEEP_WATER = 0.25  # the deep water behind a tentacle, fraction of water_color
STRIPE_TRANSMIT = 0.6  # a stripe lets through this fraction of the light the bell lets through
# The radial stripe profile over one period (0 at a stripe's centre): (position, stripe weight);
# POV-Ray's ``radial`` color_map and the preview read the same table.
STRIPE_PROFILE = ((0.0, 1.0), (0.1, 1.0), (0.3, 0.0), (0.7, 0.0), (0.9, 1.0), (1.0, 1.0))


@dataclass(frozen=True)
class Material:
    """A surface as every output describes it: ``base_color`` and ``emissive`` linear RGB,
    ``opacity`` 1 opaque (face-on, before the rim), ``roughness`` in [0, 1], ``ior`` the index of
    refraction of a refracting volume (1: none, a thin or opaque surface)."""

    name: str
    base_color: RGB
    opacity: float
    emissive: RGB
    roughness: float
    ior: float = 1.0


def _rgb(values: np.ndarray) -> RGB:
    r, g, b = (float(v) for v in values)
    return (r, g, b)


def bell_material(look: Look) -> Material:
    """The bell: its colour, ``1 - bell_transparency`` opaque, glowing ``GLOW_EMISSION glow`` of
    its colour, refracting ``BELL_IOR``."""
    color = np.asarray(look.bell_color, dtype=np.float64)
    return Material(
        name="bell",
        base_color=_rgb(color),
        opacity=1.0 - float(look.bell_transparency),
        emissive=_rgb(GLOW_EMISSION * look.glow * color),
        roughness=BELL_ROUGHNESS,
        ior=BELL_IOR,
    )


def tentacle_material(look: Look) -> Material:
    """The tentacles: their colour, opaque (their transparency is faked face-on, see
    :func:`tentacle_face_color`), no glow."""
    return Material(
        name="tentacles",
        base_color=_rgb(np.asarray(look.tentacle_color, dtype=np.float64)),
        opacity=1.0,
        emissive=(0.0, 0.0, 0.0),
        roughness=TENTACLE_ROUGHNESS,
    )


def arm_tissue(look: Look) -> Look:
    """The oral arms' tissue: the bell's, ``ARM_CLEARING`` times as transparent, rim
    ``ARM_RIM``, so that face-on an arm shows its colour through the veil of threads."""
    return replace(look, bell_transparency=ARM_CLEARING * look.bell_transparency, rim=ARM_RIM)


def group_material(look: Look, group: GroupLook, name: str) -> Material:
    """The material of one tentacle group drawn as ``group``, named ``name``: a thread group
    :func:`tentacle_material` in its colour; a ribbon group (oral arms) the bell's tissue in its
    colour, :func:`arm_tissue`'s transparency, glowing as the bell does (POV-Ray's and the
    preview's ribbons are drawn in the same tissue)."""
    if group.form == "ribbon":
        color = np.asarray(group.color, dtype=np.float64)
        return Material(
            name=name,
            base_color=_rgb(color),
            opacity=1.0 - float(arm_tissue(look).bell_transparency),
            emissive=_rgb(GLOW_EMISSION * look.glow * color),
            roughness=BELL_ROUGHNESS,
        )
    return replace(tentacle_material(look), name=name, base_color=group.color)


def phong_shininess(material: Material) -> float:
    """The Phong exponent of ``material``'s roughness (three.js's ``shininess``, the viewer's):
    ``PHONG_SHININESS / roughness``."""
    return PHONG_SHININESS / max(material.roughness, 1e-3)


RIBBON_WIDTH_SPACINGS = 4.0  # a ribbon's width at the root, unset: this many particle spacings
RUFFLE_DEPTH = 0.3  # a ribbon's ruffle amplitude, unset: this fraction of its width


@dataclass(frozen=True)
class GroupLook:
    """How one group of tentacles is drawn, every default resolved: ``form`` "thread" (a tapered
    tube of ``radius`` m at the root, ``taper`` of that at the tip) or "ribbon" (a ruffled
    curtain ``ribbon_width`` m wide at the root, ``taper`` of that at the tip, ``ruffles`` waves
    per metre along it, ``ruffle_depth`` of the width deep), in ``color`` (linear RGB);
    ``placement`` "margin" or "mouth" (oral arms, hung from the manubrium)."""

    name: str
    form: str
    color: RGB
    radius: float
    taper: float
    ribbon_width: float
    ruffles: float
    ruffle_depth: float
    placement: str


def group_look(look: Look, tentacles: Any = None, name: str = "tentacles") -> GroupLook:
    """The one place a group's drawn look is resolved: its keys (a scene's
    :class:`~jellysim.config.schema.Tentacles` of the group; None: every key unset) over
    ``look``'s ``tentacle_color``, ``tentacle_radius`` and ``tentacle_taper``; a ribbon
    ``RIBBON_WIDTH_SPACINGS`` spacings wide, ``1 / (2 ribbon_width)`` ruffles per metre and
    ``RUFFLE_DEPTH`` deep where unset (the schema's documented defaults)."""

    def key(name: str) -> Any:
        return None if tentacles is None else getattr(tentacles, name, None)

    def unset(value: Any, fallback: Any) -> Any:
        return fallback if value is None else value

    spacing = key("spacing")
    width = unset(
        key("ribbon_width"),
        RIBBON_WIDTH_SPACINGS * spacing if spacing else 4.0 * look.tentacle_radius,
    )
    color = key("color")
    return GroupLook(
        name=name,
        form=unset(key("form"), "thread"),
        color=look.tentacle_color if color is None else _rgb(np.asarray(color, dtype=np.float64)),
        radius=float(unset(key("drawn_radius"), look.tentacle_radius)),
        taper=float(unset(key("taper"), look.tentacle_taper)),
        ribbon_width=float(width),
        ruffles=float(unset(key("ruffles"), 1.0 / (2.0 * width))),
        ruffle_depth=float(unset(key("ruffle_depth"), RUFFLE_DEPTH)),
        placement=unset(key("placement"), "margin"),
    )


def thread_look(look: Look, group: GroupLook) -> Look:
    """``look`` with the group's colour, radius and taper as its tentacles': what the thread
    renderers (and :func:`tentacle_face_color`) read."""
    return replace(
        look, tentacle_color=group.color, tentacle_radius=group.radius, tentacle_taper=group.taper
    )


def fluid_material() -> Material:
    """The fluid particles: ``FLUID_COLOR``, opaque."""
    return Material("fluid", FLUID_COLOR, 1.0, (0.0, 0.0, 0.0), 0.2)


def tentacle_face_color(look: Look) -> RGB:
    """A tentacle seen face-on: its colour mixed ``tentacle_transparency`` of the way towards
    the deep water (``DEEP_WATER water_color``), as a clear tube in dark water looks; at its
    silhouette edges it shows its own colour."""
    color = np.asarray(look.tentacle_color, dtype=np.float64)
    deep = DEEP_WATER * np.asarray(look.water_color, dtype=np.float64)
    t = float(look.tentacle_transparency)
    return _rgb((1.0 - t) * color + t * deep)


def stripe_color(look: Look) -> RGB:
    """The colour of the bell's radial stripes: ``STRIPE_TENTACLE_SHARE`` tentacle colour, the
    rest bell colour."""
    bell = np.asarray(look.bell_color, dtype=np.float64)
    tentacle = np.asarray(look.tentacle_color, dtype=np.float64)
    return _rgb((1.0 - STRIPE_TENTACLE_SHARE) * bell + STRIPE_TENTACLE_SHARE * tentacle)


def rim_weight(cos_theta: np.ndarray | float) -> np.ndarray:
    """The Fresnel-like falloff ``w = (1 - |cos theta|)^1.5``: 0 face-on, 1 at the silhouette
    (``theta`` the angle between the surface normal and the direction to the eye)."""
    return (1.0 - np.clip(np.abs(cos_theta), 0.0, 1.0)) ** 1.5


def bell_transmit(look: Look, cos_theta: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """The bell's transmitted fraction and how far its colour is lightened towards white, seen
    at ``theta`` from its normal: face-on the transparency ``t`` moves ``look.rim`` of the way
    towards clear, at the silhouette ``look.rim`` of the way towards opaque and the colour
    ``look.rim`` of the way towards white: ``transmit = face - (face - edge) w``,
    ``lighten = rim w`` with ``w`` from :func:`rim_weight`."""
    t, rim = float(look.bell_transparency), float(look.rim)
    face, edge = t + (1.0 - t) * rim, t * (1.0 - rim)
    weight = rim_weight(cos_theta)
    return face - (face - edge) * weight, rim * weight


def stripe_weight(look: Look, azimuth: np.ndarray) -> np.ndarray:
    """How much of the stripe colour shows at ``azimuth`` (rad) about the bell's axis, 0 to 1:
    ``look.stripes`` stripes, one centred at azimuth 0, over :data:`STRIPE_PROFILE`."""
    azimuth = np.asarray(azimuth, dtype=np.float64)
    if look.stripes <= 0:
        return np.zeros_like(azimuth)
    phase = np.mod(azimuth * look.stripes / (2.0 * math.pi), 1.0)
    positions, weights = zip(*STRIPE_PROFILE, strict=True)
    return np.interp(phase, positions, weights)


def srgb(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) of linear values in [0, 1], any shape."""
    c = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1.0 / 2.4) - 0.055)
