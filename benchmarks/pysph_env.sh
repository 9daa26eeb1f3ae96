#!/usr/bin/env bash
# A separate virtual environment with PySPH 1.0b2, the peer of the MPS fluid benchmarks (issue 5).
#
#     benchmarks/pysph_env.sh [VENV]        # default .venv-pysph; then VENV/bin/pysph run dam_break_2d ...
#
# PySPH 1.0b2 (PyPI, source only) builds with Cython < 3 and NumPy < 2, and not as published:
# three lines of pysph/base/gpu_nnps_base.pyx read `ndarray.data`, which NumPy 1.26's headers
# hide; they are rewritten to `np.PyArray_DATA(...)`, the same pointer. Everything comes from
# PyPI; nothing of PySPH is vendored into jellysim.
set -euo pipefail
VENV=${1:-.venv-pysph}
PYTHON=${PYTHON:-python3}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

"$PYTHON" -m venv "$VENV"
VENV=$(cd "$VENV" && pwd)
"$VENV/bin/pip" install -q "cython==0.29.37" "numpy==1.26.4" "cyarray==1.2" "compyle==0.9.1" \
  mako pytools beaker setuptools wheel
"$VENV/bin/pip" download -q --no-deps --no-build-isolation "pysph==1.0b2" -d "$work"
tar -xzf "$work/pysph-1.0b2.tar.gz" -C "$work"
sed -i 's/<unsigned int\*> self\.\(_[a-z_]*\)\.data$/<unsigned int*> np.PyArray_DATA(self.\1)/' \
  "$work/pysph-1.0b2/pysph/base/gpu_nnps_base.pyx"
grep -c "np.PyArray_DATA" "$work/pysph-1.0b2/pysph/base/gpu_nnps_base.pyx" | grep -qx 3
(cd "$work/pysph-1.0b2" && "$VENV/bin/pip" install -q --no-build-isolation .)
"$VENV/bin/python" -c "import pysph; print('PySPH', pysph.__version__, 'in $VENV')"
