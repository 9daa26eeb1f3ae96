"""The traces of a sweep: a tentacle's root and tip x against time, one per point, as the
paper's Figs. 5, 7 and 8 draw them (root red, tip blue, one panel per point, labelled)."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from jellysim.config import Scene
from jellysim.errors import InputError


@dataclass(frozen=True)
class Trace:
    """x (m) of a tentacle's root and tip, (F,) each, at the frame times (s), (F,), of one run;
    ``point`` maps each swept key to its value in that run, and ``value`` is that value (one
    key) or the tuple of them in the keys' order (several)."""

    value: Any
    time: np.ndarray
    root_x: np.ndarray
    tip_x: np.ndarray
    point: dict[str, Any] = field(default_factory=dict)

    @property
    def label(self) -> str:
        """``key = value, ...``: the point, for a figure's panel."""
        return ", ".join(f"{key} = {format_value(value)}" for key, value in self.point.items())

    def late(self, fraction: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
        """Root and tip x over the last ``fraction`` of the run (after the start-up transient)."""
        start = int(len(self.time) * (1.0 - fraction))
        return self.root_x[start:], self.tip_x[start:]

    def tip_to_root_range(self, fraction: float = 0.5) -> float:
        """Peak-to-peak tip x over peak-to-peak root x, late in the run."""
        root, tip = self.late(fraction)
        return float(np.ptp(tip) / np.ptp(root))


def own_particles(scene: Scene, tentacle: int) -> int:
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


def plot_sweep(traces: Sequence[Trace], path: Path, title: str = "") -> Path:
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
            trace.label,
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


def write_traces_csv(traces: Sequence[Trace], path: Path) -> Path:
    """One row per point and frame. Columns: each swept key (its value), time (s), root x (m),
    tip x (m)."""
    keys = list(traces[0].point) if traces else []
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow([*keys, "time_s", "root_x_m", "tip_x_m"])
        for trace in traces:
            values = [trace.point[key] for key in keys]
            for row in zip(trace.time, trace.root_x, trace.tip_x, strict=True):
                writer.writerow([*values, *(f"{v:.9g}" for v in row)])
    return path


def format_value(value: Any) -> str:
    """A swept value as a label shows it: numbers in ``g`` format, booleans in TOML's spelling."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, int | float):
        return f"{value:g}"
    return str(value)
