"""Parameter sweeps: the paper's Figs. 5, 7 and 8 (root and tip x against time as keys vary).

``jellysim sweep SCENE --vary tentacles.youngs_modulus=100,2.4e5,9e9`` runs the scene once per
point (a grid of every combination of several ``--vary`` keys, or with ``--zip`` their values
paired in order), the points at once over local processes or a Dask cluster, each to its own
folder under the sweep's, so a killed sweep resumes; then writes one tidy table of the points
(CSV and netCDF) and draws the figure from it: the root's and the tip's x against time, one
panel per point, labelled.
"""

from jellysim.studies.plan import Plan, grid, listed
from jellysim.studies.sweep import SweepFailed, SweepRun, run_sweep, sweep
from jellysim.studies.table import summary_dataset, traces_from_dataset, write_table
from jellysim.studies.traces import Trace, plot_sweep, write_traces_csv

__all__ = [
    "Plan",
    "SweepFailed",
    "SweepRun",
    "Trace",
    "grid",
    "listed",
    "plot_sweep",
    "run_sweep",
    "summary_dataset",
    "sweep",
    "traces_from_dataset",
    "write_table",
    "write_traces_csv",
]
