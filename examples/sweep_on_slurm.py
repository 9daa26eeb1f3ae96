"""The paper's Figs. 7 and 8 as one grid sweep on a Slurm (or PBS) cluster: dask-jobqueue
starts Dask workers as batch jobs and jellysim.sweep runs one point per task on them.

    pip install 'jellysim[dask]' dask-jobqueue
    python examples/sweep_on_slurm.py /shared/sweeps/fig7-8 [--pbs] [--jobs 8]

OUT must be on a file system the compute nodes share (each point's run writes there); run the
script again with the same OUT to continue a sweep that was stopped (finished points are kept,
killed ones resume from their checkpoints). Not run by the test suite: it needs a batch system.
"""

from __future__ import annotations

import argparse

import jellysim

MODULI = [100.0, 1e4, 2.4e5, 5e6, 9e9]  # Pa, Fig. 7
SPEEDS = [0.0, 0.3, 0.6, 1.0]  # m/s, Fig. 8


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="the sweep's folder, shared by the compute nodes")
    parser.add_argument("--pbs", action="store_true", help="PBS instead of Slurm")
    parser.add_argument("--jobs", type=int, default=8, help="batch jobs, one Dask worker each")
    args = parser.parse_args()
    from dask_jobqueue import PBSCluster, SLURMCluster

    # Each batch job books 4 cores for one Dask worker that runs one task, one point, at a time
    # (cores=1: one thread; several would run points at once in one process, each using every
    # core). The point's Numba kernels use the job's 4 cores: NUMBA_NUM_THREADS, shared among
    # the worker's threads (docs/sweeps.md).
    cores = 4
    booked: dict[str, object]
    if args.pbs:
        booked = {"resource_spec": f"select=1:ncpus={cores}:mem=8GB"}
        kind = PBSCluster
    else:
        booked = {"job_cpu": cores}
        kind = SLURMCluster
    with kind(
        cores=1,
        processes=1,
        memory="8GB",
        walltime="02:00:00",
        job_script_prologue=[f"export NUMBA_NUM_THREADS={cores}"],
        **booked,
    ) as cluster:
        cluster.scale(jobs=args.jobs)
        traces = jellysim.sweep(
            "forced-tentacles",
            {"tentacles.youngs_modulus": MODULI, "flow.speed": SPEEDS},
            overrides={"tentacles.count": 1, "flow.noise": 0},
            out=args.out,
            scheduler=cluster.scheduler_address,
            quiet=False,
        )
    for trace in traces:
        print(trace.label, f"tip/root range {trace.tip_to_root_range():.2f}")


if __name__ == "__main__":
    main()
