"""A JSON Schema of scene files, for editors (issue 27): generated from the same field metadata
as the loader's checks and docs/scene.md.

``jellysim schema > scene.schema.json`` writes it; a TOML editor with schema support (Taplo, the
"Even Better TOML" extension of VS Code) then completes keys, shows each key's unit, default and
meaning, and flags a wrong value as it is typed, when the scene file begins with
``#:schema ./scene.schema.json``. The schema says what one key may hold; what keys must agree on
(a current's direction, arms that fit under the bell, ...) stays the loader's, which has the last
word and exits 2 with one line.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from typing import Any

from jellysim.config.schema import SECTIONS, Scene

DRAFT = "https://json-schema.org/draft/2020-12/schema"
NUMBER = {"type": "number"}


def _bounds(meta: dict[str, Any]) -> dict[str, Any]:
    words = {"gt": "exclusiveMinimum", "ge": "minimum", "lt": "exclusiveMaximum", "le": "maximum"}
    return {word: meta[key] for key, word in words.items() if key in meta}


def _vector(length: int, item: dict[str, Any]) -> dict[str, Any]:
    return {"type": "array", "items": item, "minItems": length, "maxItems": length}


def value_schema(meta: dict[str, Any]) -> dict[str, Any]:
    """The JSON Schema of one key's value, from its ``param`` metadata (config/schema.py)."""
    kind = meta["kind"]
    if kind == "choice":
        return {"type": "string", "enum": list(meta["choices"])}
    if kind == "str":
        return {"type": "string", "pattern": meta.get("pattern", ".*")}
    if kind == "bool":
        return {"type": "boolean"}
    if kind == "vec3":
        return _vector(3, NUMBER)
    if kind == "direction":
        return {"anyOf": [{"const": "radial"}, _vector(3, NUMBER)]}
    if kind == "color":
        unit = {"type": "number", "minimum": 0.0, "maximum": 1.0}
        return {"anyOf": [_vector(3, unit), {"type": "string", "pattern": "^#[0-9A-Fa-f]{6}$"}]}
    if kind == "angles":
        degrees = {"type": "number", "minimum": -360.0, "maximum": 360.0}
        return {"type": "array", "items": degrees, "minItems": 1, "maxItems": 100_000}
    if kind == "boxes":
        return {"type": "array", "items": _vector(6, NUMBER), "maxItems": 1000}
    if kind == "points":
        point = {"type": "array", "items": NUMBER, "minItems": 1, "maxItems": 3}
        return {
            "type": "object",
            "propertyNames": {"pattern": "^[A-Za-z0-9_-]{1,64}$"},
            "additionalProperties": point,
            "maxProperties": 1000,
        }
    return {"type": "integer" if kind == "int" else "number", **_bounds(meta)}


def _key_schema(f: dataclasses.Field[Any]) -> dict[str, Any]:
    meta = dict(f.metadata)
    schema = value_schema(meta)
    unit = f" [{meta['unit']}]" if meta.get("unit") else ""
    schema["description"] = meta["doc"] + unit
    default = f.default if f.default is not dataclasses.MISSING else None
    if f.default_factory is not dataclasses.MISSING:
        default = f.default_factory()
    if meta["kind"] == "points":
        schema["default"] = {}
    elif default is not None:  # unset in TOML: the key is left out
        schema["default"] = list(default) if isinstance(default, tuple) else default
    return schema


def _table(cls: type) -> dict[str, Any]:
    keys = {f.name: _key_schema(f) for f in dataclasses.fields(cls)}
    return {"type": "object", "properties": keys, "additionalProperties": False}


def scene_schema() -> dict[str, Any]:
    """The JSON Schema of a scene file: top-level keys, one table per section, and in
    ``[tentacles]`` any number of named groups ``[tentacles.NAME]`` taking the same keys."""
    top = {
        f.name: _key_schema(f)
        for f in dataclasses.fields(Scene)
        if f.name not in SECTIONS and not f.metadata.get("internal")
    }
    sections = {name: _table(cls) for name, cls in SECTIONS.items()}
    tentacles = sections["tentacles"]
    tentacles["additionalProperties"] = {**_table(SECTIONS["tentacles"]), "description": (
        "a tentacle group [tentacles.NAME]: every [tentacles] key; those left out are inherited "
        "from [tentacles] (docs/groups.md)"
    )}  # fmt: skip
    return {
        "$schema": DRAFT,
        "title": "jellysim scene",
        "description": "A jellysim scene file (TOML; docs/scene.md). SI units, z up.",
        "type": "object",
        "properties": {**top, **sections},
        "additionalProperties": False,
    }


def main() -> None:
    json.dump(scene_schema(), sys.stdout, indent=2)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
