"""Scene parameters: frozen dataclasses, one per TOML table.

Every field carries its unit, its allowed range and a one-line description in its metadata; the
validator (:mod:`jellysim.config.load`) and the generated reference ``docs/scene.md``
(:mod:`jellysim.config.docs`) both read them, so the documentation cannot drift from the code.
SI units everywhere; jellyfish scenes are 3-D with z up (DESIGN §3).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

# Allowed-value specifications understood by the validator.
#   kind: "float" | "int" | "str" | "choice" | "vec3" | "direction" | "bool"
#   gt / ge / lt / le: numeric bounds; choices: tuple of names; nullable: None allowed.


def param(default: Any, *, unit: str = "", doc: str, kind: str = "float", **spec: Any) -> Any:
    """A scene parameter with its unit, description and allowed values."""
    meta = {"unit": unit, "doc": doc, "kind": kind, **spec}
    if isinstance(default, (list, tuple)):
        value = tuple(default)
        return field(default_factory=lambda: value, metadata=meta)
    return field(default=default, metadata=meta)


# The largest turning per segment, kappa d and |tau| d, that a tentacle's rest shape may ask of
# the chain (docs/theory/tentacle.md §6): 12.6 segments or more per turn of the coil.
MAX_TURN_PER_SEGMENT = 0.5


@dataclass(frozen=True)
class Water:
    density: float = param(1000.0, unit="kg/m3", doc="density of the water", ge=1.0e-3, le=1.0e5)
    viscosity: float = param(
        1.0e-3, unit="Pa s", doc="dynamic viscosity of the water", ge=1.0e-8, le=1.0e6
    )
    gravity: tuple[float, float, float] = param(
        (0.0, 0.0, -9.81), unit="m/s2", kind="vec3", doc="gravitational acceleration (z up)"
    )


@dataclass(frozen=True)
class Flow:
    speed: float = param(
        0.3,
        unit="m/s",
        ge=-100.0,
        le=100.0,
        doc="speed of the water: relative to the bell, along the bell axis from root to tip "
        "(model = 'bell'), or of the current along direction (model = 'current')",
    )
    noise: float = param(
        0.0,
        unit="m/s",
        ge=0.0,
        le=100.0,
        doc="standard deviation of each component of the flow noise",
    )
    noise_correlation_time: float = param(
        0.5,
        unit="s",
        ge=1.0e-3,
        le=1.0e4,
        doc="correlation time of the smooth (Ornstein-Uhlenbeck) flow noise, one per tentacle",
    )
    model: str = param(
        "auto",
        kind="choice",
        choices=("auto", "bell", "current", "fluid"),
        doc="the water at the tentacles: 'auto', 'fluid' in a scene with simulated water (a "
        "soft bell in MPS water, Case 2) and 'bell' otherwise (Case 1); 'bell', the paper's "
        "uniform flow relative to the bell "
        "along its axis (speed); 'current', a uniform current in the world frame, speed along "
        "direction, whatever the bell does; 'fluid', the simulated water's velocity at each "
        "particle (a scene with a fluid; speed then only sets the substep's speed scale); all "
        "with the noise",
    )
    two_way: bool = param(
        False,
        kind="bool",
        doc="model = 'fluid': the tentacles' drag acts back on the water, equal and opposite, "
        "spread over the water particles around each tentacle particle",
    )
    direction: tuple[float, float, float] = param(
        (1.0, 0.0, 0.0),
        kind="vec3",
        doc="model = 'current': the current's direction in the world frame (z up; any length "
        "but zero, normalised)",
    )


@dataclass(frozen=True)
class Tentacles:
    count: int = param(
        6,
        kind="int",
        ge=0,
        le=10000,
        doc="number of simulated tentacles (0: none, a fluid-only scene)",
    )
    particles: int = param(
        60, kind="int", ge=3, le=100000, doc="particles per tentacle, root included"
    )
    spacing: float = param(
        0.01, unit="m", ge=1.0e-6, le=10.0, doc="particle spacing d, also the tentacle diameter"
    )
    youngs_modulus: float = param(
        100.0, unit="Pa", ge=1.0e-3, le=1.0e13, doc="Young's modulus E of the tentacle material"
    )
    density: float | None = param(
        None,
        unit="kg/m3",
        ge=1.0e-3,
        le=1.0e5,
        nullable=True,
        doc="density of the tentacle material (default: the water density, neutrally buoyant)",
    )
    bending: str = param(
        "euler-bernoulli",
        kind="choice",
        choices=("euler-bernoulli", "ewing"),
        doc="bending span: 12^(1/3) d gives stiffness EI; 'ewing' is the paper's 2d (1.5 EI)",
    )
    root: str = param(
        "clamped",
        kind="choice",
        choices=("clamped", "pinned"),
        doc="root held along its initial direction in the bell frame, or a free pin",
    )
    drag: str = param(
        "sphere",
        kind="choice",
        choices=("sphere", "slender"),
        doc="drag law: 'sphere', the paper's sphere per particle (Eq. 3-5), blind to the "
        "chain's direction; 'slender', normal and tangential drag from the water's velocity "
        "across and along the chain (independence principle, cylinder coefficients)",
    )
    normal_drag: float = param(
        1.2,
        ge=0.0,
        le=10.0,
        doc="drag = 'slender': normal drag coefficient C_n of a cylinder, on the projected "
        "area (diameter x length)",
    )
    tangential_drag: float = param(
        0.01,
        ge=0.0,
        le=1.0,
        doc="drag = 'slender': tangential (skin-friction) coefficient C_t, on the wetted "
        "area (pi x diameter x length)",
    )
    interpolation: int = param(
        1, kind="int", ge=1, le=1000, doc="tentacles drawn per simulated tentacle (render time)"
    )
    rest_curvature: float | None = param(
        None,
        unit="1/m",
        ge=0.0,
        le=1.0e6,
        nullable=True,
        doc="natural curl: curvature of the tentacle at rest, at the root (unset: straight); "
        "slack tentacles coil, the flow straightens them. rest_curvature x spacing at most 0.5",
    )
    rest_curvature_tip: float | None = param(
        None,
        unit="1/m",
        ge=0.0,
        le=1.0e6,
        nullable=True,
        doc="rest curvature at the tip, linear in arc length from the root's (unset: the same "
        "as rest_curvature, a uniform curl); larger than at the root coils the tips tighter",
    )
    curl_angle: float | None = param(
        None,
        unit="deg",
        ge=-360.0,
        le=360.0,
        nullable=True,
        doc="direction the curl turns at the root, about the root direction from the outward "
        "radial direction (unset: 0, curling outward, away from the bell axis; 180 curls "
        "inward; 90 sideways, right-handed about the root direction), fixed in the bell frame",
    )
    rest_torsion: float | None = param(
        None,
        unit="1/m",
        ge=-1.0e6,
        le=1.0e6,
        nullable=True,
        doc="helical twist of the curl: its plane turns by this many radians per metre along "
        "the chain (unset: 0, a planar curl; > 0 a right-handed helix of radius k/(k^2 + tau^2) "
        "rising 2 pi tau/(k^2 + tau^2) per turn, k the rest curvature); |rest_torsion| x "
        "spacing at most 0.5",
    )
    # Where a group's roots sit (docs/groups.md). Unset keys keep the one-table scene's layout:
    # every root on the margin, evenly spaced, the first at angle 0.
    placement: str | None = param(
        None,
        kind="choice",
        choices=("margin", "mouth"),
        nullable=True,
        doc="where the roots sit: on the bell 'margin' (unset), or around the 'mouth' under "
        "the bell, on a circle of mouth_radius in the margin plane (oral arms; a mass-spring "
        "bell carries the circle by bell.arm_anchor)",
    )
    arrangement: str | None = param(
        None,
        kind="choice",
        choices=("even", "clusters"),
        nullable=True,
        doc="roots 'even'ly spaced around the circle (unset), or in 'clusters' (like Cyanea's "
        "eight); ignored where angles are given",
    )
    clusters: int | None = param(
        None,
        kind="int",
        ge=1,
        le=1000,
        nullable=True,
        doc="number of clusters (arrangement = 'clusters'; unset: 8), evenly spaced, the "
        "count shared among them as evenly as it divides",
    )
    cluster_spread: float | None = param(
        None,
        unit="deg",
        gt=0.0,
        le=360.0,
        nullable=True,
        doc="angle one cluster's roots span (arrangement = 'clusters'; unset: half the gap "
        "between cluster centres)",
    )
    angles: tuple[float, ...] | None = param(
        None,
        unit="deg",
        kind="angles",
        nullable=True,
        doc="the roots' angles about the bell axis, from +x towards +y, one per tentacle "
        "(count = their number); overrides arrangement",
    )
    angle_offset: float | None = param(
        None,
        unit="deg",
        ge=-360.0,
        le=360.0,
        nullable=True,
        doc="turns the whole arrangement about the bell axis (unset: 0, the first root or "
        "cluster at +x)",
    )
    mouth_radius: float | None = param(
        None,
        gt=0.0,
        lt=1.0,
        nullable=True,
        doc="placement = 'mouth': radius of the roots' circle as a fraction of bell.radius "
        "(unset: 0.15)",
    )
    # How a group is drawn (render time; [look] gives the defaults).
    form: str | None = param(
        None,
        kind="choice",
        choices=("thread", "ribbon"),
        nullable=True,
        doc="drawn as a tapered 'thread' (unset) or a frilled 'ribbon' with a ruffled edge "
        "(oral arms)",
    )
    color: tuple[float, float, float] | None = param(
        None,
        kind="color",
        nullable=True,
        doc="colour of this group (linear RGB; unset: look.tentacle_color)",
    )
    drawn_radius: float | None = param(
        None,
        unit="m",
        gt=0.0,
        le=10.0,
        nullable=True,
        doc="drawn radius of a thread at its root (unset: look.tentacle_radius)",
    )
    taper: float | None = param(
        None,
        gt=0.0,
        le=1.0,
        nullable=True,
        doc="drawn radius (thread) or width (ribbon) at the tip as a fraction of the root's "
        "(unset: look.tentacle_taper)",
    )
    ribbon_width: float | None = param(
        None,
        unit="m",
        gt=0.0,
        le=10.0,
        nullable=True,
        doc="form = 'ribbon': width of the ribbon at the root (unset: 4 x spacing)",
    )
    ruffles: float | None = param(
        None,
        unit="1/m",
        ge=0.0,
        le=1.0e4,
        nullable=True,
        doc="form = 'ribbon': waves of the ruffled edge per metre of arm (unset: 1 / (2 x "
        "ribbon_width))",
    )
    ruffle_depth: float | None = param(
        None,
        ge=0.0,
        le=2.0,
        nullable=True,
        doc="form = 'ribbon': amplitude of the edge's waves as a fraction of the width "
        "(unset: 0.3; 0: a flat ribbon)",
    )


# Named groups: any name of letters, digits, '_' and '-' that is not a [tentacles] key.
GROUP_NAME_PATTERN = r"^[A-Za-z][A-Za-z0-9_-]*$"
# The group of a scene with one [tentacles] table and no named groups.
DEFAULT_GROUP = "tentacles"


@dataclass(frozen=True)
class TentacleGroup:
    """A named group of identical tentacles: ``tentacles`` holds its keys with the shared
    ``[tentacles]`` keys filled in where the group leaves them out."""

    name: str
    tentacles: Tentacles


@dataclass(frozen=True)
class Bell:
    model: str = param(
        "none",
        kind="choice",
        choices=("none", "kinematic", "mass-spring"),
        doc="bell model driving the tentacle roots: 'kinematic' (a rigid, animated bell), "
        "'mass-spring' (a soft bell of particles and springs pulsing in the MPS fluid) or "
        "'none' (a still margin whose roots are forced by [root_motion])",
    )
    radius: float = param(0.15, unit="m", gt=0.0, le=1.0e3, doc="margin radius of the bell")
    height: float = param(
        0.1, unit="m", gt=0.0, le=1.0e3, doc="height of the bell from margin to apex, at rest"
    )
    thickness: float = param(
        0.25,
        gt=0.0,
        lt=1.0,
        doc="thickness of the bell at the apex, as a fraction of its height (mass-spring: "
        "everywhere)",
    )
    lobes: int = param(
        0, kind="int", ge=0, le=1000, doc="number of marginal lobes (0: a smooth round margin)"
    )
    lobe_depth: float = param(
        0.05, ge=0.0, lt=0.5, doc="depth of the notches between lobes, a fraction of the radius"
    )
    period: float = param(1.0, unit="s", ge=1.0e-3, le=1.0e4, doc="pulse period of the bell")
    contraction: float = param(
        0.0,
        ge=0.0,
        lt=1.0,
        doc="fraction of the margin radius lost at full contraction",
    )
    waveform: str = param(
        "jet",
        kind="choice",
        choices=("jet", "sine"),
        doc="contraction in time: 'jet' (fast contraction, slow relaxation) or 'sine'",
    )
    jet_fraction: float = param(
        0.3, ge=0.05, le=0.95, doc="fraction of the period spent contracting ('jet' waveform)"
    )
    elongation: float = param(
        0.5,
        ge=0.0,
        le=2.0,
        doc="relative height gained per unit of contraction (bell turns taller)",
    )
    swim_speed: float = param(
        0.0, unit="m/s", ge=0.0, le=100.0, doc="mean forward speed of the bell along its axis"
    )
    margin_height: float = param(
        0.5,
        unit="m",
        gt=0.0,
        le=1.0e3,
        doc="mass-spring: height of the margin plane above the tank floor (the bell stands "
        "centred in the tank; a whole number of fluid.spacing)",
    )
    spring_radius: float = param(
        2.4,
        ge=2.0,
        le=4.0,
        doc="mass-spring: particles closer than this many fluid.spacing at the start are joined "
        "by springs",
    )
    spring_stiffness: float = param(
        20.0, unit="N/m", gt=0.0, le=1.0e9, doc="mass-spring: spring constant k of Hooke's law"
    )
    muscle_ratio: float = param(
        0.4,
        ge=0.0,
        lt=1.0,
        doc="mass-spring: fraction of their length the circular-muscle springs lose at full "
        "contraction (0: the muscle is off)",
    )
    muscle_stiffening: float = param(
        50.0,
        ge=1.0,
        le=1.0e4,
        doc="mass-spring: factor on the muscle springs' constant at full contraction",
    )
    spring_integration: str = param(
        "explicit",
        kind="choice",
        choices=("explicit", "implicit"),
        doc="mass-spring: springs in MPS's explicit stage as the force now ('explicit', the "
        "paper; the step is held under the springs' stability limit) or by linearised "
        "backward Euler ('implicit', Baraff & Witkin 1998; the fluid's limits alone set the "
        "step)",
    )
    root_placement: str = param(
        "edge",
        kind="choice",
        choices=("edge", "surface", "particles"),
        doc="mass-spring: where the marginal tentacles hang from: 'edge', the outer edge of the "
        "drawn margin's underside, turning with the wall, so that the margin's inward turn does "
        "not sweep its wall over the tentacles; 'surface', the underside of the drawn margin "
        "below the lowest particle layer (the default from issue 25 until 'edge'); 'particles', "
        "the mean of the lowest particle layer, half a spacing inside the drawn tissue (the "
        "paper's §4.2.4; what runs before the key had)",
    )
    arm_anchor: str = param(
        "subumbrella",
        kind="choice",
        choices=("subumbrella", "margin"),
        doc="mass-spring: what the oral arms (groups placed at the 'mouth') hang from: "
        "'subumbrella', the centre of the drawn underside, by a stalk (the manubrium) as long as "
        "that centre stands above the margin plane at rest, so that the arms stay under the "
        "bell however it deforms; 'margin', their circle in the margin plane about its centre "
        "(what runs before the key had)",
    )
    muscle_band: float = param(
        0.3,
        gt=0.0,
        lt=1.0,
        doc="mass-spring: height of the margin band holding the circular muscle, a fraction of "
        "the bell height",
    )
    muscle_taper: float = param(
        0.0,
        ge=0.0,
        le=1.0,
        doc="mass-spring: how the circular muscle weakens up its band: a muscle spring's "
        "shortening and stiffening are scaled by 1 - taper x (its mid-point's height / the "
        "band's height); 0: the whole band alike (the paper's), 1: full at the margin, none at "
        "the band's top",
    )
    tentacle_contact: bool = param(
        True,
        kind="bool",
        doc="tentacles and oral arms are kept out of the bell's tissue, the closed shell every "
        "output draws: after each substep a particle inside it is put on the nearest point of "
        "its surface (an inelastic, frictionless contact; the bell does not feel it); false: "
        "the paper's model, whose tentacles feel only the water",
    )
    speed_variation: float = param(
        0.8,
        ge=0.0,
        le=1.0,
        doc="swimming speed swing with the pulse: the slowest speed is (1 - this) x swim_speed",
    )


@dataclass(frozen=True)
class RootMotion:
    amplitude: float = param(
        0.0,
        unit="m",
        ge=0.0,
        le=1.0e3,
        doc="amplitude of the forced root oscillation (only with bell.model = none)",
    )
    frequency: float = param(
        1.0, unit="Hz", ge=0.0, le=1.0e3, doc="frequency of the root oscillation"
    )
    direction: str | tuple[float, float, float] = param(
        "radial",
        kind="direction",
        doc="'radial' (outward from the bell axis) or a vector [x, y, z] (normalised)",
    )


@dataclass(frozen=True)
class Fluid:
    model: str = param(
        "none",
        kind="choice",
        choices=("none", "mps"),
        doc="'mps': a particle fluid (Koshizuka & Oka's MPS); 'none': the assumed flow only",
    )
    dimensions: int = param(
        2, kind="int", ge=2, le=3, doc="2 (x, y with y up) or 3 (z up) for a fluid-only scene"
    )
    spacing: float = param(
        0.005, unit="m", gt=0.0, le=100.0, doc="particle spacing l0 of the fluid lattice"
    )
    geometry: str = param(
        "dam-break",
        kind="choice",
        choices=("dam-break", "hydrostatic"),
        doc="'dam-break': a water column against the left wall; 'hydrostatic': the tank "
        "filled to water_height",
    )
    tank_width: float = param(0.5, unit="m", gt=0.0, le=1.0e3, doc="inner width of the tank (x)")
    tank_height: float = param(
        0.3, unit="m", gt=0.0, le=1.0e3, doc="inner height of the tank walls"
    )
    tank_depth: float = param(
        0.1, unit="m", gt=0.0, le=1.0e3, doc="inner depth of the tank (y, 3-D only)"
    )
    water_width: float = param(
        0.1, unit="m", gt=0.0, le=1.0e3, doc="width a of the water column (dam-break)"
    )
    water_height: float = param(
        0.2, unit="m", gt=0.0, le=1.0e3, doc="height of the water column or of the still water"
    )
    water_side: str = param(
        "left",
        kind="choice",
        choices=("left", "right"),
        doc="dam-break: the column stands against the left (x = 0) or the right "
        "(x = tank_width) wall",
    )
    obstacles: tuple[tuple[float, ...], ...] = param(
        (),
        unit="m",
        kind="boxes",
        doc="solid boxes in the tank (3-D), each [x0, y0, z0, x1, y1, z1] (lower and upper "
        "corners): the lattice's sites inside a box are wall particles within one spacing "
        'of its faces, dummies deeper (docs/fluid.md, "Obstacles and probes")',
    )
    source: str = param(
        "standard",
        kind="choice",
        choices=("standard", "mixed"),
        doc="PPE source: 'standard', the number density (Koshizuka & Oka 1996); 'mixed', the "
        "velocity divergence plus 0.01 of the number density (Tanaka & Masunaga 2010), with "
        "gradient = 'corrected' only",
    )
    gradient: str = param(
        "standard",
        kind="choice",
        choices=("standard", "corrected", "conservative"),
        doc="pressure gradient: 'standard', the minimum-pressure gradient (Koshizuka & Oka "
        "1996); 'corrected', times the inverse moment matrix of each particle's neighbourhood "
        "(Khayyer & Gotoh 2011): a particle at a flat free surface carries its full weight; "
        "'conservative', pair-wise antisymmetric (Khayyer & Gotoh 2008): the pressure "
        "conserves the water's momentum, not with surface_repulsion",
    )
    surface: str = param(
        "standard",
        kind="choice",
        choices=("standard", "either-density"),
        doc="free-surface detection: 'standard', n* < beta n0 after the explicit stage "
        "(Koshizuka & Oka 1996); 'either-density', also where n < beta n0 at the start of the "
        "step, so that a splash particle pushed into a neighbour stays on the surface (this "
        "project's; with source = 'mixed' only)",
    )
    surface_threshold: float | None = param(
        None,
        gt=0.5,
        lt=1.0,
        nullable=True,
        doc="beta: a particle with n < beta n0 is on the free surface (default: 0.97 on the "
        "square lattice, 0.93 on the hexagonal and fcc ones, whose second row or layer has "
        "n = 0.962 or 0.964 n0)",
    )
    collision_distance: float = param(
        0.5,
        gt=0.0,
        lt=1.0,
        doc="pairs closer than this many spacings that approach each other collide (momentum "
        "exchanged, restitution 0.2; Koshizuka & Oka's collision model); 0.8 on the 2-D presets "
        "keeps splash particles from being thrown off the floor (docs/fluid.md)",
    )
    surface_repulsion: bool = param(
        False,
        kind="bool",
        doc="free-surface particles are pushed apart along the surface by the largest pressure "
        "among their fluid neighbours, as the minimum-pressure gradient pushes interior "
        "particles apart (this project's, docs/theory/fluid.md F10b): without it nothing holds "
        "surface particles apart along the surface and still water's top row slides; on in the "
        "2-D presets",
    )
    lattice: str = param(
        "square",
        kind="choice",
        choices=("square", "hexagonal", "fcc"),
        doc="initial arrangement of the particles: 'square' (cubic in 3-D); 'hexagonal' (2-D "
        "fluid-only scenes): rows sqrt(3)/2 spacing apart, each particle with six neighbours at "
        "one spacing; 'fcc' (3-D fluid-only scenes): face-centred cubic, its close-packed "
        "layers horizontal sqrt(2/3) spacing apart, each particle with twelve neighbours at one "
        "spacing. The square and cubic lattices are unstable to shear under the pressure "
        "gradient; with the surface repulsion still water stays still on the other two "
        "(docs/fluid.md)",
    )
    solver: str = param(
        "iccg",
        kind="choice",
        choices=("iccg", "cg", "deflated"),
        doc="pressure solver: incomplete-Cholesky preconditioned CG, plain CG, or CG with "
        "Jacobi and a coarse problem on aggregates of particles (two-level deflation, Tang et "
        "al. 2009; docs/fluid.md)",
    )
    device: str = param(
        "cpu",
        kind="choice",
        choices=("cpu", "cuda"),
        doc="where the fluid is stepped: 'cpu' (the CPU cores), or 'cuda' (an NVIDIA GPU, "
        "`pip install jellysim[cuda]`; the pressure by CG with Jacobi, plus a coarse "
        "correction where fluid.solver is 'deflated'; a soft bell's springs and muscle on the "
        "GPU too; docs/fluid.md)",
    )
    matrix_precision: str = param(
        "double",
        kind="choice",
        choices=("double", "single"),
        doc="precision in which the pressure matrix's off-diagonal entries are stored: "
        "'double', or 'single' (rounded; the diagonal, the vectors and every sum stay in double, "
        "the diagonal summed from the rounded entries): each product with the matrix reads 8 "
        "bytes an entry instead of 12, a faster solve where memory bandwidth bounds it; the "
        "same flow on another round-off path (docs/fluid.md)",
    )
    coarse_cell: float = param(
        4.0,
        ge=2.0,
        le=16.0,
        doc="edge of the deflated solver's aggregates, in particle spacings",
    )
    neighbour_skin: float = param(
        0.0,
        ge=0.0,
        le=2.0,
        doc="Verlet skin of the neighbour lists, in particle spacings: 0 searches the cells "
        "twice a step; above 0 one wider search serves until a particle has moved half the "
        "skin (faster; other round-off)",
    )
    tolerance: float = param(
        1.0e-8, gt=0.0, lt=1.0, doc="relative residual at which the pressure solve stops"
    )
    courant: float = param(0.2, gt=0.0, le=1.0, doc="Courant number of the fluid's time step")


@dataclass(frozen=True)
class Probes:
    height: tuple[tuple[str, tuple[float, ...]], ...] = param(
        (),
        unit="m",
        kind="points",
        doc="water-height probes, NAME = [x, y] (3-D) or [x] (2-D): vertical lines; each "
        "frame the result's probes/height holds the water's depth along each line "
        "(docs/theory/fluid.md F14)",
    )
    pressure: tuple[tuple[str, tuple[float, ...]], ...] = param(
        (),
        unit="m",
        kind="points",
        doc="pressure probes, NAME = [x, y, z] (3-D) or [x, y] (2-D), each on a face of the "
        "tank or of an obstacle; the result's probes/pressure holds the wall pressure there, "
        "averaged over each frame's steps (docs/theory/fluid.md F15)",
    )
    reference: str = param(
        "none",
        kind="choice",
        choices=("none", "spheric-test2"),
        doc="measurements that jellysim plot draws the probes against: 'spheric-test2', "
        "Kleefsman et al. (2005)'s dam break with a box (SPHERIC benchmark Test 2)",
    )


@dataclass(frozen=True)
class Look:
    bell_color: tuple[float, float, float] = param(
        (0.9, 0.45, 0.15), kind="color", doc="colour of the bell (linear RGB)"
    )
    tentacle_color: tuple[float, float, float] = param(
        (0.7, 0.25, 0.1), kind="color", doc="colour of the tentacles (linear RGB)"
    )
    bell_transparency: float = param(
        0.5, ge=0.0, le=0.95, doc="how much light passes through the bell (0 opaque)"
    )
    glow: float = param(0.3, ge=0.0, le=1.0, doc="the bell's own glow at final quality")
    water_color: tuple[float, float, float] = param(
        (0.01, 0.06, 0.12), kind="color", doc="colour of the water (tint and depth fade)"
    )
    tentacle_radius: float | None = param(
        None,
        unit="m",
        gt=0.0,
        le=10.0,
        nullable=True,
        doc="drawn radius of a tentacle at its root (default: 0.25 x tentacles.spacing)",
    )
    tentacle_taper: float = param(
        0.3, gt=0.0, le=1.0, doc="drawn radius at the tip as a fraction of the root's"
    )
    tentacle_transparency: float | None = param(
        None,
        ge=0.0,
        le=0.95,
        nullable=True,
        doc="how much of the water shows through a tentacle seen face-on (0 opaque; default 0.3)",
    )
    rim: float | None = param(
        None,
        ge=0.0,
        le=1.0,
        nullable=True,
        doc="Fresnel-like rim: face-on the bell's transparency moves this far towards clear, "
        "at the silhouette this far towards opaque and lighter (0: the same at every angle; "
        "default 0.6)",
    )
    stripes: int | None = param(
        None,
        kind="int",
        ge=0,
        le=1000,
        nullable=True,
        doc="radial stripes seen through the bell, in a mix of the bell's and the tentacles' "
        "colours (default: bell.lobes / 2, one on every other lobe; 0: none)",
    )
    gonads: int | None = param(
        None,
        kind="int",
        ge=0,
        le=16,
        nullable=True,
        doc="horseshoe gonads seen through the bell, open towards the margin, on the "
        "subumbrella about the bell's axis (Aurelia's four; default 0: none)",
    )
    gonad_color: tuple[float, float, float] | None = param(
        None,
        kind="color",
        nullable=True,
        doc="colour of the gonads (linear RGB; default a violet)",
    )
    marine_snow: int | None = param(
        None,
        kind="int",
        ge=0,
        le=100000,
        nullable=True,
        doc="drifting particles (marine snow) in the water around the camera (0: none; "
        "default 400)",
    )
    light_shafts: float | None = param(
        None,
        ge=0.0,
        le=1.0,
        nullable=True,
        doc="brightness of the light shafts from above at final quality (default 0.5)",
    )
    depth_of_field: float | None = param(
        None,
        ge=0.0,
        le=10.0,
        nullable=True,
        doc="focal blur at final quality, focused on the jellyfish (0: everything sharp; "
        "default 1.0)",
    )


@dataclass(frozen=True)
class Solver:
    dt_safety: float = param(
        1.0,
        ge=1.0e-3,
        le=10.0,
        doc="factor on the substep the code chooses (smaller: more accurate; for studies)",
    )
    checkpoint_every: int = param(
        10, kind="int", ge=1, doc="frames between checkpoints (for --resume)"
    )


@dataclass(frozen=True)
class Scene:
    name: str = param(
        "scene", kind="str", pattern=r"^(?!\.+$)[A-Za-z0-9_.-]+$", doc="name of the scene"
    )
    duration: float = param(10.0, unit="s", gt=0.0, le=1.0e6, doc="simulated time")
    fps: float = param(30.0, unit="1/s", gt=0.0, le=10000.0, doc="frames stored per second")
    seed: int = param(1, kind="int", ge=0, doc="seed of every random draw (flow noise)")
    water: Water = field(default_factory=Water)
    flow: Flow = field(default_factory=Flow)
    tentacles: Tentacles = field(default_factory=Tentacles)
    bell: Bell = field(default_factory=Bell)
    root_motion: RootMotion = field(default_factory=RootMotion)
    fluid: Fluid = field(default_factory=Fluid)
    probes: Probes = field(default_factory=Probes)
    look: Look = field(default_factory=Look)
    solver: Solver = field(default_factory=Solver)
    # The named groups [tentacles.NAME], in the scene's order; none: [tentacles] is the one group.
    # Not a TOML key of its own (the loader fills it from the sub-tables of [tentacles]).
    tentacle_groups: tuple[TentacleGroup, ...] = field(default=(), metadata={"internal": True})

    def __post_init__(self) -> None:
        # flow.model = "auto" resolves here, however the scene is made: the tentacles feel the
        # simulated water where the scene has water for them (issue 26), and the scene (and so
        # every text written of it) names the model it resolved to.
        if self.flow.model == "auto":
            model = "fluid" if self.has_water_for_tentacles else "bell"
            object.__setattr__(self, "flow", dataclasses.replace(self.flow, model=model))

    @property
    def has_water_for_tentacles(self) -> bool:
        """Whether the tentacles can feel a simulated water: a soft bell in MPS water."""
        return self.bell.model == "mass-spring" and self.fluid.model == "mps"

    @property
    def frame_count(self) -> int:
        """F = round(duration * fps) + 1 frames, t = 0 included."""
        return int(round(self.duration * self.fps)) + 1

    @property
    def tentacle_density(self) -> float:
        """Density of the tentacles, the water's when unset (neutral buoyancy)."""
        d = self.tentacles.density
        return self.water.density if d is None else d

    @property
    def groups(self) -> tuple[TentacleGroup, ...]:
        """Every group of tentacles, in order: the named groups, or ``[tentacles]`` alone."""
        return self.tentacle_groups or (TentacleGroup(DEFAULT_GROUP, self.tentacles),)

    @property
    def tentacle_count(self) -> int:
        """Simulated tentacles over all groups."""
        return sum(g.tentacles.count for g in self.groups)

    @property
    def particle_count(self) -> int:
        """Simulated tentacle particles over all groups."""
        return sum(g.tentacles.count * g.tentacles.particles for g in self.groups)

    @property
    def max_particles(self) -> int:
        """The most particles of any group's tentacles (P of the result's tentacle arrays)."""
        return max((g.tentacles.particles for g in self.groups if g.tentacles.count), default=0)

    def group_scene(self, index: int) -> Scene:
        """The scene as group ``index`` alone sees it: its keys as the ``[tentacles]`` table."""
        if not self.tentacle_groups:
            return self
        return dataclasses.replace(
            self, tentacles=self.tentacle_groups[index].tentacles, tentacle_groups=()
        )


SECTIONS: dict[str, type] = {
    f.name: f.type if isinstance(f.type, type) else globals()[str(f.type)]
    for f in dataclasses.fields(Scene)
    if f.name
    in ("water", "flow", "tentacles", "bell", "root_motion", "fluid", "probes", "look", "solver")
}
