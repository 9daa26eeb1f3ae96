#!/usr/bin/env bash
# The GPU path measured on a machine with an NVIDIA GPU and 16 cores (issue 28;
# docs/performance.md), in parts, most wanted first:
#   tests      tests/gpu (the CPU comparisons at full size, two runs bit for bit, the coarse
#              space's iterations, the preset bell's springs; the slow ones are left out)
#   steps      bench_gpu.py: GPU steps/s at 57,600 (moon-jelly's water), 54,000 (tank-3d) and
#              1,024,000 fluid particles beside the CPU on 16 threads, the two paths' water
#              compared after 20 steps
#   moon-jelly the moon-jelly preset's bell and water (no tentacles) for three pulses on the GPU
#              (issue 28's 30 s), the springs on the GPU; per pulse contraction and rise
#   spheric    SPHERIC Test 2 at 1,121,729 fluid particles, its pressure probes read each step
#   threads    the 3-D tank's CPU step on 16, 8, 4, 2 and 1 threads (bench_fluid.py); with
#              BASELINE, that package's on 16 and 1; the parallel regions a step and one's
#              cost on 16 threads (parallel_regions.py, where a C compiler is)
#   dam-break  dam-break-2d run on the GPU and plotted against Martin & Moyce
#   warm       dam-break-2d on the GPU twice with a new NUMBA_CACHE_DIR: a machine's first run
#              (every kernel compiled, the CPU's too) against a later one (all from the cache)
#   fine       moon-jelly-fine for three pulses on the GPU (issue 28's 10 minutes: a session
#              of its own; the tests part leaves its test in tests/gpu out)
#   baseline   the steps part's GPU cases (no CPU) on another version's package, BASELINE (a
#              directory holding its src/jellysim, e.g. from `git archive COMMIT src | tar -x
#              -C .baseline`, carried): a comparison on the same card as the steps part
# Limits and options from the environment: TESTS_LIMIT (s, default 240), STEPS_LIMIT (s,
# default 220), CPU_THREADS (16), GPU_SOLVERS (e.g. "--gpu-solver deflated --gpu-solver cg":
# the steps part times the GPU with each pressure solver; default the presets'), GRID_BLOCKS
# (e.g. "--grid-blocks 132 --grid-blocks 264": the steps part times each cooperative grid cut
# to that many blocks too, after the GPU's most), PRECISIONS (e.g. "--precision double
# --precision single": each with fluid.matrix_precision so, in turn), THREADS (the
# threads part's counts, default "16 8 4 2 1"; THREAD_PRECISIONS, its matrix precisions,
# default "double", e.g. "double single"), CHUNKSIZE (its parallel loops' chunk size, 0);
# NUMBA_THREADING_LAYER=tbb with the tbb wheel carried compares TBB's dynamic scheduling.
#   bash benchmarks/gpu_device.sh OUTDIR [PART ...]   (no part: tests steps moon-jelly, about
#   9 minutes at most, which a 15-minute device session holds with its start)
# Each part has a time limit, so that one stuck part leaves the others' figures.
set -u
out=${1:-/tmp/gpu-device}
shift || true
parts=${*:-tests steps moon-jelly}
mkdir -p "$out"
py=${PYTHON:-python3}
export PYTHONUNBUFFERED=1
say() { echo "$@" | tee -a "$out/log"; }
say "== machine (parts: $parts)"
{ nproc; lscpu | grep -E "Model name|^CPU\(s\)"; nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv
  $py -c "import numba, numpy, sys; print('python', sys.version.split()[0], 'numba', numba.__version__, 'numpy', numpy.__version__)"
  $py -m pip show numba-cuda 2>/dev/null | grep -E "^Version"; } 2>&1 | tee -a "$out/log"
