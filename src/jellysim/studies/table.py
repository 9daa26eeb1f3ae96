"""A sweep's tidy table: one row per point (the swept keys' values, where its run lies, and
summaries of its trace), with the traces themselves, as an :class:`xarray.Dataset` written to
netCDF (through h5netcdf) and its per-point part to CSV. The figure is drawn from the netCDF
file, so what is plotted is what was written.

Dimensions: ``point`` (N) and ``frame`` (the longest run's F; shorter runs are NaN beyond their
own ``frames``). Coordinates: ``point`` (0..N-1) and one per swept key, named by the key
(``flow.speed``), on ``point``. Variables, units as attributes (and in the name where there is
one): ``folder`` (the point's run, relative to the sweep's folder), ``frames``, the summaries
over the second half of each run (:data:`LATE_FRACTION`) ``root_x_range_m``, ``tip_x_range_m``,
``tip_to_root_range`` (their ratio, the paper's measure of how the tip follows the root),
``root_x_mean_m``, ``tip_x_mean_m``, and the traces ``time_s``, ``root_x_m``, ``tip_x_m``
(point, frame). Attributes: ``swept_keys`` (the keys, space-separated, in the sweep's order),
``tentacle`` (the traced tentacle), ``late_fraction``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from jellysim.studies.traces import Trace, format_value

LATE_FRACTION = 0.5  # the summaries cover the last half of each run (after the start-up)
SUMMARIES = {  # name: (units, description)
    "root_x_range_m": ("m", "peak-to-peak x of the root, late in the run"),
    "tip_x_range_m": ("m", "peak-to-peak x of the tip, late in the run"),
    "tip_to_root_range": ("1", "tip x range over root x range, late in the run"),
    "root_x_mean_m": ("m", "mean x of the root, late in the run"),
    "tip_x_mean_m": ("m", "mean x of the tip, late in the run"),
}


def summary_dataset(
    traces: Sequence[Trace], keys: Sequence[str], folders: Sequence[str], tentacle: int
) -> Any:
    """The sweep's :class:`xarray.Dataset` (module docstring) from its traces, in point order;
    ``folders`` are the points' run folders relative to the sweep's."""
    import xarray

    count = len(traces)
    longest = max(len(trace.time) for trace in traces)
    padded = {name: np.full((count, longest), np.nan) for name in ("time_s", "root_x_m", "tip_x_m")}
    summaries = {name: np.empty(count) for name in SUMMARIES}
    for row, trace in enumerate(traces):
        frames = len(trace.time)
        padded["time_s"][row, :frames] = trace.time
        padded["root_x_m"][row, :frames] = trace.root_x
        padded["tip_x_m"][row, :frames] = trace.tip_x
        root, tip = trace.late(LATE_FRACTION)
        summaries["root_x_range_m"][row] = np.ptp(root)
        summaries["tip_x_range_m"][row] = np.ptp(tip)
        summaries["tip_to_root_range"][row] = trace.tip_to_root_range(LATE_FRACTION)
        summaries["root_x_mean_m"][row] = root.mean()
        summaries["tip_x_mean_m"][row] = tip.mean()
    coords: dict[str, Any] = {"point": ("point", np.arange(count))}
    for key in keys:
        coords[key] = ("point", _column([trace.point[key] for trace in traces]), {"scene_key": key})
    variables: dict[str, Any] = {
        "folder": ("point", np.array(folders, dtype=object), {"description": "the point's run"}),
        "frames": ("point", np.array([len(t.time) for t in traces]), {"units": "1"}),
    }
    for name, (units, description) in SUMMARIES.items():
        variables[name] = ("point", summaries[name], {"units": units, "description": description})
    traced = {"time_s": "s", "root_x_m": "m", "tip_x_m": "m"}
    for name, units in traced.items():
        variables[name] = (("point", "frame"), padded[name], {"units": units})
    attrs = {"swept_keys": " ".join(keys), "tentacle": tentacle, "late_fraction": LATE_FRACTION}
    return xarray.Dataset(variables, coords=coords, attrs=attrs)


def _column(values: list[Any]) -> np.ndarray:
    """A swept key's values as one array: numbers, booleans, or else their text."""
    if all(isinstance(v, bool) for v in values):
        return np.array(values, dtype=bool)
    if all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
        return np.array(values)
    return np.array([format_value(v) for v in values], dtype=object)


def write_table(dataset: Any, csv_path: Path, netcdf_path: Path) -> None:
    """The per-point variables to CSV (a row per point), everything to netCDF; each file is
    written beside and then moved into place, so a killed write leaves no half table."""
    per_point = [name for name, array in dataset.data_vars.items() if array.dims == ("point",)]
    frame = dataset[per_point].to_dataframe().reset_index()
    _atomic(csv_path, lambda path: frame.to_csv(path, index=False))
    _atomic(netcdf_path, lambda path: dataset.to_netcdf(path, engine="h5netcdf"))


def _atomic(path: Path, write: Any) -> None:
    temporary = path.with_name(path.name + ".tmp")
    write(temporary)
    os.replace(temporary, path)


def traces_from_dataset(dataset: Any) -> list[Trace]:
    """The traces a sweep table holds, in point order (what its figure draws)."""
    keys = str(dataset.attrs["swept_keys"]).split()
    traces = []
    for row in range(dataset.sizes["point"]):
        frames = int(dataset["frames"].values[row])
        point = {key: dataset[key].values[row].item() for key in keys}
        value = point[keys[0]] if len(keys) == 1 else tuple(point.values())
        traces.append(
            Trace(
                value,
                dataset["time_s"].values[row, :frames],
                dataset["root_x_m"].values[row, :frames],
                dataset["tip_x_m"].values[row, :frames],
                point,
            )
        )
    return traces
