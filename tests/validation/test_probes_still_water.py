"""Probes against a closed form: still water in hydrostatic-3d's tank (fcc lattice, l0 = 5 mm,
12 layers filling H = 0.0490 m), 0.5 s, the probes' means over 0.25-0.5 s.

- Height probes (docs/theory/fluid.md F14) read the depth the layers fill, H, within 1 %
  (the unit test's still block within 1 %; here the water has settled for 0.5 s).
- Pressure probes (F15) read the hydrostatic pressure of MPS's own water: the free surface's
  Dirichlet condition p = 0 holds at the top layer's centres, half a layer (h_z / 2 = 2.0 mm)
  below H, so the pressure is rho g (H - h_z / 2 - z) (the fluid's own particles follow it to
  a few per cent). The wall particles a probe reads lie up to l0 behind the face (the floor's
  at z = -2.0 mm), and the probe reads their pressure: within 4 % of that law at the probe's
  point (1 % on the side walls, the floor's +3 % is its walls' depth: 2.0 mm of 47 mm).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import jellysim
from jellysim.fluid.geometry import ROW_HEIGHT
from jellysim.io.plots import plot_result

PROBES = {
    "probes.height.middle": [0.05, 0.025],
    "probes.height.near_wall": [0.012, 0.025],
    "probes.pressure.left_wall": [0.0, 0.025, 0.02],
    "probes.pressure.right_wall_low": [0.1, 0.025, 0.005],
    "probes.pressure.floor": [0.05, 0.025, 0.0],
}
GRAVITY, DENSITY = 9.81, 1000.0


def test_probes_read_still_water(tmp_path: Path) -> None:
    scene = jellysim.load_scene("hydrostatic-3d", {"duration": 0.5, "fps": 20.0, **PROBES})
    with jellysim.run(scene, tmp_path, quiet=True) as result:
        probes = result.probes()
        late = result.time > 0.25
        depth = float(result.file.attrs["water_depth"])
        l0 = float(result.file.attrs["particle_spacing"])
        paths = plot_result(result)
    assert tmp_path / "plots" / "probes.png" in paths
    for name in ("middle", "near_wall"):
        values, units = probes[name]
        assert units == "m"
        assert values[late].mean() == pytest.approx(depth, rel=0.01), name
    surface = depth - 0.5 * ROW_HEIGHT["fcc"] * l0  # where p = 0: the top layer's centres
    for name, (_, _, z) in (
        (k.split(".")[-1], v) for k, v in PROBES.items() if k.startswith("probes.pressure")
    ):
        values, units = probes[name]
        expected = DENSITY * GRAVITY * (surface - z)
        print(f"{name}: {values[late].mean():.1f} Pa, rho g (H - h_z/2 - z) = {expected:.1f} Pa")
        assert units == "Pa"
        assert values[late].mean() == pytest.approx(expected, rel=0.04), name
        assert np.all(np.abs(values[late] - values[late].mean()) < 0.05 * expected), name
