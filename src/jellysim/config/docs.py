"""The scene reference ``docs/scene.md``, generated from the field metadata of the schema.

Regenerate with ``python -m jellysim.config.docs > docs/scene.md``; a unit test checks that the
file in the repository equals :func:`scene_reference`, so the reference cannot drift from the code.
"""

from __future__ import annotations

import dataclasses
import sys
from typing import Any

import tomli_w

from jellysim.config.load import allowed
from jellysim.config.schema import SECTIONS, Scene

PREAMBLE = """\
# Scene reference

<!-- Generated from src/jellysim/config/schema.py by
     `python -m jellysim.config.docs > docs/scene.md`; do not edit by hand. -->

A scene is a TOML file (or a preset: `jellysim presets` lists them, `jellysim show NAME` prints
one) with the top-level keys below and one table per section. Every key is optional; a missing
key takes its default.

- SI units everywhere. Jellyfish scenes are 3-D with z up: the bell swims towards +z and the
  tentacles hang towards -z.
- `jellysim run SCENE --set KEY=VALUE` overrides any key, dotted for keys in a table
  (`--set tentacles.youngs_modulus=1e5`). VALUE is read as a TOML value; a bare word is taken as
  a string (`--set tentacles.root=pinned`), and a list needs quoting from the shell
  (`--set 'water.gravity=[0, 0, -9.81]'`).
- Unknown keys are errors, with a did-you-mean suggestion; so is any value outside its allowed
  range. Invalid input exits with status 2 and writes nothing.
- `tentacles.density` left unset means the water density (`water.density`): neutrally buoyant
  tentacles, on which gravity does not act.
- **Tentacle groups** (docs/groups.md): a jellyfish may carry several groups of tentacles
  (marginal tentacles, oral arms, ...), each a sub-table `[tentacles.NAME]` that takes every
  `[tentacles]` key below. Keys written in `[tentacles]` itself are then shared: each group
  inherits those it does not set. `--set tentacles.NAME.KEY=VALUE` sets a key of one group
  (`--set tentacles.arms.youngs_modulus=5e6`); `--set` never adds a group. A scene with a plain
  `[tentacles]` table and no sub-tables has one group, named `tentacles`.
"""


def _default(f: dataclasses.Field[Any]) -> str:
    if f.metadata.get("kind") == "points":
        return "none"
    if f.default is not dataclasses.MISSING:
        value = f.default
    else:
        assert f.default_factory is not dataclasses.MISSING
        value = f.default_factory()
    return "unset" if value is None else f"`{_toml_value(value)}`"


def _toml_value(value: Any) -> str:
    """A default as written in a scene file (inline, unlike tomli_w's multi-line arrays)."""
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    text: str = tomli_w.dumps({"v": value})
    return text[len("v = ") :].strip()


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _table(title: str, cls: type, prefix: str) -> list[str]:
    lines = [
        f"## {title}",
        "",
        "| key | allowed values | unit | default | description |",
        "| --- | --- | --- | --- | --- |",
    ]
    for f in dataclasses.fields(cls):
        if (f.name in SECTIONS and cls is Scene) or f.metadata.get("internal"):
            continue
        meta = f.metadata
        cells = (
            f"`{prefix}{f.name}`",
            allowed(meta),
            meta["unit"] or "-",
            _default(f),
            meta["doc"],
        )
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return [*lines, ""]


def scene_reference() -> str:
    """The Markdown reference of every scene key: allowed values, unit, default, description."""
    lines = [PREAMBLE, *_table("Top level", Scene, "")]
    for name, cls in SECTIONS.items():
        lines += _table(f"[{name}]", cls, f"{name}.")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.stdout.write(scene_reference())
