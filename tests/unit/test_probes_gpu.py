"""The probes on the GPU path (jellysim.fluid.gpu) against the CPU path, in Numba's CUDA
simulator (CI has no GPU; tests/gpu runs a million-particle case on one).

The scene is spheric-test2 shrunk to what the simulator steps in under a minute: l0 = 0.161 / 2
(the box 2 spacings thick, as the regression case), the tank 6 x 4 spacings and 0.2 m tall, a
column of 2 spacings against its far wall, the box's face a quarter of a spacing from it; 28
fluid, 136 wall and 752 dummy particles, and the probes on the tank's floor and far wall and on
the box's face towards the water. One frame of one step: the simulator takes 15-30 s for it
on an idle 2-core host (the CPU 0.3 s). In that step the box's sensor reads 0 on both paths
(its walls are not wet yet): the device's sums over the box's walls are checked on a given
pressure instead.

Bounds, as tests/unit/test_fluid_gpu.py's (both paths solve the pressure to a relative
residual of 1e-12 and differ by the round-off of their sums and solvers; a wrong term shows as
a difference of order one): heights 1e-8 l0 (the positions' bound), pressures 1e-6 of the
largest probe's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tomli_w

import jellysim
from jellysim import fields
from jellysim.config.scenes import scene_source_tree
from jellysim.fluid import gpu
from jellysim.fluid.probes import face_of, weighted_sums
from jellysim.simulation.fluid import FluidSimulation

pytestmark = pytest.mark.skipif(
    not gpu.simulated(), reason="the CUDA simulator is off (make test-gpu runs tests/gpu)"
)

L0 = 0.161 / 2
BOX = [L0, L0, 0.0, 0.30, 3 * L0, 2 * L0]  # its face at x = 0.30, the column's at 0.322


def _scene_file(folder: Path) -> Path:
    """spheric-test2 shrunk (the module's docstring), the pressure solved to 1e-12."""
    tree = scene_source_tree("spheric-test2")
    tree["fluid"].update(
        spacing=L0,
        tank_width=6 * L0,
        tank_depth=4 * L0,
        tank_height=0.2,
        water_width=2 * L0,
        water_height=0.17,
        obstacles=[BOX],
        tolerance=1e-12,
    )
    tree["probes"] = {
        "height": {"water": [0.4, 2 * L0], "gap": [0.31, 2 * L0]},
        "pressure": {
            "box": [BOX[3], 2 * L0, 0.05],
            "floor": [0.4, 2 * L0, 0.0],
            "wall": [6 * L0, 2 * L0, 0.1],
        },
    }
    tree.update(duration=0.005, fps=200.0)  # one frame of one step (the stable dt: 7.9 ms)
    path = folder / "spheric-small.toml"
    path.write_text(tomli_w.dumps(tree))
    return path


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _scene_file(tmp_path_factory.mktemp("spheric-small"))


def test_probes_on_the_gpu_match_the_cpu(scene_file: Path, tmp_path: Path) -> None:
    """The result's probes/height and probes/pressure of a GPU run are the CPU run's, to the
    bounds of the module's docstring, the box's probe included."""
    records = {}
    for device in ("cpu", "cuda"):
        scene = jellysim.load_scene(str(scene_file), {"fluid.device": device})
        with jellysim.run(scene, out=tmp_path / device, quiet=True) as result:
            assert len(result.time) == 2
            records[device] = {name: values for name, (values, _) in result.probes().items()}
    cpu, on_gpu = records["cpu"], records["cuda"]
    assert cpu.keys() == on_gpu.keys() == {"water", "gap", "box", "floor", "wall"}
    apart = {name: float(np.abs(on_gpu[name] - cpu[name]).max()) for name in cpu}
    print("GPU (simulator) - CPU, largest:", ", ".join(f"{k} {v:.3g}" for k, v in apart.items()))
    for name in ("water", "gap"):
        assert apart[name] <= 1e-8 * L0, name
    largest = max(np.abs(cpu[name]).max() for name in ("box", "floor", "wall"))
    for name in ("box", "floor", "wall"):
        assert apart[name] <= 1e-6 * largest, name
    # the comparison is of probes that read something: water under pressure on the floor
    assert cpu["water"][-1] > 0.1 and cpu["floor"][-1] > 100.0


def test_the_gpu_sums_the_probes_and_downloads_only_them(scene_file: Path, monkeypatch) -> None:
    """On a GPU solver's state (a random pressure), the device's probe sums are the host's
    formula (Eq. F15, :func:`weighted_sums`) for every probe, the box's included; a step's
    reading downloads no state array, and the heights are measured from the frame's host
    copies. The CPU solver's gauge is the host formula to the bit."""
    simulation = FluidSimulation(jellysim.load_scene(str(scene_file), {"fluid.device": "cuda"}))
    solver = simulation.solver
    probes = simulation.probes
    assert isinstance(solver, gpu.GPUSolver) and probes is not None
    state = solver.state_arrays()
    state["pressure"] = np.random.default_rng(5).uniform(0.0, 2000.0, solver.n)
    solver.restore(state)
    pressure = probes.pressure
    # the box's probe reads the walls of the box's face towards the water (face 2D - 1 + 3)
    box_rows = pressure.rows[0]
    tank = np.array([6 * L0, 4 * L0, 0.2])
    faces = face_of(state["position"][box_rows], tank, np.array([BOX]), 1e-6 * L0)
    assert box_rows.size > 0 and np.all(faces == 5 + 3)
    downloads: list[str] = []
    download = solver._download

    def recorded(name: str, array: object) -> np.ndarray:
        if name not in solver._host:
            downloads.append(name)
        return download(name, array)

    monkeypatch.setattr(solver, "_download", recorded)
    got = probes.gauge()
    expected = weighted_sums(state["pressure"], pressure.rows, pressure.weights)
    assert np.all(expected > 0.0)
    np.testing.assert_allclose(got, expected, rtol=1e-14)  # the same terms, in another order
    probes.after_step(1e-3)
    probes.end_frame()
    np.testing.assert_allclose(probes.frame_pressure, expected, rtol=1e-14)
    assert downloads == []
    values = probes.frame_values()
    assert sorted(downloads) == ["alive", "position"]  # the frame's host copies, once
    heights = probes.height.measure(state["position"], state["kind"], state["alive"])
    np.testing.assert_array_equal(values[fields.PROBE_HEIGHT.path], heights)
    # another set of sums: every particle in one, a lone particle in another
    rows = [np.arange(solver.n), np.array([solver.n - 1])]
    weights = [np.full(solver.n, 1.0 / solver.n), np.array([2.0])]
    np.testing.assert_allclose(
        solver.pressure_gauge(rows, weights)(),
        [state["pressure"].mean(), 2.0 * state["pressure"][-1]],
        rtol=1e-13,
    )
    assert solver.pressure_gauge([], [])().shape == (0,)
    with pytest.raises(ValueError, match="as many weights"):
        solver.pressure_gauge(rows, weights[::-1])
    # the CPU: the formula itself, on its live pressure
    cpu = FluidSimulation(jellysim.load_scene(str(scene_file))).solver
    cpu.restore(state)
    gauge = cpu.pressure_gauge(pressure.rows, pressure.weights)
    np.testing.assert_array_equal(gauge(), pressure.measure(state["pressure"]))
