"""What a script sees (issue 27): the package says it is typed (PEP 561), and the parameter
sweep is part of the top-level API beside ``run`` and ``open_result``."""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

import jellysim


def test_the_package_is_marked_typed_and_ships_the_marker() -> None:
    assert resources.files("jellysim").joinpath("py.typed").is_file()
    pyproject = Path(__file__).resolve().parents[2] / "pyproject.toml"
    package_data = tomllib.loads(pyproject.read_text())["tool"]["setuptools"]["package-data"]
    assert "py.typed" in package_data["jellysim"]


def test_sweep_is_top_level() -> None:
    from jellysim.studies import sweep

    assert jellysim.sweep is sweep
    assert "sweep" in jellysim.__all__


def test_every_public_result_accessor_says_what_it_gives() -> None:
    """Result's properties and methods carry docstrings (the per-frame arrays with shape, dtype
    and unit, as ``time``: "(F,) float64, s")."""
    import inspect

    from jellysim.io.result import Result

    undocumented = []
    for name, member in inspect.getmembers(Result):
        if name.startswith("_"):
            continue
        target = member.fget if isinstance(member, property) else member
        if callable(target) and not (target.__doc__ or "").strip():
            undocumented.append(name)
    assert undocumented == []
