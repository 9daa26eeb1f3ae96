"""SPHERIC benchmark Test 2 on the CPU: the 3-D dam break hitting a box, against the experiment of
Kleefsman, Fekken, Veldman, Iwanowski & Buchner (2005), J. Comput. Phys. 206:363-393 (the
SPHERIC release of Issa & Violeau 2006; src/jellysim/reference/kleefsman_2005_spheric_test2.csv).

The preset at 3 spacings a box height (l0 = 0.161 / 3 = 5.4 cm, 6,486 water particles, 23 along
the column) for the first second, 10 ms frames: the front crossing the tank, the height gauge
H2 before the box wetting, the impact on the box's face (P1) and the reservoir draining (H4),
measured by :func:`jellysim.reference.spheric_test2_measures`. Tolerances, from the resolution
(docs/fluid.md, "SPHERIC benchmark Test 2"):
- H4: the 17 fcc layers fill 0.570 m, not 0.55 (+0.020 m, the lattice's rounding), and the
  gauge reads a kernel 4 l0 across: RMS within 0.03 m of the experiment.
- The release: the simulated reservoir drains as the measured one 25 ms later (the best shift
  of H4 over 0-0.4 s at l0 = 4.0 and 3.2 cm), a lag that does not shrink with resolution and
  that every arrival carries (docs/fluid.md).
- H2's arrival (2 cm): that 25 ms, and the front's tip, whose place on the lattice is
  uncertain by a spacing at about 4 m/s: l0 / (4 m/s) = 13 ms either way; within 0.04 s.
  After it, H2 within 0.03 m RMS (the kernel's 4 l0 across a front that rises 0.1 m in 0.1 s).
- P1's impact (2 kPa): the release's 25 ms, the sensor's 10 ms means and the box's first wall
  layer, up to l0 inside the face (l0 / (4 m/s) = 13 ms): late by at most 0.055 s. Its peak and
  the pressure of the water piled up after it (0.6-1 s), read from the 11-15 wall particles
  within the sensor's 2 l0: within 35 % (measured: -6 % and -27 %, -16 % and -7 % for the latter
  at 4.0 and 3.2 cm). The box's top (P5, P7) stays dry until the wave comes back at 1.4 s.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest

import jellysim
from jellysim.reference import spheric_test2_measures

SPACING = 0.161 / 3


@pytest.fixture(scope="module")
def measures(tmp_path_factory: pytest.TempPathFactory) -> dict[str, float]:
    folder: Path = tmp_path_factory.mktemp("spheric")
    scene = jellysim.load_scene(
        "spheric-test2", {"fluid.spacing": SPACING, "duration": 1.0, "fps": 100.0}
    )
    clock = time.perf_counter()
    jellysim.run(scene, out=folder, quiet=True).close()
    print(f"spheric-test2, l0 = {SPACING:.4f} m, 1 s: {time.perf_counter() - clock:.0f} s")
    with jellysim.open_result(folder) as result:
        probes = {name: values for name, (values, _) in result.probes().items()}
        found = spheric_test2_measures(result.time, probes)
    print(", ".join(f"{key} {value:.4g}" for key, value in found.items()))
    return found


def test_reservoir_drains_as_measured(measures: dict[str, float]) -> None:
    assert measures["H4_rms"] < 0.03


def test_front_reaches_h2_in_time(measures: dict[str, float]) -> None:
    assert measures["H2_arrival"] == pytest.approx(measures["H2_arrival_measured"], abs=0.04)
    assert measures["H2_rms"] < 0.03


def test_impact_on_the_box(measures: dict[str, float]) -> None:
    lag = measures["P1_arrival"] - measures["P1_arrival_measured"]
    assert 0.0 <= lag < 0.055
    assert measures["P1_peak"] == pytest.approx(measures["P1_peak_measured"], rel=0.35)
    assert measures["P1_mean"] == pytest.approx(measures["P1_mean_measured"], rel=0.35)


def test_top_of_the_box_stays_dry(measures: dict[str, float]) -> None:
    assert measures["top_before_0.9_measured"] < 200.0
    assert measures["top_before_0.9"] < 500.0
