"""Scenes: parameters as frozen dataclasses, read from TOML or presets, validated."""

from jellysim.config.load import (
    apply_overrides,
    parse_override,
    scene_from_tree,
    scene_to_toml,
    scene_to_tree,
)
from jellysim.config.scenes import load_scene, scene_source_tree
from jellysim.config.schema import Scene

__all__ = [
    "Scene",
    "apply_overrides",
    "load_scene",
    "parse_override",
    "scene_from_tree",
    "scene_source_tree",
    "scene_to_toml",
    "scene_to_tree",
]
