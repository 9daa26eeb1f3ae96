#!/usr/bin/env bash
# GNU OpenMP's wait policy on a 16-core machine (issue 24; after threads_16core.sh showed the
# omp layer collapsing on 16 threads when 16 other processes share the cores).
#   bash benchmarks/threads_omp_wait.sh LOG
set -u
log=${1:-/dev/stdout}
py=${PYTHON:-python3}
say() { echo "$@" | tee -a "$log"; }
$py -m jellysim run dam-break-2d --out /tmp/warm2d --force --set duration=0.002 >/dev/null 2>&1 &
$py benchmarks/bench_fluid.py --case tank-3d --steps 1 --threads 16 >/dev/null 2>&1
wait
tank() {  # label, then environment assignments
  local label=$1; shift
  line=$(env "$@" timeout 45 $py benchmarks/bench_fluid.py --case tank-3d --steps 20 --threads 16 \
    2>&1 | grep -oE "[0-9.]+ steps/s.*solve [0-9]+ ms|Error.*" | tail -1)
  say "tank-3d, 16 threads, $label: ${line:-no result within 45 s}"
}
dam() {
  local label=$1; shift
  start=$(date +%s%N)
  if env "$@" NUMBA_NUM_THREADS=16 timeout 40 $py -m jellysim run dam-break-2d --out /tmp/d2 --force \
    --set duration=0.1 >/dev/null 2>&1; then
    say "dam-break-2d run, 16 threads, $label: $(( ($(date +%s%N) - start) / 1000000 )) ms"
  else say "dam-break-2d run, 16 threads, $label: no exit within 40 s"; fi
}
tank "omp, idle" NUMBA_THREADING_LAYER=omp
tank "omp passive, idle" NUMBA_THREADING_LAYER=omp OMP_WAIT_POLICY=passive
dam "omp passive, idle" NUMBA_THREADING_LAYER=omp OMP_WAIT_POLICY=passive
for _ in $(seq 16); do $py -c "while True: pass" & done
tank "omp passive, 16 busy" NUMBA_THREADING_LAYER=omp OMP_WAIT_POLICY=passive
tank "workqueue, 16 busy" NUMBA_THREADING_LAYER=workqueue
tank "omp, 16 busy" NUMBA_THREADING_LAYER=omp
dam "omp passive, 16 busy" NUMBA_THREADING_LAYER=omp OMP_WAIT_POLICY=passive
jobs -p | xargs -r kill; wait 2>/dev/null
say "== done"
