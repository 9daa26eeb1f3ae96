"""Tentacle model set-up: lumped masses, the bending matrix and the substep choice (paper §4.1)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from jellysim.config.schema import Scene
from jellysim.errors import InputError
from jellysim.tentacle.kernels import DRAG_SLENDER, DRAG_SPHERE, ChainModel, Medium, drag_gain
from jellysim.tentacle.roots import Forcing

# Cube of the span L of the paper's three-point bending cell, in units of d^3 (Eq. T2).
# "euler-bernoulli": L^3 = 12 d^3 makes the chain's continuum stiffness exactly EI;
# "ewing": the paper's span L = 2d, whose continuum stiffness is 1.5 EI (docs/theory/tentacle.md).
SPAN_CUBED = {"euler-bernoulli": 12.0, "ewing": 8.0}

CANTILEVER_FIRST_ROOT = 1.8751040687119611  # beta_1 L of a clamped-free beam
TENSION_COURANT = 2.0  # segments a tension wave may cross per substep
# The rest shape's force is explicit: dt <= REST_SHAPE_STEP sqrt(m / (c turn)), turn the rest
# turning per segment. Measured on a 60-particle chain perturbed from its curl (kappa d = 0.5, with
# and without torsion, clamped and pinned, E = 1e5 to 9e9 Pa): stable at 4, unstable at 8.
REST_SHAPE_STEP = 2.0
MAX_SUBSTEPS_PER_FRAME = 100_000


def second_moment(diameter: float) -> float:
    """I = pi d^4 / 64 (m^4), paper Eq. 2."""
    return math.pi * diameter**4 / 64.0


def bending_stiffness(youngs_modulus: float, diameter: float, bending: str) -> float:
    """c = 48 E I / L^3 (N/m), the paper's Eq. 1 solved for P / h."""
    return 48.0 * youngs_modulus * second_moment(diameter) / (SPAN_CUBED[bending] * diameter**3)


def effective_bending_rigidity(youngs_modulus: float, diameter: float, bending: str) -> float:
    """Continuum limit of the chain's stiffness, EI_eff = c d^3 / 4 (N m^2)."""
    return bending_stiffness(youngs_modulus, diameter, bending) * diameter**3 / 4.0


