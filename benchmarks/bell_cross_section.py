"""The soft bell's particles at rest in a cross-section, one preset above another (the figure in
docs/soft-bell.md, "moon-jelly-fine"): the lattice cells of the plane half a spacing off the axis
that Eq. B7's shell takes, as the coupling carves them, over the shell's two half-ellipses.

    python benchmarks/bell_cross_section.py [PRESET ...] [--out FILE]

Default: moon-jelly and moon-jelly-fine, into docs/images/moon-jelly-fine-cross-section.png.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PatchCollection  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

import jellysim  # noqa: E402
from jellysim.bell.soft import BellShape  # noqa: E402
from jellysim.fluid.geometry import FLUID  # noqa: E402
from jellysim.fluid.setup import fluid_particles  # noqa: E402

FIGURE = Path(__file__).resolve().parents[1] / "docs/images/moon-jelly-fine-cross-section.png"


def draw(ax: plt.Axes, name: str) -> None:
    """The bell of preset ``name`` in the plane y = l0 / 2 from its axis, on ``ax``."""
    scene = jellysim.load_scene(name)
    l0 = scene.fluid.spacing
    positions, kinds, _ = fluid_particles(scene)
    shape = BellShape(scene)
    bell = positions[(kinds == FLUID) & shape.shell(positions)] - shape.centre
    plane = bell[np.abs(bell[:, 1] - 0.5 * l0) < 1e-6 * l0]  # the axis runs along cell faces
    cells = [Rectangle((x - l0 / 2, z - l0 / 2), l0, l0) for x, z in plane[:, [0, 2]]]
    ax.add_collection(PatchCollection(cells, facecolor="#9ec3e6", edgecolor="#2b5d8a", lw=0.4))
    angle = np.linspace(0.0, np.pi, 400)
    r, h, w = shape.radius, shape.height, shape.wall
    ax.plot(r * np.cos(angle), h * np.sin(angle), "k-", lw=0.8)
    ax.plot((r - w) * np.cos(angle), (h - w) * np.sin(angle), "k--", lw=0.8)
    ax.set_title(
        f"{name}: l0 = {l0:.4g} m, wall {w / l0:.0f} l0, {len(bell):,} bell particles",
        fontsize=9,
    )
    ax.set_aspect("equal")
    ax.set_ylabel("above the margin plane [m]")
    ax.set_ylim(-0.15, h + 0.15)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("presets", nargs="*", default=["moon-jelly", "moon-jelly-fine"])
    parser.add_argument("--out", type=Path, default=FIGURE)
    args = parser.parse_args()
    fig, axes = plt.subplots(len(args.presets), 1, figsize=(9, 3.1 * len(args.presets)))
    for ax, name in zip(np.atleast_1d(axes), args.presets, strict=True):
        draw(ax, name)
    ax.set_xlabel("x from the bell's axis [m]")
    fig.text(
        0.01, 0.005, "solid: outer half-ellipse (R, H); dashed: inner (R - w, H - w), Eq. B7",
        fontsize=8,
    )  # fmt: skip
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(args.out)


if __name__ == "__main__":
    main()
