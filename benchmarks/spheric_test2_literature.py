"""The measures of a ``spheric-test2`` result that docs/fluid.md compares with other codes'
published results ("Against other codes' published results"), beside the experiment's.

    PYTHONPATH=src python benchmarks/spheric_test2_literature.py RESULT [RESULT ...]
        [--raw /work/shared/data/spheric_test2/test_case_2_exp_data.dat]

RESULT is a run folder (or its ``result.h5``) of the preset, at any spacing. Reads only the
probes (seconds, whatever the result's size). Prints, per result, the spacing, the simulated
time and, for each measure, jellysim's value and the experiment's from the shipped 5 ms means
(``jellysim.reference.spheric_test2``); with ``--raw`` the experiment's value from the 1 kHz file
too (peaks are higher there). The measures:

- ``spheric_test2_measures`` (docs/fluid.md's own table: H2 reaches 2 cm, P1 reaches 2 kPa,
  P1's peak in 0.35-0.6 s, P1 and P3 means over 0.6-1 s, RMS of H2 and H4);
- P1's and P2's peak in 0.3-1.2 s, its time, and the time each first reaches a quarter of the
  measured peak (the definitions of the OpenFOAM interFoam validation cited in docs/fluid.md:
  vamseeachanta/digitalmodel, ``validation/kleefsman.py``, ``extract_impact_metrics``);
- the mean absolute difference of H2 and H4 over the run, at the measured samples, divided by
  the measured maximum over the same window (that source's "normalized MAE"; from the 5 ms
  means, and from the 1 kHz record with ``--raw``);
- the wave that comes back from the dry end's wall (docs/fluid.md, "What the late return is
  not"), beside the 5 ms means: H1's highest in 0.5-1.5 s, H2's first hump (highest in 1-3 s),
  the time H4 passes 0.16 m after 2 s, H4's second peak (3-5 s) and the time H2 passes 0.2 m
  after 4 s.
"""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path

import numpy as np

import jellysim
from jellysim.reference import arrival, spheric_test2, spheric_test2_measures

IMPACT_WINDOW = (0.3, 1.2)  # s, the window of the interFoam case's peak and arrival


def read_raw(path: Path) -> dict[str, np.ndarray]:
    """The benchmark's 1 kHz file: ``t``, P1-P8 (Pa), H1-H4 (m), with its H1 and H3 columns
    swapped to the places the preset's probes have (docs/decisions.md, "The height gauges'
    columns")."""
    data = np.loadtxt(path, skiprows=1)
    names = ["t", "P1", "P2", "P3", "P4", "P5", "P6", "P7", "P8", "H3", "H2", "H1", "H4"]
    return {name: data[:, k] for k, name in enumerate(names)}


def impact(times: np.ndarray, values: np.ndarray, reference_peak: float) -> tuple[float, ...]:
    """(peak Pa, its time s, first time at a quarter of ``reference_peak``) in the window."""
    inside = (times >= IMPACT_WINDOW[0]) & (times <= IMPACT_WINDOW[1])
    k = int(np.argmax(np.where(inside, values, -np.inf)))
    start = int(np.flatnonzero(inside)[0])
    quarter = arrival(times[start:], values[start:], 0.25 * reference_peak)
    return float(values[k]), float(times[k]), quarter


def normalized_mae(times, values, ref_t, ref_values) -> float:
    """Mean |simulated - measured| over the measured samples within the run, the simulated
    record interpolated to them, / the measured maximum there (the interFoam case's measure)."""
    window = (ref_t >= times[0]) & (ref_t <= times[-1])
    simulated = np.interp(ref_t[window], times, values)
    return float(np.mean(np.abs(simulated - ref_values[window])) / ref_values[window].max())


def highest(times: np.ndarray, values: np.ndarray, start: float, end: float) -> str:
    """'0.34 m at 1.79 s': the largest of ``values`` with ``start <= times <= end``."""
    inside = (times >= start) & (times <= end)
    k = int(np.argmax(np.where(inside, values, -np.inf)))
    return f"{values[k]:.3f} m at {times[k]:.2f} s"


def passes(times: np.ndarray, values: np.ndarray, level: float, after: float) -> str:
    """'2.75 s': the first time after ``after`` at which ``values`` reach ``level``."""
    k = np.flatnonzero((times > after) & (values >= level))
    return f"{times[k[0]]:.2f} s" if k.size else "never"


def return_wave(times: np.ndarray, heights: dict[str, np.ndarray]) -> list[str]:
    """The returning wave's measures (module docstring), one line each."""
    return [
        f"H1 highest, 0.5-1.5 s: {highest(times, heights['H1'], 0.5, 1.5)}",
        f"H2 first hump, 1-3 s: {highest(times, heights['H2'], 1.0, 3.0)}",
        f"H4 passes 0.16 m after 2 s: {passes(times, heights['H4'], 0.16, 2.0)}",
        f"H4 second peak, 3-5 s: {highest(times, heights['H4'], 3.0, 5.0)}",
        f"H2 passes 0.2 m after 4 s: {passes(times, heights['H2'], 0.2, 4.0)}",
    ]


def report(path: Path, raw: dict[str, np.ndarray] | None) -> None:
    with jellysim.open_result(path) as result:
        times = np.asarray(result.time, dtype=float)
        probes = {name: np.asarray(v, dtype=float) for name, (v, _) in result.probes().items()}
    folder = path if path.is_dir() else path.parent
    scene = folder / "scene.toml"
    spacing = tomllib.loads(scene.read_text())["fluid"]["spacing"] if scene.exists() else np.nan
    ref = spheric_test2()
    print(f"== {path}: l0 = {spacing:.4f} m, {times[-1]:.2f} s, {len(times)} frames")
    for key, value in spheric_test2_measures(times, probes).items():
        print(f"  {key:28s} {value:10.4g}")
    sources = [("5 ms means", ref)] + ([("1 kHz", raw)] if raw is not None else [])
    for name in ("P1", "P2"):
        for label, data in sources:
            peak_ref, t_ref, quarter_ref = impact(data["t"], data[name], data[name].max())
            peak, t_peak, quarter = impact(times, probes[name], peak_ref)
            print(
                f"  {name} peak {peak:7.0f} Pa at {t_peak:.3f} s, reaches {0.25 * peak_ref:5.0f} Pa"
                f" at {quarter:.3f} s | measured ({label}) {peak_ref:7.0f} Pa at {t_ref:.3f} s,"
                f" {quarter_ref:.3f} s"
            )
    for name in ("H2", "H4"):
        for label, data in sources:
            mae = normalized_mae(times, probes[name], data["t"], data[name])
            print(f"  {name} normalized MAE over 0-{times[-1]:.1f} s ({label}): {100 * mae:.1f} %")
    heights = ("H1", "H2", "H4")
    simulated = return_wave(times, {name: probes[name] for name in heights})
    measured = return_wave(ref["t"], {name: ref[name] for name in heights})
    for ours, theirs in zip(simulated, measured, strict=True):
        print(f"  {ours} | measured (5 ms means) {theirs.split(': ')[1]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", type=Path)
    parser.add_argument("--raw", type=Path, help="the benchmark's 1 kHz test_case_2_exp_data.dat")
    args = parser.parse_args()
    raw = read_raw(args.raw) if args.raw else None
    for path in args.results:
        report(path, raw)


if __name__ == "__main__":
    main()
