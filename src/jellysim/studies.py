"""Parameter sweeps: the paper's Figs. 5, 7 and 8 (root and tip x against time as one key varies).

``jellysim sweep SCENE --key tentacles.youngs_modulus --values 100,2.4e5,9e9`` runs the scene once
per value (in memory, nothing but the figure and a CSV written) and draws the root's and the
tips' x against time, one curve per value, labelled.
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from jellysim import fields
from jellysim.config import Scene, load_scene
from jellysim.config.load import parse_override
from jellysim.errors import InputError
from jellysim.simulation import Simulation, make_loop


@dataclass(frozen=True)
class Trace:
    """x (m) of a tentacle's root and tip at the frame times (s) of one run."""

    value: Any
    time: np.ndarray
    root_x: np.ndarray
    tip_x: np.ndarray

    def late(self, fraction: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
        """Root and tip x over the last ``fraction`` of the run (after the start-up transient)."""
        start = int(len(self.time) * (1.0 - fraction))
        return self.root_x[start:], self.tip_x[start:]

    def tip_to_root_range(self, fraction: float = 0.5) -> float:
        """Peak-to-peak tip x over peak-to-peak root x, late in the run."""
        root, tip = self.late(fraction)
        return float(np.ptp(tip) / np.ptp(root))


def sweep(
    scene: str | Path | Mapping[str, Any],
    key: str,
    values: Sequence[Any],
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    tentacle: int = 0,
) -> list[Trace]:
    """Run ``scene`` once per value of ``key``; the traces of ``tentacle``'s root and tip.

    ``tentacle`` numbers the simulated tentacles across every group, in the scene's order (the
    result's T axis: ``tentacles/group`` tells its group); its tip is its own last particle."""
    base: dict[str, Any] = (
        dict(overrides)
        if isinstance(overrides, Mapping)
        else dict(parse_override(item) for item in overrides or [])
    )
    traces = []
    for value in values:
        loaded = load_scene(scene, {**base, key: value})
        if loaded.tentacle_count == 0:
            raise InputError(
                f"{loaded.name} has no tentacles (tentacles.count = 0): a sweep traces a "
                "tentacle's root and tip; set tentacles.count"
            )
        particles = _own_particles(loaded, tentacle)
        loop = make_loop(loaded)
        xs = [_root_and_tip_x(loop, tentacle, particles)]
        for _ in range(loaded.frame_count - 1):
            loop.step_frame()
            xs.append(_root_and_tip_x(loop, tentacle, particles))
        x = np.array(xs)
        time = np.arange(loaded.frame_count) / loaded.fps
        traces.append(Trace(value, time, x[:, 0], x[:, 1]))
    return traces


def _own_particles(scene: Scene, tentacle: int) -> int:
    """The particles of simulated tentacle ``tentacle``, numbered across the scene's groups in
    order (as the result's T axis); raises :class:`InputError` listing the range (and each
    group's part of it) for one the scene does not have."""
    first = 0
    ranges = []
    for group in scene.groups:
        count = group.tentacles.count
        if first <= tentacle < first + count:
            return group.tentacles.particles
        if count:
            ranges.append(f"{first}..{first + count - 1} {group.name}")
        first += count
    groups = f" ({', '.join(ranges)})" if len(scene.groups) > 1 else ""
    raise InputError(
        f"--tentacle {tentacle}: the scene has tentacles 0..{scene.tentacle_count - 1}{groups}"
    )


def _root_and_tip_x(loop: Simulation, tentacle: int, particles: int) -> np.ndarray:
    """x (m) of ``tentacle``'s root and tip (its own last particle, ``particles`` - 1: the rows
    beyond are NaN padding) in the loop's current frame, (2,)."""
    positions = loop.frame_values()[fields.TENTACLE_POSITION.path]
    return np.array(positions[tentacle, [0, particles - 1], 0])


def plot_sweep(traces: Sequence[Trace], key: str, path: Path, title: str = "") -> Path:
    """Paper Figs. 7-8 style: the root (red) and each tip against time, labelled by value."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = len(traces)
    fig, axes = plt.subplots(rows, 1, figsize=(8, 1.7 * rows + 0.8), dpi=120, sharex=True)
    for ax, trace in zip(np.atleast_1d(axes), traces, strict=True):
        ax.plot(trace.time, trace.root_x, color="tab:red", lw=1.4, label="root")
        ax.plot(trace.time, trace.tip_x, color="tab:blue", lw=1.1, label="tip")
        ax.set_ylabel("x [m]")
        ax.text(
            0.01,
            0.88,
            f"{key} = {trace.value:g}",
            transform=ax.transAxes,
            fontsize=9,
            va="top",
            bbox={"facecolor": "white", "alpha": 0.8, "lw": 0},
        )
        ax.text(
            0.99,
            0.88,
            f"tip/root range {trace.tip_to_root_range():.2f}",
            transform=ax.transAxes,
            fontsize=8,
            ha="right",
            va="top",
        )
        ax.grid(alpha=0.3)
    first = np.atleast_1d(axes)[0]
    first.legend(loc="lower right", fontsize=8)
    np.atleast_1d(axes)[-1].set_xlabel("time t [s]")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def write_traces_csv(traces: Sequence[Trace], key: str, path: Path) -> Path:
    """Columns: key value, time (s), root x (m), tip x (m)."""
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow([key, "time_s", "root_x_m", "tip_x_m"])
        for trace in traces:
            for row in zip(trace.time, trace.root_x, trace.tip_x, strict=True):
                writer.writerow([trace.value, *(f"{v:.9g}" for v in row)])
    return path
