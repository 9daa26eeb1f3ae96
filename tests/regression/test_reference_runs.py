"""Behaviour unchanged: every reference case re-run and compared with its stored result bit for bit
(every dataset, its units and every root attribute but the version).

The references were stored by ``make_reference.py`` before issue 23's re-layout of the simulation
loops began, and stored again (each time said so in its commit) where a change of behaviour was
meant; a difference here means a change altered what a run computes. They hold on the tests'
pinned floating-point path (``tests/pinning.py``), the same on every x86-64-v3 host.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pinning import NOT_PINNED, PINNED

from regression.cases import CASES
from regression.compare import REFERENCE_FOLDER, differences, read_all, run_case


@pytest.mark.skipif(not PINNED, reason=NOT_PINNED)
@pytest.mark.parametrize("name", list(CASES))
def test_reference_run_is_bit_for_bit(name: str, tmp_path: Path) -> None:
    with np.load(REFERENCE_FOLDER / f"{name}.npz") as stored:
        expected = dict(stored)
    actual = read_all(run_case(name, tmp_path))
    assert len(expected) > 0
    assert differences(expected, actual) == []


def test_comparison_sees_one_ulp() -> None:
    expected = {"data:x": np.array([1.0, 2.0]), "attr:n": np.array(3)}
    nudged = {"data:x": np.array([1.0, np.nextafter(2.0, 3.0)]), "attr:n": np.array(3)}
    assert differences(expected, dict(expected)) == []
    assert differences(expected, nudged) == ["data:x: differs by up to 4.44e-16 (values up to 2)"]
    assert differences(expected, {"data:x": expected["data:x"]}) == ["missing: attr:n"]
