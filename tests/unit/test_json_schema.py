"""The JSON Schema of scene files (issue 27: a schema for editors) agrees with the loader: every
preset is valid under it, and values the loader refuses for a single key are invalid under it
too. Validated with the ``jsonschema`` library (Draft 2020-12)."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib

import jsonschema
import pytest

from jellysim.config.json_schema import scene_schema
from jellysim.config.scenes import scene_source_tree
from jellysim.errors import InputError
from jellysim.species import preset_names

SCHEMA = scene_schema()
VALIDATOR = jsonschema.Draft202012Validator(SCHEMA)


def test_the_schema_is_a_valid_draft_2020_12_schema() -> None:
    jsonschema.Draft202012Validator.check_schema(SCHEMA)


@pytest.mark.parametrize("preset", preset_names())
def test_every_preset_is_valid(preset: str) -> None:
    tree = scene_source_tree(preset)
    errors = [e.message for e in VALIDATOR.iter_errors(tree)]
    assert errors == []


BAD = {
    "unknown key": {"durtion": 2},
    "unknown table key": {"flow": {"sped": 1.0}},
    "out of range": {"tentacles": {"spacing": 0.0}},
    "wrong type": {"fps": "fast"},
    "not a choice": {"flow": {"model": "currant"}},
    "short vector": {"water": {"gravity": [0, -9.81]}},
    "colour out of range": {"look": {"bell_color": [1.5, 0, 0]}},
    "bad hex colour": {"look": {"bell_color": "#ff90"}},
    "a group key out of range": {"tentacles": {"arms": {"youngs_modulus": -1}}},
    "a group that is not a table": {"tentacles": {"arms": 3}},
    "integer expected": {"tentacles": {"count": 2.5}},
}


@pytest.mark.parametrize("tree", BAD.values(), ids=BAD)
def test_what_the_loader_refuses_the_schema_flags(tree: dict[str, object]) -> None:
    from jellysim.config.load import scene_from_tree

    assert list(VALIDATOR.iter_errors(tree)), tree
    with pytest.raises(InputError):
        scene_from_tree(tree)


def test_keys_carry_unit_default_and_meaning() -> None:
    speed = SCHEMA["properties"]["flow"]["properties"]["speed"]
    assert speed["default"] == 0.3 and "[m/s]" in speed["description"]
    group = SCHEMA["properties"]["tentacles"]["additionalProperties"]
    assert "youngs_modulus" in group["properties"]


def test_the_command_prints_the_schema() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "jellysim", "schema"], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == json.loads(json.dumps(SCHEMA))
    assert tomllib.loads("#:schema ./scene.schema.json\nduration = 1\n") == {"duration": 1}
