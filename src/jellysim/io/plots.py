"""The paper's figures for a result (matplotlib, Agg backend, PNG files)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from jellysim import fields
from jellysim.config import Scene
from jellysim.io.result import Result

if TYPE_CHECKING:
    from matplotlib.axes import Axes


def flow_label(scene: Scene) -> str:
    """What the tentacles' water was, for a title: the paper's flow (``v = 0.3 m/s``), a current
    (``current 0.3 m/s along (1, 0, 0)``) or the simulated water (``simulated water``, with
    ``, two-way``)."""
    f = scene.flow
    if f.model == "current":
        direction = ", ".join(f"{c:g}" for c in f.direction)
        return f"current {f.speed:g} m/s along ({direction})"
    if f.model == "fluid":
        return "simulated water" + (", two-way" if f.two_way else "")
    return f"v = {f.speed:g} m/s"


def _drag_label(law: str) -> str:
    return "" if law == "sphere" else f", {law} drag"


def _pyplot():  # type: ignore[no-untyped-def]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# Per group (index into the result's tentacle_groups): the colour of its simulated tentacles and
# of the tentacles drawn between them; group 0 keeps the one-group figures' purple and orange.
GROUP_COLOURS: tuple[tuple[str, str], ...] = (
    ("tab:purple", "tab:orange"),
    ("tab:green", "tab:olive"),
    ("tab:blue", "tab:cyan"),
    ("tab:red", "tab:pink"),
    ("tab:brown", "tab:gray"),
)


def group_colours(index: int) -> tuple[str, str]:
    """The (simulated, drawn) colours of group ``index``."""
    return GROUP_COLOURS[index % len(GROUP_COLOURS)]


def root_tip_trace(result: Result, path: Path, tentacle: int | None = None) -> Path:
    """Paper Figs. 7-8: x of a tentacle's root and of its tip (its own last particle) against
    time, one panel per tentacle group: each group's first tentacle, or the one ``tentacle``
    (an index into the result's T tentacles, across groups)."""
    plt = _pyplot()
    time = result.time
    names = result.tentacle_groups
    group = result.tentacle_group
    particles = result.tentacle_particles
    if tentacle is None:
        picks = [int(np.flatnonzero(group == g)[0]) for g in np.unique(group)]
    else:
        picks = [range(group.size)[tentacle]]
    positions = result.tentacle_positions
    scene = result.scene
    fig, axes = plt.subplots(
        len(picks), 1, figsize=(8, 0.4 + 3.2 * len(picks)), dpi=120, sharex=True, squeeze=False
    )
    for ax, k in zip(axes[:, 0], picks, strict=True):
        x = positions[:, k, : particles[k], 0]
        ax.plot(time, x[:, 0], color="tab:red", lw=1.6, label="root")
        ax.plot(time, x[:, -1], color="tab:blue", lw=1.2, label="tip")
        ax.set_ylabel("x [m]")
        t = scene.groups[group[k]].tentacles
        named = f"group {names[group[k]]}, " if len(names) > 1 else ""
        ax.set_title(
            f"{scene.name}: {named}tentacle {k}, E = {t.youngs_modulus:g} Pa, "
            f"{flow_label(scene)} ({t.bending}, {t.root}{_drag_label(t.drag)})",
            fontsize=10,
        )
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right")
    axes[-1, 0].set_xlabel("time t [s]")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def tentacle_shapes(result: Result, path: Path, snapshots: int = 6) -> Path:
    """Side view (x-z) of every simulated tentacle at a few times over the run, each over its own
    particles, coloured by group (a legend names the groups when there are several)."""
    plt = _pyplot()
    frames = result.frames
    picks = np.unique(np.linspace(0, frames - 1, snapshots).round().astype(int))
    positions = result.read(fields.TENTACLE_POSITION, picks.tolist())
    margins = result.read(fields.BELL_MARGIN, picks.tolist())
    names = result.tentacle_groups
    group = result.tentacle_group
    particles = result.tentacle_particles
    time = result.time
    fig, axes = plt.subplots(
        1, len(picks), figsize=(2.2 * len(picks), 4.4), dpi=120, sharex=True, sharey=True
    )
    for ax, frame, chains, margin in zip(
        np.atleast_1d(axes), picks, positions, margins, strict=True
    ):
        centre = np.array([0.0, 0.0, margin[:, 2].mean()])  # in the bell's frame
        ring = np.vstack([margin, margin[:1]]) - centre
        ax.plot(ring[:, 0], ring[:, 2], color="0.5", lw=2)
        for k, chain in enumerate(chains):
            x = chain[: particles[k]] - centre
            # One group: a colour per tentacle, as before groups; several: one per group.
            colour = None if len(names) == 1 else group_colours(int(group[k]))[0]
            ax.plot(x[:, 0], x[:, 2], lw=1.2, color=colour)
            ax.plot(x[-1, 0], x[-1, 2], "o", color="tab:red", ms=2.5)
        ax.set_title(f"t = {time[frame]:.2f} s", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.grid(alpha=0.3)
    first = np.atleast_1d(axes)[0]
    first.set_ylabel("z - z(margin) [m]")
    if len(names) > 1:
        counts = np.bincount(group, minlength=len(names))
        _legend(
            first,
            [
                (group_colours(g)[0], f"{name} ({counts[g]})")
                for g, name in enumerate(names)
                if counts[g]
            ],
        )
    fig.suptitle(f"{result.scene.name}: tentacle shapes (side view, bell frame)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def _legend(ax: Axes, entries: list[tuple[str, str]]) -> None:
    """A legend of lines: (colour, label) each."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=colour, lw=1.5, label=label) for colour, label in entries]
    ax.legend(handles=handles, loc="lower left", fontsize=7)


def _meridians(vertices: np.ndarray, sectors: int) -> list[np.ndarray]:
    """The kinematic bell's cross-section in the x-z plane: the shell's outline at angles 0 and
    pi (outer apex, outer rings down to the margin, inner rings back up, inner apex)."""
    rings = (vertices.shape[0] - 2) // sectors
    outlines = []
    for sector in (0, sectors // 2):
        ring_points = vertices[1 + np.arange(rings) * sectors + sector]
        outlines.append(np.vstack([vertices[:1], ring_points, vertices[-1:]]))
    return outlines


def phase_frames(result: Result) -> tuple[int, int]:
    """Frames of the last whole pulse at the end of jetting (full contraction) and late in the
    relaxation (phase 0.95), for a kinematic bell."""
    bell = result.scene.bell
    time = result.time
    period = bell.period
    jet = bell.jet_fraction if bell.waveform == "jet" else 0.5
    last = np.floor((time[-1] - 0.95 * period) / period) * period
    if last < 0.0:
        raise ValueError("the run is shorter than one pulse")
    return (
        int(np.argmin(np.abs(time - (last + jet * period)))),
        int(np.argmin(np.abs(time - (last + 0.95 * period)))),
    )


def jetting_and_relaxation(result: Result, path: Path) -> Path:
    """Paper Fig. 9: the jellyfish at the end of its jetting phase and late in its relaxation,
    in the bell's frame, side view: each group's drawn (interpolated) tentacles, its simulated
    ones over them, in the group's colours (:func:`group_colours`; one group: simulated purple,
    drawn orange), each chain over its own particles."""
    from jellysim.interpolation import interpolate_groups

    plt = _pyplot()
    drawn = interpolate_groups(result)
    simulated = result.tentacle_positions
    particles = result.tentacle_particles
    sectors = result.dataset(fields.BELL_MARGIN).shape[1]  # R: vertices per ring
    time = result.time
    scene = result.scene
    fig, axes = plt.subplots(1, 2, figsize=(8.0, 5.2), dpi=120, sharex=True, sharey=True)
    names = ("jetting phase (full contraction)", "relaxation phase")
    for ax, frame, name in zip(axes, phase_frames(result), names, strict=True):
        origin = result.read(fields.BELL_CENTRE, frame)
        vertices = result.read(fields.BELL_SURFACE_VERTICES, frame).astype(np.float64)
        for g in drawn:
            own, between = group_colours(g.index)
            for chain in g.positions[frame] - origin:
                ax.plot(chain[:, 0], chain[:, 2], lw=0.5, color=between, alpha=0.45)
            for k in range(simulated.shape[1])[g.simulated]:
                chain = simulated[frame, k, : particles[k]] - origin
                ax.plot(chain[:, 0], chain[:, 2], lw=0.9, color=own, alpha=0.9)
        for outline in _meridians(vertices - origin, sectors):
            ax.fill(outline[:, 0], outline[:, 2], color="tab:brown", alpha=0.6, lw=0)
            ax.plot(outline[:, 0], outline[:, 2], color="tab:brown", lw=1.2)
        ax.set_title(f"{name}, t = {time[frame]:.2f} s", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("z - z(bell) [m]")
    if len(drawn) == 1:
        t = scene.tentacles
        g = drawn[0]
        title = (
            f"{scene.name}: E = {t.youngs_modulus:g} Pa, {flow_label(scene)}, "
            f"{simulated.shape[1]} simulated x {g.positions.shape[1] // max(1, simulated.shape[1])}"
            " drawn tentacles (cf. paper Fig. 9)"
        )
    else:
        title = (
            f"{scene.name}: {flow_label(scene)}; "
            + ", ".join(
                f"{g.name} {g.positions.shape[1]} drawn of "
                f"{len(range(simulated.shape[1])[g.simulated])}"
                for g in drawn
            )
            + " (cf. paper Fig. 9)"
        )
        _legend(
            axes[0],
            [(group_colours(g.index)[0], f"{g.name} (simulated)") for g in drawn]
            + [(group_colours(g.index)[1], f"{g.name} (drawn)") for g in drawn],
        )
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def surge_front_plot(result: Result, path: Path) -> Path:
    """The dam break's surge front x_front / a against T = t sqrt(2 g / a), with Martin & Moyce
    (1952, n^2 = 2) and the RMS errors, raw and after the best time shift."""
    from jellysim.reference import front_errors, martin_moyce, surge_front

    plt = _pyplot()
    a = float(result.file.attrs["column_width"])
    g = float(np.linalg.norm(result.scene.water.gravity))
    positions = result.fluid_positions
    alive = (
        result.fluid_alive
        if result.has(fields.FLUID_ALIVE)
        else np.ones(positions.shape[:2], dtype=bool)
    )
    fluid = (
        result.fluid_kind == 0
        if result.has(fields.FLUID_KIND)
        else np.ones(alive.shape[1], dtype=bool)
    )
    front = surge_front(positions, alive, fluid, a)
    t = result.time * np.sqrt(2.0 * g / a)
    raw, shifted, shift = front_errors(t, front)
    t_ref, z_ref = martin_moyce()
    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=120)
    ax.plot(t, front, color="tab:blue", lw=1.6, label="jellysim (MPS)")
    ax.plot(t + shift, front, color="tab:blue", lw=1.0, ls="--", label=f"shifted by {shift:+.2f}")
    ax.plot(t_ref, z_ref, "o", color="k", ms=4, label="Martin & Moyce (1952), n² = 2")
    ax.set_xlabel("T = t √(2g/a)")
    ax.set_ylabel("Z = x_front / a")
    ax.set_xlim(0, max(3.5, float(t[-1])))
    ax.set_title(
        f"{result.scene.name}: surge front; RMS error {100 * raw:.1f} % "
        f"({100 * shifted:.1f} % shifted), T <= 3",
        fontsize=10,
    )
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


class HydrostaticProfile(NamedTuple):
    """Still water's pressure against height, averaged over the second half of a result's frames
    (:func:`hydrostatic_profile`): per live fluid particle its mean height (m) and mean
    pressure (Pa); the least-squares line's slope over rho g and head (m, where it reaches
    p = 0); the averaging window (s) and its frame count."""

    height: np.ndarray
    pressure: np.ndarray
    slope: float
    head: float
    window: tuple[float, float]
    frames: int


def _weight_density(result: Result) -> float:
    """rho g of the result's water (N/m3)."""
    water = result.scene.water
    return water.density * float(np.linalg.norm(water.gravity))


def hydrostatic_profile(result: Result) -> HydrostaticProfile:
    """Average still water's pressure over the second half of the frames (at least the last one)
    and fit it by a line. A single frame is not enough: the MPS pressure of the 2-D presets
    alternates from step to step by about 4 % of the head (docs/fluid.md, "Still water"), so
    frames taken an odd number of steps apart alternate too; the average over the settled half
    of the run is the profile the validation test holds to rho g (H - y)."""
    rho_g = _weight_density(result)
    count = len(result.time)
    first = min(count // 2, count - 1)
    settled = slice(first, None)
    fluid = result.fluid_kind == 0
    alive = np.all(result.read(fields.FLUID_ALIVE, settled), axis=0) & fluid
    height = result.read(fields.FLUID_POSITION, settled)[:, alive, -1].mean(axis=0)
    pressure = result.read(fields.FLUID_PRESSURE, settled)[:, alive].mean(axis=0)
    slope, intercept = np.polyfit(height, pressure, 1)
    window = (float(result.time[first]), float(result.time[-1]))
    return HydrostaticProfile(
        height, pressure, -slope / rho_g, intercept / -slope, window, count - first
    )


def hydrostatic_plot(result: Result, path: Path) -> Path:
    """Still water: the pressure of every fluid particle against its height, averaged over the
    second half of the run (:func:`hydrostatic_profile`), with the hydrostatic law
    rho g (H - y) and the least-squares line."""
    plt = _pyplot()
    depth = float(result.file.attrs["water_depth"])
    scene = result.scene
    rho_g = _weight_density(result)
    profile = hydrostatic_profile(result)
    fig, ax = plt.subplots(figsize=(5.6, 4.4), dpi=120)
    ax.plot(profile.pressure, profile.height, ".", ms=3, color="tab:blue", label="fluid particles")
    y = np.linspace(0.0, depth, 50)
    up = "z" if result.dataset(fields.FLUID_POSITION).shape[-1] == 3 else "y"
    ax.plot(rho_g * (depth - y), y, color="k", lw=1.4, label=f"ρ g (H − {up}), H = {depth:.4f} m")
    ax.plot(
        profile.slope * rho_g * (profile.head - y),
        y,
        color="tab:red",
        lw=1.0,
        ls="--",
        label=f"fit: slope {profile.slope:.3f} ρg, head {profile.head:.4f} m",
    )
    ax.set_xlabel("pressure [Pa]")
    ax.set_ylabel("height [m]")
    start, end = profile.window
    ax.set_title(
        f"{scene.name}: mean pressure over t = {start:.2f}–{end:.2f} s ({profile.frames} frames)",
        fontsize=10,
    )
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def thrust_plot(result: Result, path: Path) -> Path:
    """Paper Fig. 11: the mean height of the bell particles and the contraction ratio of the
    bell's radius against time, each pulse's lag from peak contraction to peak upward speed
    marked."""
    from jellysim.bell.swimming import phase_lag, swim_cycles

    plt = _pyplot()
    time = result.time
    height = result.bell_centre[:, 2]
    contraction = result.bell_contraction
    period = result.scene.bell.period
    fig, ax = plt.subplots(figsize=(7.2, 4.2), dpi=120)
    ax.plot(time, height - height[0], color="tab:red", lw=1.6, label="mean height of the bell")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("z - z(0) of the bell particles [m]", color="tab:red")
    other = ax.twinx()
    other.plot(time, contraction, color="tab:blue", lw=1.2, ls="--", label="contraction ratio")
    other.set_ylabel("contraction ratio of the radius", color="tab:blue")
    cycles = swim_cycles(time, height, contraction, period)
    lag = phase_lag(time, height, contraction, period)
    if lag is not None:
        # Shade from each pulse's peak contraction to the upward-speed peak that follows it.
        for cycle in cycles[1:]:  # the lag is measured after the first pulse
            start = cycle.peak_contraction_time
            ax.axvspan(start, min(start + lag.lag, time[-1]), color="0.85", lw=0)
    if cycles:
        mean_rise = float(np.mean([c.rise for c in cycles]))
        title = f"rise {mean_rise:.3g} m per pulse"
        if lag is not None:
            title += f"; upward speed peaks {lag.lag:.2f} s after the contraction (shaded)"
    else:
        title = "shorter than one pulse"
    ax.set_title(f"{result.scene.name} (cf. paper Fig. 11)\n{title}", fontsize=9)
    ax.grid(alpha=0.3)
    lines = ax.get_lines() + other.get_lines()
    ax.legend(lines, [line.get_label() for line in lines], loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


# The probes that published comparisons of SPHERIC Test 2 draw (Issa & Violeau 2006, Figs. 4-5).
SPHERIC_TEST2_PANELS = ("H2", "H4", "P1", "P3", "P5", "P7")


def probes_plot(result: Result, path: Path) -> Path:
    """The probes against time: with ``probes.reference = "spheric-test2"`` H2, H4, P1, P3, P5
    and P7 (those the result has) against Kleefsman et al. (2005)'s measurements, otherwise
    every probe, heights then pressures."""
    plt = _pyplot()
    t = result.time
    series = result.probes()
    measured = None
    if result.scene.probes.reference == "spheric-test2":
        from jellysim.reference import spheric_test2

        measured = spheric_test2()
        panels = [name for name in SPHERIC_TEST2_PANELS if name in series] or list(series)
    else:
        panels = list(series)
    panels = panels[:12]
    columns = 2 if len(panels) > 1 else 1
    rows = -(-len(panels) // columns)
    fig, axes = plt.subplots(
        rows, columns, figsize=(6.0 * columns, 2.6 * rows), dpi=110, squeeze=False
    )
    for ax, name in zip(axes.ravel(), panels, strict=False):
        values, unit = series[name]
        scale, label = (1e-3, "kPa") if unit == "Pa" else (1.0, "m")
        if measured is not None and name in measured:
            ax.plot(measured["t"], measured[name] * scale, color="0.55", lw=0.9,
                    label="experiment (Kleefsman et al. 2005)")  # fmt: skip
        ax.plot(t, values * scale, color="tab:blue", lw=1.3, label="jellysim (MPS)")
        ax.set_title(name, fontsize=10, loc="left")
        ax.set_ylabel(label)
        ax.set_xlim(0, float(t[-1]) if len(t) > 1 else 1.0)
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(panels) :]:
        ax.set_visible(False)
    for ax in axes.ravel()[max(0, len(panels) - columns) : len(panels)]:
        ax.set_xlabel("t (s)")  # the lowest panel of each column
    axes[0, 0].legend(loc="best", fontsize=8)
    l0 = float(result.file.attrs.get("particle_spacing", 0.0))
    fig.suptitle(f"{result.scene.name}: probes (l0 = {l0:g} m)", fontsize=11)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_result(result: Result, folder: Path | None = None) -> list[Path]:
    """Write every figure that applies to ``result`` into ``folder`` (default DIR/plots)."""
    folder = folder or result.folder / "plots"
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    if result.has(fields.TENTACLE_POSITION):
        paths += [
            root_tip_trace(result, folder / "root_tip_trace.png"),
            tentacle_shapes(result, folder / "tentacle_shapes.png"),
        ]
    if result.has(fields.BELL_ACTIVATION):
        paths.append(thrust_plot(result, folder / "thrust.png"))
    if (
        result.has(fields.BELL_SURFACE_VERTICES)
        and result.has(fields.TENTACLE_POSITION)
        and result.time[-1] >= result.scene.bell.period
    ):
        paths.append(jetting_and_relaxation(result, folder / "jetting_and_relaxation.png"))
    if (
        result.has(fields.FLUID_POSITION)
        and "column_width" in result.file.attrs
        # Martin & Moyce's column: against the left wall, the floor free
        and result.scene.fluid.water_side == "left"
        and not result.scene.fluid.obstacles
    ):
        paths.append(surge_front_plot(result, folder / "surge_front.png"))
    if result.has(fields.PROBE_HEIGHT) or result.has(fields.PROBE_PRESSURE):
        paths.append(probes_plot(result, folder / "probes.png"))
    if (
        result.has(fields.FLUID_POSITION)
        and "water_depth" in result.file.attrs
        and np.any(result.scene.water.gravity)  # weightless water has no hydrostatic law
    ):
        paths.append(hydrostatic_plot(result, folder / "hydrostatic_pressure.png"))
    return paths
