"""Store the reference runs of ``cases.py`` under ``reference/`` (one ``.npz`` per case).

Run once, before a behaviour-preserving change, from the repository root:
``.venv/bin/python tests/regression/make_reference.py [CASE ...]``. Re-storing a reference is a
deliberate change of behaviour and is said so in its commit. The runs take the tests' pinned
floating-point path (``tests/pinning.py``).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: scenes.py, pinning.py

from pinning import NOT_PINNED, PINNED  # noqa: E402, I001  (first: before NumPy loads)

import numpy as np  # noqa: E402
from regression.cases import CASES  # noqa: E402
from regression.compare import REFERENCE_FOLDER, read_all, run_case  # noqa: E402


def main(names: list[str]) -> None:
    if not PINNED:
        sys.exit(f"not stored: {NOT_PINNED}")
    REFERENCE_FOLDER.mkdir(exist_ok=True)
    for name in names or list(CASES):
        with tempfile.TemporaryDirectory() as folder:
            values = read_all(run_case(name, Path(folder)))
        np.savez_compressed(REFERENCE_FOLDER / f"{name}.npz", **values)
        print(f"{name}: {len(values)} arrays")


if __name__ == "__main__":
    main(sys.argv[1:])
