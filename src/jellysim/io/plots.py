"""The paper's figures for a result (matplotlib, Agg backend, PNG files)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jellysim.io.result import Result


def _pyplot():  # type: ignore[no-untyped-def]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def root_tip_trace(result: Result, path: Path, tentacle: int = 0) -> Path:
    """Paper Figs. 7-8: x of a tentacle's root and of its tip against time."""
    plt = _pyplot()
    time = result.time
    x = result.file["tentacles/position"][:, tentacle, :, 0]
    scene = result.scene
    fig, ax = plt.subplots(figsize=(8, 3.6), dpi=120)
    ax.plot(time, x[:, 0], color="tab:red", lw=1.6, label="root")
    ax.plot(time, x[:, -1], color="tab:blue", lw=1.2, label="tip")
    ax.set_xlabel("time t [s]")
    ax.set_ylabel("x [m]")
    t = scene.tentacles
    ax.set_title(
        f"{scene.name}: tentacle {tentacle}, E = {t.youngs_modulus:g} Pa, "
        f"v = {scene.flow.speed:g} m/s ({t.bending}, {t.root})",
        fontsize=10,
    )
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def tentacle_shapes(result: Result, path: Path, snapshots: int = 6) -> Path:
    """Side view (x-z) of every simulated tentacle at a few times over the run."""
    plt = _pyplot()
    frames = result.frames
    picks = np.unique(np.linspace(0, frames - 1, snapshots).round().astype(int))
    positions = result.file["tentacles/position"]
    margin = result.file["bell/margin"]
    time = result.time
    fig, axes = plt.subplots(
        1, len(picks), figsize=(2.2 * len(picks), 4.4), dpi=120, sharex=True, sharey=True
    )
    for ax, frame in zip(np.atleast_1d(axes), picks, strict=True):
        x = positions[frame]
        ring = np.vstack([margin[frame], margin[frame][:1]])
        ax.plot(ring[:, 0], ring[:, 2], color="0.5", lw=2)
        for chain in x:
            ax.plot(chain[:, 0], chain[:, 2], lw=1.2)
            ax.plot(chain[-1, 0], chain[-1, 2], "o", color="tab:red", ms=2.5)
        ax.set_title(f"t = {time[frame]:.2f} s", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("z [m]")
    fig.suptitle(f"{result.scene.name}: tentacle shapes (side view)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_result(result: Result, folder: Path | None = None) -> list[Path]:
    """Write every figure that applies to ``result`` into ``folder`` (default DIR/plots)."""
    folder = folder or result.folder / "plots"
    folder.mkdir(parents=True, exist_ok=True)
    return [
        root_tip_trace(result, folder / "root_tip_trace.png"),
        tentacle_shapes(result, folder / "tentacle_shapes.png"),
    ]
