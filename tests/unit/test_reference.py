"""Reference data (Martin & Moyce 1952) and the surge-front measures of the dam break."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

import jellysim
from jellysim import fields
from jellysim.io.plots import plot_result
from jellysim.reference import front_errors, martin_moyce, surge_front

REPO = Path(__file__).resolve().parents[2]


def test_martin_moyce_is_the_shared_table():
    t, z = martin_moyce()
    shared = np.loadtxt(
        REPO / "tests" / "data" / "martin_moyce_1952_n2_a225.csv",
        delimiter=",",
        comments="#",
        skiprows=4,
    )
    np.testing.assert_array_equal(np.stack([t, z], axis=1), shared)
    assert t.size == 15 and np.all(np.diff(t) > 0) and np.all(np.diff(z) > 0)


def test_surge_front_is_the_furthest_live_fluid_particle_near_the_floor():
    a = 0.1
    positions = np.array(
        [
            [[0.05, 0.0], [0.20, 0.005], [0.35, 0.02], [0.50, 0.0], [0.60, 0.0]],
        ]
    )
    alive = np.array([[True, True, True, True, False]])  # the last one has left the domain
    fluid = np.array([True, True, True, False, True])  # the fourth is a wall particle
    # 0.35 m is 0.02 m up: above 0.1 a = 0.01 m; so the front is the particle at 0.20 m.
    np.testing.assert_allclose(surge_front(positions, alive, fluid, a), [2.0])


def test_front_errors_are_zero_on_the_experiment_and_find_a_shift():
    t, z = martin_moyce()
    assert front_errors(t, z) == (0.0, 0.0, 0.0)
    raw, shifted, shift = front_errors(t - 0.2, z)  # a simulation that leads by 0.2
    assert raw > 0.05 and shifted < 1e-3 and shift == pytest.approx(0.2, abs=1e-3)
    raw, shifted, shift = front_errors(t - 0.5, z)  # beyond the largest shift allowed
    assert shift == pytest.approx(0.3) and shifted > 0.01


def test_the_surge_front_figure_of_a_fluid_result(tmp_path: Path):
    # A hand-made result whose front follows the experiment exactly: the figure reports 0 %.
    a, g = 0.1, 9.81
    t_ref, z_ref = martin_moyce()
    times = np.linspace(0.0, 3.3, 34) / np.sqrt(2 * g / a)
    front = np.interp(times * np.sqrt(2 * g / a), t_ref, z_ref, left=1.0)
    positions = np.zeros((times.size, 2, 2))
    positions[:, 0, 0] = front * a  # the front particle on the floor
    positions[:, 1] = [0.01, 0.15]  # one high in the column
    with h5py.File(tmp_path / "result.h5", "w") as f:
        f[fields.TIME.path] = times
        f[fields.FLUID_POSITION.path] = positions
        f[fields.FLUID_ALIVE.path] = np.ones((times.size, 2), dtype=bool)
        f[fields.FLUID_KIND.path] = np.zeros(2, dtype=np.int8)
        f.attrs["scene"] = 'name = "dam"\n[water]\ngravity = [0.0, -9.81, 0.0]\n'
        f.attrs["column_width"] = a
        f.attrs["fps"] = 10.0
        f.attrs["frames_expected"] = times.size
    with jellysim.open_result(tmp_path) as result:
        paths = plot_result(result)
    assert [p.name for p in paths] == ["surge_front.png"]
    assert paths[0].stat().st_size > 10_000