for part in $parts; do
  case $part in
    tests)
      say "== tests/gpu"
      JELLYSIM_TEST_GPU=1 timeout ${TESTS_LIMIT-240} $py -m pytest -q -p no:cacheprovider tests/gpu -k "not moon_jelly_fine" 2>&1 | tee "$out/tests.log" | tail -15 | tee -a "$out/log" ;;
    steps)
      say "== bench_gpu.py"
      timeout ${STEPS_LIMIT-220} $py benchmarks/bench_gpu.py --case moon-jelly-water --case tank-3d --case tank-3d-million --steps 20 --cpu-threads ${CPU_THREADS-16} --compare-steps 20 ${GPU_SOLVERS-} ${PRECISIONS-} ${GRID_BLOCKS-} 2>&1 | tee -a "$out/log" ;;
    moon-jelly)
      say "== moon-jelly, three pulses on the GPU (bell_pulses.py --full --pulses 3 --no-tentacles)"
      timeout 150 $py benchmarks/bell_pulses.py --full --pulses 3 --no-tentacles --set fluid.device='"cuda"' 2>&1 | tee "$out/moon-jelly.log" | grep -E "time per phase|as it is|pulse |Error|error" | tee -a "$out/log" ;;
    spheric)
      say "== bench_gpu.py --case spheric-test2-million"
      timeout 150 $py benchmarks/bench_gpu.py --case spheric-test2-million --steps 20 2>&1 | tee -a "$out/log" ;;
    threads)
      say "== CPU threads: bench_fluid.py --case tank-3d"
      for precision in ${THREAD_PRECISIONS-double}; do
      for threads in ${THREADS-16 8 4 2 1}; do
        timeout 50 $py benchmarks/bench_fluid.py --case tank-3d --steps 5 --threads $threads --chunksize ${CHUNKSIZE-0} --set fluid.matrix_precision=$precision 2>&1 | grep -E "steps/s|Error" | tail -1 | sed "s/^/$threads threads, $precision: /" | tee -a "$out/log"
      done; done
      if [ -d "${BASELINE-}/src/jellysim" ]; then  # the same cores on the baseline package
        for threads in 16 1; do
          PYTHONPATH="$(cd "$BASELINE" && pwd)/src:${PYTHONPATH-}" timeout 50 $py benchmarks/bench_fluid.py --case tank-3d --steps 5 --threads $threads 2>&1 | grep -E "steps/s|Error" | tail -1 | sed "s/^/baseline, $threads threads: /" | tee -a "$out/log"
        done
      fi
      if command -v cc >/dev/null || command -v gcc >/dev/null; then  # regions a step, and one's cost
        timeout 60 $py benchmarks/parallel_regions.py --threads 16 --steps 3 2>&1 | sed -n '1p;$p' | tee -a "$out/log"
      fi ;;
    dam-break)
      say "== jellysim run dam-break-2d --device cuda"
      ( time timeout 80 $py -m jellysim run dam-break-2d --device cuda --out /tmp/db2d --force ) 2>&1 | tail -8 | tee -a "$out/log"
      timeout 40 $py -m jellysim plot /tmp/db2d --out "$out/plots" 2>&1 | tail -5 | tee -a "$out/log" ;;
    warm)
      say "== the kernels' cache: jellysim run dam-break-2d --device cuda, a first and a second run"
      rm -rf "$out/numba-cache"  # a new cache: the first run compiles every kernel, CPU's and GPU's
      for run in first second; do
        ( time NUMBA_CACHE_DIR="$out/numba-cache" timeout 120 $py -m jellysim run dam-break-2d --device cuda --out /tmp/db2d-warm --force --quiet ) 2>&1 | grep -E "^real|Error|error" | sed "s/^/$run run: /" | tee -a "$out/log"
      done ;;
    fine)
      say "== moon-jelly-fine: three pulses, no tentacles (issue 28: at most 600 s; tests/gpu's test_moon_jelly_fine_* is the same run)"
      timeout 580 $py benchmarks/bell_pulses.py --full --preset moon-jelly-fine --pulses 3 --no-tentacles --set fluid.device='"cuda"' --out /tmp/fine-pulses 2>&1 | tee "$out/fine.log" | grep -E "time per phase|as it is|pulse |simulating|Error|error" | tail -12 | tee -a "$out/log" ;;
    baseline)
      say "== bench_gpu.py on the baseline package ${BASELINE-unset}"
      if [ -d "${BASELINE-}/src/jellysim" ]; then
        PYTHONPATH="$(cd "$BASELINE" && pwd)/src:${PYTHONPATH-}" timeout ${STEPS_LIMIT-220} $py benchmarks/bench_gpu.py --case moon-jelly-water --case tank-3d --case tank-3d-million --steps 20 ${GPU_SOLVERS-} 2>&1 | tee -a "$out/log"
      else
        say "no BASELINE/src/jellysim: set BASELINE to a carried directory"
      fi ;;
    *)
      say "unknown part: $part (tests steps moon-jelly spheric threads dam-break warm fine baseline)" ;;
  esac
done
say "== done"
