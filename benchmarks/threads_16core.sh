#!/usr/bin/env bash
# Numba's threading layers on a 16-core machine (issue 24; docs/decisions.md, "Threading layer"):
# omp, workqueue and tbb on 2 and 16 threads, with the cores idle and with 16 busy processes.
#   bash benchmarks/threads_16core.sh LOG
# Two measurements: the 3-D tank's MPS steps per second (bench_fluid.py, tank-3d at 54,000
# fluid particles, 20 timed steps), and a whole `jellysim run dam-break-2d` (0.1 s simulated)
# with the time from its "wrote" line to the process's exit (bench_threads.py; TBB's
# finalization hang shows there). TBB comes from LD_LIBRARY_PATH or the system (libtbb12).
set -u
log=${1:-/dev/stdout}
py=${PYTHON:-python3}
say() { echo "$@" | tee -a "$log"; }
say "== machine"
{ nproc; lscpu | grep -E "Model name|^CPU\(s\)|Thread|Core|Socket"; uptime
  $py -c "import numba, numpy, sys; print('python', sys.version.split()[0], 'numba', numba.__version__, 'numpy', numpy.__version__)"
  ldconfig -p | grep -E "libgomp|libtbb" ; } 2>&1 | tee -a "$log"
say "== compile (not timed)"
$py -m jellysim run dam-break-2d --out /tmp/warm2d --force --set duration=0.002 >/dev/null 2>&1 &
$py benchmarks/bench_fluid.py --case tank-3d --steps 1 --threads 16 2>&1 | tail -1 | tee -a "$log"
wait
busy_start() { for _ in $(seq "$1"); do $py -c "while True: pass" & done; }
busy_stop() { jobs -p | xargs -r kill 2>/dev/null; wait 2>/dev/null; }
for load in 0 16; do
  busy_start $load
  for threads in 2 16; do
    for layer in omp workqueue tbb; do
      line=$(NUMBA_THREADING_LAYER=$layer timeout 45 $py benchmarks/bench_fluid.py --case tank-3d \
        --steps 20 --threads $threads 2>&1 | grep -E "steps/s|Error" | tail -1)
      say "tank-3d, $threads threads, $layer, $load busy: ${line:-no result within 45 s}"
    done
  done
  busy_stop
done
for threads in 2 16; do
  say "== jellysim run dam-break-2d, duration 0.1 s, NUMBA_NUM_THREADS=$threads"
  NUMBA_NUM_THREADS=$threads $py benchmarks/bench_threads.py --set duration=0.1 --timeout 40 \
    --load 0 --load 16 2>&1 | tee -a "$log"
done
say "== done"
