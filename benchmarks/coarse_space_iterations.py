"""Iterations of the GPU's pressure preconditioners, counted on the CPU (issue 28): on the PPE
of a case of ``bench_gpu.py`` after three steps from rest, CG to the scene's tolerance with
Jacobi (the GPU's solver for ``fluid.solver`` other than "deflated") and with the additive
two-level preconditioner ``D^-1 + Z E^-1 Z^T`` (docs/theory/fluid.md F12b) on cubic aggregates
CELL l0 wide, its E^-1 made from that step's system ("fresh") or from the system of the first
step counted ("stale"), from zero ("cold") and from the last pressure ("warm").

    .venv/bin/python benchmarks/coarse_space_iterations.py CASE [CELL] [STEPS,STEPS...]

A SciPy model of the preconditioner, not the package's GPU kernels: the iteration counts are
the algorithm's (the GPU's aggregates are blocks of search cells, not cubes of CELL l0). The
table in docs/performance.md was measured with it.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import scipy.linalg
import scipy.sparse

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_gpu import CASES  # noqa: E402

import jellysim  # noqa: E402
from jellysim.simulation.fluid import FluidSimulation  # noqa: E402

Preconditioner = Callable[[np.ndarray], np.ndarray]


def pcg(
    a: scipy.sparse.csr_matrix, b: np.ndarray, x0: np.ndarray, m: Preconditioner, tol: float
) -> int:
    """Preconditioned CG's iterations to ``|b - A x| <= tol |b|``."""
    x = x0.copy()
    r = b - a @ x
    z = m(r)
    d = z.copy()
    rz = r @ z
    norm_b = np.linalg.norm(b)
    iterations = 0
    while np.linalg.norm(r) > tol * norm_b and iterations < 5000:
        q = a @ d
        alpha = rz / (d @ q)
        x += alpha * d
        r -= alpha * q
        z = m(r)
        rz_new = r @ z
        d = z + (rz_new / rz) * d
        rz = rz_new
        iterations += 1
    return iterations


def main() -> None:
    case = sys.argv[1]
    cell_l0 = float(sys.argv[2]) if len(sys.argv) > 2 else 4.0
    later = [int(s) for s in sys.argv[3].split(",")] if len(sys.argv) > 3 else [5, 20]
    preset, overrides = CASES[case]
    solver = FluidSimulation(jellysim.load_scene(preset, overrides)).solver
    tolerance = solver.params.tolerance
    origin = solver.domain_min
    size = cell_l0 * solver.params.l0
    shape = np.ceil((solver.domain_max - solver.domain_min) / size).astype(int) + 1

    def system() -> tuple[scipy.sparse.csr_matrix, np.ndarray, np.ndarray, np.ndarray]:
        s = solver.poisson_system(solver.stable_dt())
        m, n = s.matrix, s.rhs.size
        end = m.indptr[-1]
        a = scipy.sparse.csr_matrix((m.data[:end], m.indices[:end], m.indptr), shape=(n, n))
        if m.diagonal_value.size:  # fluid.matrix_precision "single": the diagonal apart
            a = (a.astype(np.float64) + scipy.sparse.diags(m.diagonal_value)).tocsr()
        return a, s.rhs.copy(), solver.position[s.particles], solver.pressure[s.particles]

    def keys(position: np.ndarray) -> np.ndarray:
        cell = np.clip(np.floor((position - origin) / size).astype(int), 0, shape - 1)
        return np.ravel_multi_index(tuple(cell.T), tuple(shape))

    def coarse(a: scipy.sparse.csr_matrix, position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cells, local = np.unique(keys(position), return_inverse=True)
        n = len(local)
        z = scipy.sparse.csr_matrix((np.ones(n), (np.arange(n), local)), shape=(n, len(cells)))
        return cells, scipy.linalg.inv((z.T @ a @ z).toarray())

    def two_level(a, position, cells, inverse) -> Preconditioner:  # noqa: ANN001
        inverse_diagonal = 1.0 / a.diagonal()
        k = keys(position)
        where = np.clip(np.searchsorted(cells, k), 0, len(cells) - 1)
        rows = np.flatnonzero(cells[where] == k)  # rows in aggregates the E^-1 knows
        z = scipy.sparse.csr_matrix(
            (np.ones(len(rows)), (rows, where[rows])), shape=(len(k), len(cells))
        )
        return lambda r: inverse_diagonal * r + z @ (inverse @ (z.T @ r))

    for _ in range(3):
        solver.step(solver.stable_dt())
    a0, b0, position0, _ = system()
    cells0, inverse0 = coarse(a0, position0)
    print(f"{case}: {len(b0)} rows, {len(cells0)} aggregates of {cell_l0:g} l0", flush=True)
    done = 0
    for target in [0, *later]:
        while done < target:
            solver.step(solver.stable_dt())
            done += 1
        a, b, position, warm = system()
        cells, inverse = coarse(a, position)
        jacobi_inverse = 1.0 / a.diagonal()
        row = []
        for start, x0 in (("cold", np.zeros_like(b)), ("warm", warm)):
            counts = (
                pcg(a, b, x0, lambda r, d=jacobi_inverse: d * r, tolerance),
                pcg(a, b, x0, two_level(a, position, cells, inverse), tolerance),
                pcg(a, b, x0, two_level(a, position, cells0, inverse0), tolerance),
            )
            row.append(f"{start}: Jacobi {counts[0]}, fresh {counts[1]}, stale {counts[2]}")
        print(f"  step +{target} ({len(cells)} aggregates): " + "; ".join(row), flush=True)


if __name__ == "__main__":
    main()
