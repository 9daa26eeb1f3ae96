"""Fluid-only scenes end to end: ``jellysim run dam-break-2d`` (coarse) against Martin & Moyce,
result.h5's fluid datasets (DESIGN §3), plot and export, resume, divergence and bad input."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import jellysim
from jellysim import fields
from jellysim.fluid.geometry import FLUID
from jellysim.reference import front_errors, surge_front

COARSE = {"fluid.spacing": 0.005}  # 20 particles across the column a = 0.1 m


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "jellysim", *args], capture_output=True, text=True, check=False
    )


@pytest.fixture(scope="module")
def dam(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("dam")
    # The preset's scheme (hexagonal lattice, mixed source, corrected gradient) at 20 particles
    # across: 0.123 raw, 0.034 shifted (2026-11-24). The standard scheme on the square lattice
    # gave 0.149 here, at the bound (its path is chaotic at this resolution).
    done = _cli(
        "run", "dam-break-2d", "--out", str(out), "--quiet", "--set", "fluid.spacing=0.005"
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return out


def test_fluid_datasets_and_attributes(dam: Path) -> None:
    with jellysim.open_result(dam) as r:
        f = r.file
        frames = r.frames
        assert frames == r.expected_frames == round(0.25 * 200) + 1
        n = f[fields.FLUID_KIND.path].shape[0]
        fluid = int(np.sum(f[fields.FLUID_KIND.path][:] == FLUID))
        assert fluid == 20 * 46 == f.attrs["fluid_particles"]  # 46 rows of sqrt(3)/2 l0
        for name, shape, units in [
            (fields.FLUID_POSITION.path, (frames, n, 2), "m"),
            (fields.FLUID_VELOCITY.path, (frames, n, 2), "m/s"),
            (fields.FLUID_PRESSURE.path, (frames, n), "Pa"),
            (fields.FLUID_NUMBER_DENSITY.path, (frames, n), "1"),
            (fields.FLUID_ALIVE.path, (frames, n), "1"),
            (fields.SOLVER_ITERATIONS.path, (frames,), "1"),
        ]:
            assert f[name].shape == shape, name
            assert f[name].attrs["units"] == units, name
        assert f.attrs["column_width"] == 0.1
        assert f.attrs["column_height"] == pytest.approx(46 * 0.005 * np.sqrt(3) / 2)
        assert f.attrs["particle_spacing"] == 0.005
        # The DESIGN §3 geometry: left inner wall at x = 0, floor at y = 0.
        start = f[fields.FLUID_POSITION.path][0][f[fields.FLUID_KIND.path][:] == FLUID]
        assert start[:, 0].min() > 0.0 and start[:, 1].min() > 0.0
        assert start[:, 0].max() < 0.1 and start[:, 1].max() < 0.2
        assert np.all(f[fields.SOLVER_ITERATIONS.path][1:] > 0)
        assert np.all(np.isfinite(f[fields.FLUID_POSITION.path][:]))


def test_dam_break_front_follows_martin_and_moyce(dam: Path) -> None:
    # Issue 5: RMS relative error <= 15 % as computed and <= 5 % after one best-fit time shift
    # of at most 0.3 in T, for T <= 3 (Martin & Moyce 1952, n^2 = 2). Coarse: 20 across a.
    with jellysim.open_result(dam) as r:
        f = r.file
        a = f.attrs["column_width"]
        front = surge_front(
            f[fields.FLUID_POSITION.path][:],
            f[fields.FLUID_ALIVE.path][:],
            f[fields.FLUID_KIND.path][:] == FLUID,
            a,
        )
        raw, shifted, shift = front_errors(r.time * np.sqrt(2 * 9.81 / a), front)
    print(f"dam break 20/a: raw {raw:.3f}, shifted {shifted:.3f} by {shift:+.2f}")
    assert raw <= 0.15
    assert shifted <= 0.05 and 0.0 <= shift <= 0.3  # the simulation leads the experiment


def test_plot_and_export_of_a_fluid_result(dam: Path) -> None:
    done = _cli("plot", str(dam))
    assert done.returncode == 0 and (dam / "plots" / "surge_front.png").is_file()
    done = _cli("export", str(dam), "--format", "vtk", "--every", "25")
    assert done.returncode == 0, done.stderr
    assert (dam / "export" / "vtk" / "fluid.pvd").is_file()
    assert len(list((dam / "export" / "vtk").glob("fluid_*.vtu"))) == 3


def test_a_resumed_fluid_run_is_bitwise_identical(tmp_path: Path) -> None:
    overrides = {**COARSE, "duration": 0.06, "solver.checkpoint_every": 4}
    whole = jellysim.run("dam-break-2d", tmp_path / "whole", overrides=overrides)

    def crash(simulation: object) -> None:
        if simulation.frame == 7:  # type: ignore[attr-defined]
            raise KeyboardInterrupt  # a run stopped between checkpoints (frame 4 is the last)

    with pytest.raises(KeyboardInterrupt):
        jellysim.run("dam-break-2d", tmp_path / "cut", overrides=overrides, observers=[crash])
    resumed = jellysim.run("dam-break-2d", tmp_path / "cut", overrides=overrides, resume=True)
    with whole, resumed:
        assert resumed.frames == whole.frames
        for field in (
            fields.TIME,
            fields.FLUID_POSITION,
            fields.FLUID_VELOCITY,
            fields.FLUID_PRESSURE,
            fields.FLUID_ALIVE,
        ):
            np.testing.assert_array_equal(resumed.read(field), whole.read(field), field.path)


def test_a_diverging_pressure_solve_exits_3_with_a_diagnosis(tmp_path: Path) -> None:
    done = _cli(
        "run", "dam-break-2d", "--out", str(tmp_path), "--quiet",
        "--set", "fluid.spacing=0.01", "--set", "fluid.tolerance=1e-300",
    )  # fmt: skip
    assert done.returncode == 3
    assert "iterations" in done.stderr and "residual" in done.stderr and "t = " in done.stderr
    with jellysim.open_result(tmp_path) as r:  # the frames before stay readable
        assert r.frames >= 1


@pytest.mark.parametrize(
    ("sets", "fragment"),
    [
        (("tentacles.count=6",), "tentacles.count"),
        (("water.gravity=[0, 0, -9.81]",), "water.gravity"),
        (("fluid.spacing=0.003",), "spacing"),
    ],
    ids=["tentacles", "gravity-2d", "off-lattice"],
)
def test_bad_fluid_scenes_exit_2(tmp_path: Path, sets: tuple[str, ...], fragment: str) -> None:
    args = [a for s in sets for a in ("--set", s)]
    done = _cli("run", "dam-break-2d", "--out", str(tmp_path / "x"), "--quiet", *args)
    assert done.returncode == 2, done.stderr
    assert fragment in done.stderr and len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()


def test_scheme_keys_reach_the_solver() -> None:
    """fluid.source, fluid.gradient, fluid.surface and fluid.lattice of a scene are the
    solver's: hydrostatic-2d and dam-break-2d choose the mixed source with the corrected
    gradient and the either-density surface on the hexagonal lattice (and its surface
    threshold, 0.93) with collisions at 0.8 l0 and the surface repulsion; the paper's standard
    scheme on the square lattice is six keys away (and 0.97, 0.5 l0, no repulsion)."""
    from jellysim.fluid.setup import mps_parameters

    still = mps_parameters(jellysim.load_scene("hydrostatic-2d"))
    assert (still.source, still.gradient, still.lattice) == ("mixed", "corrected", "hexagonal")
    assert still.surface == "either-density"
    assert still.beta == 0.93  # the hexagonal lattice's default
    dam = mps_parameters(jellysim.load_scene("dam-break-2d"))
    assert (dam.source, dam.gradient, dam.lattice) == ("mixed", "corrected", "hexagonal")
    assert dam.surface == "either-density"
    assert still.collision_distance == dam.collision_distance == 0.8
    assert still.surface_repulsion and dam.surface_repulsion
    paper = mps_parameters(
        jellysim.load_scene(
            "dam-break-2d",
            {
                "fluid.lattice": "square", "fluid.source": "standard",
                "fluid.gradient": "standard", "fluid.surface": "standard",
                "fluid.collision_distance": 0.5, "fluid.surface_repulsion": False,
            },
        )
    )  # fmt: skip
    assert (paper.source, paper.gradient, paper.lattice) == ("standard", "standard", "square")
    assert paper.surface == "standard"
    assert paper.beta == 0.97
    assert paper.collision_distance == 0.5
    assert not paper.surface_repulsion
    set_beta = jellysim.load_scene("hydrostatic-2d", {"fluid.surface_threshold": 0.95})
    assert mps_parameters(set_beta).beta == 0.95
    chosen = mps_parameters(
        jellysim.load_scene(
            "dam-break-2d", {"fluid.source": "mixed", "fluid.gradient": "corrected"}
        )
    )
    assert (chosen.source, chosen.gradient) == ("mixed", "corrected")
    assert dam.matrix_precision == "double"  # fluid.matrix_precision's default
    single = jellysim.load_scene("dam-break-2d", {"fluid.matrix_precision": "single"})
    assert mps_parameters(single).matrix_precision == "single"


def test_hydrostatic_preset_plots_the_hydrostatic_law(tmp_path: Path) -> None:
    """``jellysim run hydrostatic-2d`` then ``jellysim plot``: the pressure averaged over the
    second half of the run (the plot's profile; single frames alternate by about 4 % of the
    head, docs/fluid.md) follows rho g (H - y). Measured 2026-11-25: slope 0.999 rho g, head
    0.0970 m against the filled height 0.0996 m (the top row's centre is 0.0974 m)."""
    from jellysim.io.plots import hydrostatic_profile

    out = tmp_path / "still"
    done = _cli("run", "hydrostatic-2d", "--out", str(out), "--quiet")
    assert done.returncode == 0, done.stderr
    with jellysim.open_result(out) as result:
        profile = hydrostatic_profile(result)
        depth = result.file.attrs["water_depth"]
    assert profile.window == (0.5, 1.0) and profile.frames == 11
    assert profile.slope == pytest.approx(1.0, rel=0.03)
    assert profile.head == pytest.approx(depth, rel=0.04)
    done = _cli("plot", str(out))
    assert done.returncode == 0, done.stderr
    png = out / "plots" / "hydrostatic_pressure.png"
    assert png.stat().st_size > 10_000


def test_hydrostatic_3d_preset_runs_and_plots(tmp_path: Path) -> None:
    """``jellysim run hydrostatic-3d`` (shortened to 0.3 s) then ``jellysim plot``: 2,800
    particles on the face-centred cubic lattice in 12 layers; the pressure averaged over the
    second half follows rho g (H - z) within a few percent, its head at the top layer's centre
    (the 1-s figures are in tests/validation/test_mps_fluid.py)."""
    from jellysim.io.plots import hydrostatic_profile

    out = tmp_path / "still3d"
    done = _cli("run", "hydrostatic-3d", "--out", str(out), "--quiet", "--set", "duration=0.3")
    assert done.returncode == 0, done.stderr
    with jellysim.open_result(out) as result:
        profile = hydrostatic_profile(result)
        depth = float(result.file.attrs["water_depth"])
        assert int(result.file.attrs["fluid_particles"]) == 2800
        assert result.file[fields.FLUID_POSITION.path].shape[1:] == (
            len(result.file[fields.FLUID_KIND.path]),
            3,
        )
        assert np.all(result.file[fields.FLUID_ALIVE.path][-1])
    assert depth == pytest.approx(12 * (2.0 / 3.0) ** 0.5 * 0.005)
    assert profile.slope == pytest.approx(1.0, rel=0.03)
    assert profile.head == pytest.approx(depth - 0.5 * (2.0 / 3.0) ** 0.5 * 0.005, rel=0.02)
    done = _cli("plot", str(out))
    assert done.returncode == 0, done.stderr
    assert (out / "plots" / "hydrostatic_pressure.png").stat().st_size > 10_000
