"""Physics imports nothing above it (issue 23, docs/architecture.md "Layers").

Every module of ``src/jellysim`` is read (its imports, those inside functions included) and each
``jellysim`` import must name a package of the same layer or a lower one. The layers, lowest
first, are those of docs/architecture.md.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "src" / "jellysim"
FACE = "(package face)"

LAYERS: list[set[str]] = [
    {"_threads", "_version", "errors", "fields", "progress", "reference"},  # neutral
    {"config", "species"},  # scenes
    {"tentacle", "fluid", "bell", "interpolation"},  # physics and render-time geometry
    {"coupling"},  # bodies joined: the bell in its water, the recorded margin
    {"io"},  # result store, checkpoints, figures
    {"simulation", "render"},  # frame loops, runs and their cost estimate (estimate.py); pictures
    {"studies", "export", "view"},  # sweeps, files for other tools, the viewer
    {"cli", "__main__", FACE},  # the command line and the Python API face
]
LAYER = {name: level for level, names in enumerate(LAYERS) for name in names}


def package_of(module: str) -> str:
    """The top-level part of ``jellysim.<part>...`` (the face for ``jellysim`` itself)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else FACE


def imported_packages(source: str) -> set[str]:
    """The jellysim packages a module's source imports, at any depth of the code."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found |= {package_of(a.name) for a in node.names if a.name.startswith("jellysim")}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module == "jellysim":  # from jellysim import fields / __version__
                for alias in node.names:
                    is_module = (PACKAGE / f"{alias.name}.py").is_file() or (
                        PACKAGE / alias.name
                    ).is_dir()
                    found.add(alias.name if is_module else FACE)
            elif node.module.startswith("jellysim."):
                found.add(package_of(node.module))
    return found


def upward_imports(own: str, source: str) -> list[str]:
    """The packages ``source`` (of package ``own``) imports from above its layer."""
    level = LAYER[own]
    return sorted(name for name in imported_packages(source) if LAYER[name] > level)


MODULES = sorted(PACKAGE.rglob("*.py"))


def _own_package(path: Path) -> str:
    relative = path.relative_to(PACKAGE)
    if len(relative.parts) == 1:
        return FACE if relative.stem == "__init__" else relative.stem
    return relative.parts[0]


def test_every_package_has_a_layer() -> None:
    packages = {_own_package(path) for path in MODULES}
    assert packages - LAYER.keys() == set()


@pytest.mark.parametrize("path", MODULES, ids=[str(p.relative_to(PACKAGE)) for p in MODULES])
def test_no_module_imports_a_layer_above_its_own(path: Path) -> None:
    own = _own_package(path)
    assert upward_imports(own, path.read_text(encoding="utf-8")) == []


def test_the_check_sees_imports_inside_functions_and_through_the_face() -> None:
    source = (
        "from jellysim.fields import TIME\n"
        "def f():\n"
        "    from jellysim.io.result import Dataset\n"
        "    import jellysim.simulation.loop\n"
        "from jellysim import __version__\n"
    )
    assert upward_imports("bell", source) == sorted(["io", "simulation", FACE])
    assert upward_imports("cli", source) == []
