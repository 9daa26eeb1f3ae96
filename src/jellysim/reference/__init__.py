"""Experimental reference data and the measures that compare a result with it.

``martin_moyce_1952_n2_a225.csv``: Martin & Moyce (1952), "An experimental study of the collapse
of liquid columns on a rigid horizontal plane", Phil. Trans. R. Soc. A 244, Fig. for n^2 = 2
(column height 2a, width a, a = 2.25 in): surge-front position Z = x_front / a against
T = t sqrt(2 g / a).

``kleefsman_2005_spheric_test2.csv``: SPHERIC benchmark Test 2, the dam break with a box of
Kleefsman et al. (2005): the pressure sensors P1-P8 (Pa) and height gauges H1-H4 (m) against t,
5 ms means of the 1 kHz record (the file's header).
"""

from __future__ import annotations

from importlib import resources

import numpy as np

MAX_TIME_SHIFT = 0.3  # the largest shift in T allowed for the gate release's lag (issue 5)


def martin_moyce() -> tuple[np.ndarray, np.ndarray]:
    """The Martin & Moyce n^2 = 2 surge front: (T, Z), dimensionless."""
    text = resources.files(__package__).joinpath("martin_moyce_1952_n2_a225.csv").read_text()
    rows = [line for line in text.splitlines() if line and not line.startswith(("#", "T,"))]
    data = np.array([[float(v) for v in row.split(",")] for row in rows])
    return data[:, 0], data[:, 1]


def spheric_test2() -> dict[str, np.ndarray]:
    """SPHERIC Test 2's measurements: ``t`` (s), ``P1``-``P8`` (Pa), ``H1``-``H4`` (m), each
    (1200,), named as the preset ``spheric-test2`` names its probes."""
    text = resources.files(__package__).joinpath("kleefsman_2005_spheric_test2.csv").read_text()
    lines = [line for line in text.splitlines() if line and not line.startswith("#")]
    names = lines[0].split(",")
    data = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    return {name: data[:, k] for k, name in enumerate(names)}


def arrival(times: np.ndarray, values: np.ndarray, threshold: float) -> float:
    """The first time (s) at which ``values`` (F,) reach ``threshold``, linearly interpolated
    between ``times`` (F,) s; nan when they never do."""
    above = np.flatnonzero(values >= threshold)
    if len(above) == 0:
        return float("nan")
    k = int(above[0])
    if k == 0:
        return float(times[0])
    t0, t1, v0, v1 = times[k - 1], times[k], values[k - 1], values[k]
    return float(t0 + (threshold - v0) / (v1 - v0) * (t1 - t0))


def spheric_test2_measures(times: np.ndarray, probes: dict[str, np.ndarray]) -> dict[str, float]:
    """What docs/fluid.md and the validation test compare of a run of ``spheric-test2``:
    ``times`` (F,) s and each probe's (F,) record by name against the measurements, each
    simulated value beside the measured one (``..._measured``): the time at which H2 reaches
    2 cm and P1 2 kPa (the front's arrival and the impact), P1's largest value in 0.35-0.6 s,
    the means of P1 and P3 over 0.6-1 s (the flow piled up at the face), the largest of P5 and
    P7 before 0.9 s (the box's top, dry then), and the RMS differences of H2 and H4 over the run
    (m). Keys whose probes or times the run lacks are left out."""
    data = spheric_test2()
    out: dict[str, float] = {}

    def measured(name: str) -> np.ndarray:
        return np.interp(times, data["t"], data[name])

    if "H2" in probes:
        out["H2_arrival"] = arrival(times, probes["H2"], 0.02)
        out["H2_arrival_measured"] = arrival(data["t"], data["H2"], 0.02)
    for name in ("H2", "H4"):
        if name in probes:
            out[f"{name}_rms"] = float(np.sqrt(np.mean((probes[name] - measured(name)) ** 2)))
    if "P1" in probes:
        out["P1_arrival"] = arrival(times, probes["P1"], 2000.0)
        out["P1_arrival_measured"] = arrival(data["t"], data["P1"], 2000.0)
        window, reference = (times > 0.35) & (times < 0.6), (data["t"] > 0.35) & (data["t"] < 0.6)
        if window.any():
            out["P1_peak"] = float(probes["P1"][window].max())
            out["P1_peak_measured"] = float(data["P1"][reference].max())
    later = (times >= 0.6) & (times <= 1.0)
    if later.any() and times[-1] >= 1.0:
        for name in ("P1", "P3"):
            if name in probes:
                out[f"{name}_mean"] = float(probes[name][later].mean())
                out[f"{name}_mean_measured"] = float(measured(name)[later].mean())
    dry = times <= 0.9
    top = [name for name in ("P5", "P7") if name in probes]
    if top:
        out["top_before_0.9"] = float(max(probes[name][dry].max() for name in top))
        out["top_before_0.9_measured"] = float(
            max(data[name][data["t"] <= 0.9].max() for name in top)
        )
    return out


def surge_front(
    positions: np.ndarray, alive: np.ndarray, fluid: np.ndarray, column_width: float
) -> np.ndarray:
    """The surge front per frame, x_front / a: the largest x of live fluid particles within 0.1 a
    of the floor (y or z = 0, the last coordinate), divided by the column width a.

    ``positions`` (F, N, D) m, ``alive`` (F, N) bool, ``fluid`` (N,) bool (fluid, not walls).
    """
    height = positions[..., -1]
    near = alive & fluid[None, :] & (height < 0.1 * column_width)
    x = np.where(near, positions[..., 0], -np.inf)
    return x.max(axis=1) / column_width


def front_errors(
    times: np.ndarray, front: np.ndarray, until: float = 3.0
) -> tuple[float, float, float]:
    """RMS relative error of a surge front Z(T) against Martin & Moyce for T <= ``until``: as
    computed, and after the best time shift |s| <= MAX_TIME_SHIFT (Z(T - s) against the
    experiment: the gate's release makes the experiment lag every simulation).

    Returns (raw, shifted, shift). ``times`` and ``front`` are dimensionless (T, Z).
    """
    t_ref, z_ref = martin_moyce()
    keep = t_ref <= until

    def rms(shift: float) -> float:
        model = np.interp(t_ref[keep] - shift, times, front)
        return float(np.sqrt(np.mean(((model - z_ref[keep]) / z_ref[keep]) ** 2)))

    shifts = np.linspace(-MAX_TIME_SHIFT, MAX_TIME_SHIFT, 601)
    errors = np.array([rms(s) for s in shifts])
    best = int(np.argmin(errors))
    return rms(0.0), float(errors[best]), float(shifts[best])
