"""Presets as data files (TOML, every value with its source in a comment)."""

from __future__ import annotations

from importlib import resources

from jellysim.config.load import Tree, parse_toml


def preset_names() -> list[str]:
    """Names of the bundled presets, sorted."""
    folder = resources.files("jellysim.species") / "presets"
    return sorted(p.name[: -len(".toml")] for p in folder.iterdir() if p.name.endswith(".toml"))


def preset_text(name: str) -> str:
    """The preset's TOML text, comments and sources included."""
    return (resources.files("jellysim.species") / "presets" / f"{name}.toml").read_text("utf-8")


def preset_tree(name: str) -> Tree:
    return parse_toml(preset_text(name), f"preset '{name}'")


def preset_summary(name: str) -> str:
    """The first comment line of the preset: what it is."""
    for line in preset_text(name).splitlines():
        if line.startswith("#"):
            return line.lstrip("# ").strip()
    return ""