def bending_bands(particles: int, clamped: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bands of the dimensionless K (P, P), bending force ``-c K x`` per coordinate,
    Eq. (T3): its diagonal (P,), first (P-1,) and second (P-2,) off-diagonals. K is never formed:
    its memory would grow as P^2 (75 GiB at the largest ``tentacles.particles``).

    K = (1/4) sum_i s_i s_i^T over interior particles with the stencil s_i = (1, -2, 1) at
    (i-1, i, i+1); a clamped root adds (1/2) s_c s_c^T with s_c = (-1, 1) at (0, 1), the isotropic
    part of the clamp term (its rank-one part along t is applied in the kernel). Every entry is a
    sum of quarters of small integers, exact in floating point.
    """
    diagonal = np.zeros(particles)
    first = np.zeros(particles - 1)
    second = np.zeros(max(particles - 2, 0))
    interior = np.arange(1, particles - 1)
    np.add.at(diagonal, interior - 1, 0.25)
    np.add.at(diagonal, interior, 1.0)
    np.add.at(diagonal, interior + 1, 0.25)
    np.add.at(first, interior - 1, -0.5)
    np.add.at(first, interior, -0.5)
    second[interior - 1] += 0.25
    if clamped:
        diagonal[:2] += 0.5
        first[0] -= 0.5
    return diagonal, first, second


def build_chain_model(
    particles: int,
    spacing: float,
    youngs_modulus: float,
    tentacle_density: float,
    bending: str = "euler-bernoulli",
    root: str = "clamped",
    drag: str = "sphere",
    normal_drag: float = 0.0,
    tangential_drag: float = 0.0,
) -> ChainModel:
    """Lumped masses (interior: one segment pi d^3 / 4; tip: half) and the bending bands.

    ``root`` is "clamped" or "pinned" (prescribed root), or "free": a detached chain whose root
    is a free end like the tip (used to test falling and momentum conservation). ``drag`` is
    "sphere" (the paper's law) or "slender" with the coefficients C_n, C_t (Eq. T14).
    """
    segment_volume = math.pi * spacing**3 / 4.0
    volume = np.full(particles, segment_volume)
    volume[-1] = 0.5 * segment_volume
    free_root = root == "free"
    if free_root:
        volume[0] = 0.5 * segment_volume
    mass = tentacle_density * volume
    inverse_mass = 1.0 / mass
    if not free_root:
        inverse_mass[0] = 0.0  # the root is prescribed
    clamped = root == "clamped"
    diagonal, off1, off2 = bending_bands(particles, clamped)
    first = 0 if free_root else 1
    n = particles - first
    return ChainModel(
        mass=mass,
        inverse_mass=inverse_mass,
        volume=volume,
        stiffness_diag=diagonal[first:].copy(),
        stiffness_off1=np.concatenate([off1[first:], np.zeros(1)])[:n].copy(),
        stiffness_off2=np.concatenate([off2[first:], np.zeros(2)])[:n].copy(),
        root_coupling=np.array([off1[0], off2[0] if particles > 2 else 0.0]),
        bending_stiffness=bending_stiffness(youngs_modulus, spacing, bending),
        clamped=clamped,
        spacing=float(spacing),
        free_root=free_root,
        drag_law=DRAG_SLENDER if drag == "slender" else DRAG_SPHERE,
        normal_drag=float(normal_drag),
        tangential_drag=float(tangential_drag),
    )


def chain_model_for(scene: Scene) -> ChainModel:
    t = scene.tentacles
    return build_chain_model(
        t.particles,
        t.spacing,
        t.youngs_modulus,
        scene.tentacle_density,
        t.bending,
        t.root,
        t.drag,
        t.normal_drag,
        t.tangential_drag,
    )


def rest_second_differences(
    particles: int,
    spacing: float,
    curvature: float,
    curvature_tip: float,
    torsion: float,
    angle: float,
) -> np.ndarray:
    """The rest shape of one chain as the components (P, 3), m, of its rest second differences
    in the transported frames (tangent, normal, tangent x normal), Eq. (T10).

    At node i = 1..P-2, arc length s_i = i d along a chain of length L = (P - 1) d: curvature
    ``kappa_i = curvature + (curvature_tip - curvature) s_i / L`` (1/m), turning angle
    ``theta_i = 2 asin(kappa_i d / 2)`` (a planar chain's nodes then lie on the circle of radius
    1/kappa), and the curl's direction ``phi_i = angle + torsion (s_i - d)`` (rad, torsion in
    1/m) about the tangent from the root frame's normal:
    ``r_i = d (cos theta_i - 1, sin theta_i cos phi_i, sin theta_i sin phi_i)``. The root and tip
    rows are zero. All zeros for a straight chain.
    """
    rest = np.zeros((particles, 3))
    if curvature == 0.0 and curvature_tip == 0.0:
        return rest
    d = spacing
    nodes = np.arange(1, particles - 1)
    arc = nodes * d
    kappa = curvature + (curvature_tip - curvature) * arc / ((particles - 1) * d)
    theta = 2.0 * np.arcsin(np.minimum(0.5 * kappa * d, 1.0))
    phi = angle + torsion * (arc - d)
    rest[nodes, 0] = d * (np.cos(theta) - 1.0)
    rest[nodes, 1] = d * np.sin(theta) * np.cos(phi)
    rest[nodes, 2] = d * np.sin(theta) * np.sin(phi)
    return rest


def rest_shape_for(scene: Scene) -> np.ndarray:
    """Every simulated tentacle's rest shape (T, P, 3), m (:func:`rest_second_differences`)
    from the scene's ``tentacles.rest_curvature``, ``rest_curvature_tip``, ``rest_torsion`` and
    ``curl_angle``; unset keys give zeros (straight)."""
    t = scene.tentacles
    curvature = t.rest_curvature or 0.0
    tip = curvature if t.rest_curvature_tip is None else t.rest_curvature_tip
    one = rest_second_differences(
        t.particles,
        t.spacing,
        curvature,
        tip,
        t.rest_torsion or 0.0,
        math.radians(t.curl_angle or 0.0),
    )
    return np.broadcast_to(one, (t.count, *one.shape)).copy()


def curl_normals(directions: np.ndarray, outward: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Unit normals (S, T, 3) of the rest shapes' root frames: the outward direction ``outward``
    (S, T, 3), unit and perpendicular to the bell axis, made perpendicular to the clamp
    direction ``directions`` (S, T, 3). Where a root points along its outward direction, the
    bell axis ``axes`` (S, 3) made perpendicular to it instead, and where that fails too (a root
    on the axis pointing along it), the world x axis.
    """
    directions = np.ascontiguousarray(directions, dtype=float)
    normals = np.empty_like(directions)
    _curl_normals(
        directions,
        np.ascontiguousarray(np.broadcast_to(outward, directions.shape), dtype=float),
        np.ascontiguousarray(axes, dtype=float),
        normals,
    )
    return normals


@njit(cache=True)
def _perpendicular(candidate: np.ndarray, direction: np.ndarray, out: np.ndarray) -> bool:
    """``candidate`` made perpendicular to the unit ``direction`` and normalised into ``out``;
    False (``out`` untouched) where less than 1e-6 of it is left."""
    along = candidate[0] * direction[0] + candidate[1] * direction[1] + candidate[2] * direction[2]
    a0 = candidate[0] - along * direction[0]
    a1 = candidate[1] - along * direction[1]
    a2 = candidate[2] - along * direction[2]
    size = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if not size > 1e-6:
        return False
    out[0] = a0 / size
    out[1] = a1 / size
    out[2] = a2 / size
    return True


@njit(cache=True)
def _first_perpendicular(
    outward: np.ndarray,
    axis: np.ndarray,
    x_axis: np.ndarray,
    direction: np.ndarray,
    out: np.ndarray,
) -> None:
    """:func:`curl_normals`' choice for one root: the first of ``outward``, the bell ``axis`` and
    the world ``x_axis`` that :func:`_perpendicular` can make perpendicular to ``direction``."""
    if not _perpendicular(outward, direction, out):
        if not _perpendicular(axis, direction, out):
            _perpendicular(x_axis, direction, out)


@njit(cache=True)
def _curl_normals(
    directions: np.ndarray, outward: np.ndarray, axes: np.ndarray, normals: np.ndarray
) -> None:
    """:func:`curl_normals` into ``normals``, every operation in NumPy's order (the same bits)."""
    x_axis = np.array([1.0, 0.0, 0.0])
    for s in range(directions.shape[0]):
        for t in range(directions.shape[1]):
            _first_perpendicular(outward[s, t], axes[s], x_axis, directions[s, t], normals[s, t])


def carried_curl_normals(
    rotation: np.ndarray,
    cos: np.ndarray,
    outward: np.ndarray,
    directions: np.ndarray,
    axes: np.ndarray,
) -> np.ndarray:
    """:func:`curl_normals` of the outward directions ``outward`` (T, 3) at t = 0 carried by the
    rotation that takes the bell axis at t = 0 to ``axes`` (S, 3): ``rotation`` (S, 3) the cross
    product of the two axes and ``cos`` (S,) their dot product (Rodrigues' formula, as
    :func:`jellysim.tentacle.kernels._transport` writes it). Compiled, in NumPy's order of
    operations (the bits of rotating with NumPy's broadcasting, then :func:`curl_normals`)."""
    directions = np.ascontiguousarray(directions, dtype=float)
    normals = np.empty_like(directions)
    _carried_curl_normals(
        np.ascontiguousarray(rotation, dtype=float),
        np.ascontiguousarray(cos, dtype=float),
        np.ascontiguousarray(outward, dtype=float),
        directions,
        np.ascontiguousarray(axes, dtype=float),
        normals,
    )
    return normals


@njit(cache=True)
def _carried_curl_normals(
    rotation: np.ndarray,
    cos: np.ndarray,
    outward: np.ndarray,
    directions: np.ndarray,
    axes: np.ndarray,
    normals: np.ndarray,
) -> None:
    x_axis = np.array([1.0, 0.0, 0.0])
    carried = np.empty(3)
    for s in range(directions.shape[0]):
        c0, c1, c2 = rotation[s, 0], rotation[s, 1], rotation[s, 2]
        co = cos[s]
        for t in range(directions.shape[1]):
            u0, u1, u2 = outward[t, 0], outward[t, 1], outward[t, 2]
            along = c0 * u0 + c1 * u1 + c2 * u2
            scale = along / (1.0 + co)
            carried[0] = (co * u0 + (c1 * u2 - c2 * u1)) + scale * c0
            carried[1] = (co * u1 + (c2 * u0 - c0 * u2)) + scale * c1
            carried[2] = (co * u2 + (c0 * u1 - c1 * u0)) + scale * c2
            _first_perpendicular(carried, axes[s], x_axis, directions[s, t], normals[s, t])


def medium_for(scene: Scene) -> Medium:
    w = scene.water
    return Medium(
        density=w.density,
        viscosity=w.viscosity,
        gravity=np.array(w.gravity, dtype=np.float64),
        tentacle_density=scene.tentacle_density,
    )


@dataclass(frozen=True)
class SubstepPlan:
    """The substep of the tentacle integrator: ``substeps`` per frame of length ``dt``.

    ``limits`` maps each accuracy limit's name to its value in s (before ``dt_safety``).
    """

    dt: float
    substeps: int
    limits: dict[str, float]

    def describe(self) -> str:
        binding = min(self.limits, key=self.limits.__getitem__)
        return f"dt = {self.dt:.3g} s, {self.substeps} substeps per frame (limited by {binding})"


def characteristic_speed(scene: Scene, forcing: Forcing) -> float:
    """A speed scale (m/s) of the tentacles relative to the water, their roots driven with
    ``forcing``."""
    return abs(scene.flow.speed) + 3.0 * scene.flow.noise + forcing.speed


def plan_substeps(scene: Scene, forcing: Forcing) -> SubstepPlan:
    """Choose the substep from the model's time scales; the user never sets dt.

    Bending and drag are integrated implicitly (unconditionally stable), so the limits are for
    accuracy: a tenth of the period over 2 pi of the chain's first cantilever mode
    ``omega_1 = (1.875 / L)^2 sqrt(EI_eff / (rho_t A))``; half the drag relaxation time
    ``m / k(U)`` at the characteristic relative speed U; a hundredth of the root-motion period (of
    the equivalent sine for a bell's pulse: ``forcing``, the root driver's
    :meth:`jellysim.tentacle.roots.RootDriver.forcing`);
    a twentieth of the noise correlation time; the frame interval; and a Courant number of 2
    for the tension waves along the chain, ``dt <= 2 d / c`` with ``c = sqrt(T / (rho_t A))`` and
    T the tension that drag, buoyant weight and the root's acceleration can build up over the
    chain (the length constraints are linearised over a step, so a wave may cross only a few
    segments per step). A chain with a rest shape adds the stability limit of its explicit
    force, ``2 sqrt(m / (c d sqrt(kappa_max^2 + tau^2)))`` (docs/theory/tentacle.md §6).
    """
    t = scene.tentacles
    frame_dt = 1.0 / scene.fps
    d = t.spacing
    length = (t.particles - 1) * d
    area = math.pi * d * d / 4.0
    rigidity = effective_bending_rigidity(t.youngs_modulus, d, t.bending)
    omega_1 = (CANTILEVER_FIRST_ROOT / length) ** 2 * math.sqrt(
        rigidity / (scene.tentacle_density * area)
    )
    mass = scene.tentacle_density * area * d
    gain = drag_gain(
        max(characteristic_speed(scene, forcing), 1e-12),
        d,
        scene.water.density,
        scene.water.viscosity,
    )
    if t.drag == "slender":  # the larger of its gains, all of the speed across the chain
        gain = (
            0.5
            * scene.water.density
            * d
            * d
            * max(t.normal_drag, math.pi * t.tangential_drag)
            * max(characteristic_speed(scene, forcing), 1e-12)
        )
    speed = characteristic_speed(scene, forcing)
    volume = area * d
    gravity = math.sqrt(sum(g * g for g in scene.water.gravity))
    per_particle = (
        gain * speed
        + abs(scene.tentacle_density - scene.water.density) * volume * gravity
        + mass * forcing.acceleration
    )
    tension = (t.particles - 1) * per_particle
    wave_speed = math.sqrt(tension / (scene.tentacle_density * area))
    limits = {"bending": 0.1 / omega_1}
    if gain > 0.0:  # the slender law with both coefficients zero has no drag
        limits["drag"] = 0.5 * mass / gain
    limits["frame"] = frame_dt
    if wave_speed > 0.0:
        limits["tension"] = TENSION_COURANT * d / wave_speed
    if forcing.period > 0.0:
        limits["root motion"] = 0.01 * forcing.period
    turn = d * math.hypot(
        max(t.rest_curvature or 0.0, t.rest_curvature_tip or 0.0), t.rest_torsion or 0.0
    )
    if turn > 0.0 and max(t.rest_curvature or 0.0, t.rest_curvature_tip or 0.0) > 0.0:
        c = bending_stiffness(t.youngs_modulus, d, t.bending)
        limits["rest shape"] = REST_SHAPE_STEP * math.sqrt(mass / (c * turn))
    if scene.flow.noise > 0.0:
        limits["noise"] = scene.flow.noise_correlation_time / 20.0
    target = scene.solver.dt_safety * min(limits.values())
    substeps = max(1, math.ceil(frame_dt / target - 1e-9))
    binding = min(limits, key=limits.__getitem__)
    if substeps > MAX_SUBSTEPS_PER_FRAME:
        raise InputError(
            f"the scene needs {substeps:.3g} substeps per frame (limited by {binding}): "
            f"at most {MAX_SUBSTEPS_PER_FRAME}; raise solver.dt_safety or fps, or soften the scene"
        )
    return SubstepPlan(dt=frame_dt / substeps, substeps=substeps, limits=limits)
