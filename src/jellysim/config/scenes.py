"""Building a scene from a preset name or a TOML path, with overrides."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from jellysim.config.load import (
    Tree,
    apply_overrides,
    parse_override,
    quote,
    read_scene_file,
    scene_from_tree,
    suggest,
)
from jellysim.config.schema import Scene
from jellysim.errors import InputError
from jellysim.species import preset_names, preset_tree


def scene_source_tree(source: str | Path) -> Tree:
    """The unvalidated tree of a preset name or a TOML file path."""
    text = str(source)
    if text in preset_names():
        return preset_tree(text)
    path = Path(text)
    if path.suffix.lower() == ".toml" or path.exists() or "/" in text:
        return read_scene_file(path)
    raise InputError(
        f"unknown preset {quote(text)}{suggest(text, preset_names())}; "
        f"presets: {', '.join(preset_names())} (or give a .toml file)"
    )


def load_scene(
    source: str | Path | Mapping[str, Any] | Scene,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
) -> Scene:
    """Load and validate a scene.

    ``source`` is a preset name, a TOML path, a nested mapping or a :class:`Scene`.
    ``overrides`` maps dotted keys to values (``{"tentacles.youngs_modulus": 1e5}``) or is a
    sequence of ``"KEY=VALUE"`` strings as on the command line.
    """
    if isinstance(source, Scene):
        from jellysim.config.load import scene_to_tree

        tree = scene_to_tree(source)
    elif isinstance(source, Mapping):
        tree = dict(source)
    else:
        tree = scene_source_tree(source)
    if overrides:
        pairs = (
            dict(parse_override(item) for item in overrides)
            if not isinstance(overrides, Mapping)
            else dict(overrides)
        )
        tree = apply_overrides(tree, pairs)
    return scene_from_tree(tree)
