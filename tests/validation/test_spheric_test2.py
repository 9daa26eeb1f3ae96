"""SPHERIC benchmark Test 2 on the CPU: the 3-D dam break hitting a box, against the experiment of
Kleefsman, Fekken, Veldman, Iwanowski & Buchner (2005), J. Comput. Phys. 206:363-393 (the
SPHERIC release of Issa & Violeau 2006; src/jellysim/reference/kleefsman_2005_spheric_test2.csv).

The preset at 3 spacings a box height (l0 = 0.161 / 3 = 5.4 cm, 6,400 water particles, 23 across
the column) for the first second: the front crossing the tank, the height gauge H2 before the
box wetting, the impact on the box's face (P1) and the reservoir draining (H4). Tolerances,
from the resolution (docs/fluid.md, "SPHERIC benchmark Test 2"):
- H4: the 17 fcc layers fill 0.570 m, not 0.55 (+0.020 m, the lattice's rounding), and the
  gauge reads a kernel of 2 l0 across: within 0.035 m of the experiment to 1 s.
- H2 arrival (2 cm): the front's tip is one or two particles thick, l0 / h_z = 1.2 layers,
  and moves at about 4 m/s, so its time is uncertain by 2 l0 / 4 m/s = 27 ms: within 0.03 s.
- P1's impact: the sensor reads 10 ms means (fps = 100), the first wall layer lies up to l0
  inside the face, and the front's thin tip is free surface (p = 0) until water piles up at
  the face: the impact lags by up to (10 ms + l0 / 4 m/s + 2 l0 / 4 m/s = 50 ms); its height
  and the flow's pressure after it, with 11 walls in the sensor's 2 l0: within 35 %.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

import jellysim
from jellysim.reference import arrival, spheric_test2

SPACING = 0.161 / 3


@pytest.fixture(scope="module")
def coarse_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, np.ndarray]:
    folder: Path = tmp_path_factory.mktemp("spheric")
    scene = jellysim.load_scene(
        "spheric-test2", {"fluid.spacing": SPACING, "duration": 1.0, "fps": 100.0}
    )
    clock = time.perf_counter()
    jellysim.run(scene, out=folder, quiet=True).close()
    print(f"spheric-test2, l0 = {SPACING:.4f} m, 1 s: {time.perf_counter() - clock:.0f} s")
    with jellysim.open_result(folder) as result:
        series = {name: values for name, (values, _) in result.probes().items()}
        series["t"] = result.time
    return series


def _measured(t: np.ndarray) -> dict[str, np.ndarray]:
    data = spheric_test2()
    return {name: np.interp(t, data["t"], values) for name, values in data.items()}


def test_reservoir_drains_as_measured(coarse_run: dict[str, np.ndarray]) -> None:
    t = coarse_run["t"]
    error = np.abs(coarse_run["H4"] - _measured(t)["H4"])
    print(f"H4: largest difference {error.max():.4f} m, at t = 0 {error[0]:.4f} m")
    assert error.max() < 0.035


def test_front_reaches_h2_in_time(coarse_run: dict[str, np.ndarray]) -> None:
    data = spheric_test2()
    simulated = arrival(coarse_run["t"], coarse_run["H2"], 0.02)
    measured = arrival(data["t"], data["H2"], 0.02)
    t = coarse_run["t"]
    after = t >= 0.45
    rms = np.sqrt(np.mean((coarse_run["H2"][after] - _measured(t)["H2"][after]) ** 2))
    print(f"H2 reaches 2 cm at {simulated:.3f} s (experiment {measured:.3f} s); RMS {rms:.4f} m")
    assert abs(simulated - measured) < 0.03
    assert rms < 0.03


def test_impact_on_the_box(coarse_run: dict[str, np.ndarray]) -> None:
    data = spheric_test2()
    t = coarse_run["t"]
    simulated = arrival(t, coarse_run["P1"], 2000.0)
    measured = arrival(data["t"], data["P1"], 2000.0)
    window = (data["t"] > 0.35) & (data["t"] < 0.6)
    peak, measured_peak = coarse_run["P1"][(t > 0.35) & (t < 0.6)].max(), data["P1"][window].max()
    late = (t >= 0.6) & (t <= 1.0)
    after, measured_after = coarse_run["P1"][late].mean(), _measured(t)["P1"][late].mean()
    top = max(coarse_run["P5"][t <= 0.9].mean(), coarse_run["P7"][t <= 0.9].mean())
    print(
        f"P1 reaches 2 kPa at {simulated:.3f} s (experiment {measured:.3f} s); peak {peak:.0f} "
        f"Pa ({measured_peak:.0f}); mean 0.6-1 s {after:.0f} Pa ({measured_after:.0f}); "
        f"top mean to 0.9 s {top:.0f} Pa"
    )
    assert 0.0 <= simulated - measured < 0.05
    assert peak == pytest.approx(measured_peak, rel=0.35)
    assert after == pytest.approx(measured_after, rel=0.35)
    assert top < 200.0  # the box's top stays dry until about 1 s, as measured (P5, P7 ~ 0)
