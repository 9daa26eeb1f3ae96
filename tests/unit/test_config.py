"""Scene configuration: the generated reference, field metadata, TOML round trip, overrides."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from jellysim.config import (
    Scene,
    apply_overrides,
    load_scene,
    parse_override,
    scene_from_tree,
    scene_to_toml,
)
from jellysim.config.docs import scene_reference
from jellysim.config.load import parse_toml, scene_to_tree
from jellysim.config.schema import SECTIONS
from jellysim.errors import InputError
from jellysim.species import preset_names

REPO = Path(__file__).resolve().parents[2]
KINDS = {
    "float",
    "int",
    "str",
    "choice",
    "vec3",
    "direction",
    "bool",
    "color",
    "angles",
    "boxes",
    "points",
}


def _value_fields() -> list[tuple[str, dataclasses.Field[object]]]:
    fields = [
        (f.name, f)
        for f in dataclasses.fields(Scene)
        if f.name not in SECTIONS and not f.metadata.get("internal")
    ]
    for section, cls in SECTIONS.items():
        fields += [(f"{section}.{f.name}", f) for f in dataclasses.fields(cls)]
    return fields


def test_scene_reference_is_up_to_date() -> None:
    written = (REPO / "docs" / "scene.md").read_text(encoding="utf-8")
    assert written == scene_reference(), (
        "docs/scene.md is stale; regenerate it with "
        "'python -m jellysim.config.docs > docs/scene.md'"
    )


def test_scene_reference_lists_every_key() -> None:
    reference = scene_reference()
    for key, _ in _value_fields():
        assert f"| `{key}` |" in reference


@pytest.mark.parametrize(("key", "f"), _value_fields(), ids=[k for k, _ in _value_fields()])
def test_every_field_has_doc_and_kind(key: str, f: dataclasses.Field[object]) -> None:
    assert f.metadata.get("doc", "").strip(), f"{key} has no doc"
    assert f.metadata.get("kind") in KINDS, f"{key} has no valid kind"
    if f.metadata["kind"] == "choice":
        assert f.metadata["choices"], f"{key} has no choices"


def test_sections_match_scene_fields() -> None:
    sections = [
        f.name
        for f in dataclasses.fields(Scene)
        if "kind" not in f.metadata and not f.metadata.get("internal")
    ]
    assert sections == list(SECTIONS)


@pytest.mark.parametrize("name", preset_names())
def test_preset_round_trips_through_toml(name: str) -> None:
    scene = load_scene(name)
    text = scene_to_toml(scene)
    assert scene_from_tree(parse_toml(text, "round trip")) == scene
    assert load_scene(scene) == scene


def test_round_trip_keeps_unset_and_explicit_tentacle_density() -> None:
    unset = Scene()
    assert unset.tentacles.density is None
    assert scene_from_tree(parse_toml(scene_to_toml(unset), "t")) == unset
    assert unset.tentacle_density == unset.water.density
    heavy = load_scene({"tentacles": {"density": 1100}})
    assert scene_from_tree(parse_toml(scene_to_toml(heavy), "t")) == heavy
    assert heavy.tentacle_density == 1100.0


@pytest.mark.parametrize(
    ("item", "key", "value"),
    [
        ("duration=2", "duration", 2),
        ("tentacles.youngs_modulus=1e5", "tentacles.youngs_modulus", 1.0e5),
        ("flow.speed=-0.25", "flow.speed", -0.25),
        ("water.gravity=[0, 0, -9.81]", "water.gravity", [0, 0, -9.81]),
        ("water.gravity=[0,-9.81,0]", "water.gravity", [0, -9.81, 0]),
        ("flag=true", "flag", True),
        ("flag=false", "flag", False),
        ('name="my scene"', "name", "my scene"),
        ("name='x'", "name", "x"),
        ("tentacles.root=pinned", "tentacles.root", "pinned"),
        ("tentacles.bending=euler-bernoulli", "tentacles.bending", "euler-bernoulli"),
        ("root_motion.direction=radial", "root_motion.direction", "radial"),
        (" duration = 3 ", "duration", 3),
        ('name="a=b"', "name", "a=b"),
        ("look.bell_color=#ff9040", "look.bell_color", "#ff9040"),  # docs/rendering.md
    ],
)
def test_parse_override(item: str, key: str, value: object) -> None:
    parsed_key, parsed = parse_override(item)
    assert parsed_key == key
    assert parsed == value
    assert type(parsed) is type(value)


def test_parse_override_reads_nan_and_inf_as_floats() -> None:
    assert math.isnan(parse_override("duration=nan")[1])
    assert parse_override("duration=inf")[1] == math.inf


def test_a_hex_colour_on_the_command_line_is_the_colour() -> None:
    """``--set look.bell_color=#ff9040`` (docs/rendering.md): TOML would read a comment."""
    scene = load_scene("brown-jelly", ["look.bell_color=#ff9040"])
    expected = load_scene("brown-jelly", {"look.bell_color": "#ff9040"}).look.bell_color
    assert scene.look.bell_color == expected
    assert expected != load_scene("brown-jelly").look.bell_color


@pytest.mark.parametrize(
    "item", ["duration", "=3", "duration=1.2.3", "name=two words", "look.bell_color=#ff90"]
)
def test_parse_override_rejects(item: str) -> None:
    with pytest.raises(InputError):
        parse_override(item)


def test_overrides_on_nested_keys() -> None:
    scene = load_scene(
        Scene(),
        [
            "tentacles.youngs_modulus=1e5",
            "tentacles.root=pinned",
            "water.gravity=[0, -9.81, 0]",
            "root_motion.direction=[1, 0, 0]",
            "duration=2",
        ],
    )
    assert scene.tentacles.youngs_modulus == 1.0e5
    assert scene.tentacles.root == "pinned"
    assert scene.water.gravity == (0.0, -9.81, 0.0)
    assert scene.root_motion.direction == (1.0, 0.0, 0.0)
    assert scene.duration == 2.0 and isinstance(scene.duration, float)
    # untouched keys keep their values
    assert scene.tentacles.count == Scene().tentacles.count
    assert scene.water.density == Scene().water.density


def test_overrides_as_mapping_and_on_presets() -> None:
    name = preset_names()[0]
    base = load_scene(name)
    scene = load_scene(name, {"tentacles.count": 2, "flow.noise": 0.0})
    assert scene.tentacles.count == 2
    assert scene.flow.noise == 0.0
    assert scene.tentacles.particles == base.tentacles.particles
    assert scene.name == base.name


def test_apply_overrides_does_not_change_its_input() -> None:
    tree = {"tentacles": {"count": 3}}
    result = apply_overrides(tree, {"tentacles.count": 4, "water.density": 1020.0})
    assert tree == {"tentacles": {"count": 3}}
    assert result == {"tentacles": {"count": 4}, "water": {"density": 1020.0}}


@pytest.mark.parametrize(
    ("overrides", "named"),
    [
        ({"tentacles.cout": 3}, "did you mean 'count'"),
        ({"durtion": 3}, "did you mean 'duration'"),
        ({"tentacles": 3}, "tentacles"),
        ({"tentacles.count.x": 3}, "count"),
    ],
)
def test_bad_override_keys(overrides: dict[str, object], named: str) -> None:
    with pytest.raises(InputError, match=named):
        apply_overrides({}, overrides)


def test_override_below_a_non_table_is_an_input_error() -> None:
    with pytest.raises(InputError, match=r"tentacles must be a table"):
        apply_overrides({"tentacles": 3}, {"tentacles.count": 2})


@pytest.mark.parametrize(
    ("tree", "named"),
    [
        ({"tentacles": {"youngs_modulus": 10**400}}, "tentacles.youngs_modulus"),
        ({"seed": 2**64}, "seed"),
        ({"name": "abc\n"}, "name"),
        ({"water": {"density": True}}, "water.density = true"),
        ({"water": {"gravity": [0, True, 0]}}, r"\[0, true, 0\]"),
        ({"root_motion": {"direction": [0, 0, 0]}}, "root_motion.direction"),
    ],
)
def test_invalid_values(tree: dict[str, object], named: str) -> None:
    with pytest.raises(InputError, match=named) as info:
        scene_from_tree(tree)
    assert len(str(info.value).splitlines()) == 1


def test_largest_int64_seed_is_accepted() -> None:
    assert scene_from_tree({"seed": 2**63 - 1}).seed == 2**63 - 1


def test_error_messages_stay_on_one_line() -> None:
    with pytest.raises(InputError) as info:
        apply_overrides({}, {"a\nb\nc\nd": 1})
    assert "\n" not in str(info.value)
    with pytest.raises(InputError) as info:
        load_scene("x\ny\nz\nw")
    assert "\n" not in str(info.value)


def test_toml_syntax_error_names_the_line() -> None:
    with pytest.raises(InputError, match=r"f\.toml: .*line 2"):
        parse_toml("duration = 1\nfps = = 3\n", "f.toml")
    with pytest.raises(InputError, match=r"f\.toml: .*line 3"):
        parse_toml("duration = 1\n\nx = [\n", "f.toml")


@pytest.mark.parametrize(
    ("duration", "fps", "frames"),
    [(10.0, 30.0, 301), (0.1, 30.0, 4), (1.0, 7.0, 8), (0.05, 30.0, 3), (2.5, 1.0, 3)],
)
def test_frame_count(duration: float, fps: float, frames: int) -> None:
    scene = load_scene(Scene(), {"duration": duration, "fps": fps})
    assert scene.frame_count == round(duration * fps) + 1 == frames


def test_scene_to_tree_omits_unset_keys_and_writes_lists() -> None:
    tree = scene_to_tree(Scene())
    assert "density" not in tree["tentacles"]
    assert tree["water"]["gravity"] == [0.0, 0.0, -9.81]


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        ("#ff8000", (1.0, ((128 / 255 + 0.055) / 1.055) ** 2.4, 0.0)),  # sRGB, decoded
        ([0.1, 0.2, 0.3], (0.1, 0.2, 0.3)),
        ([0, 1, 0], (0.0, 1.0, 0.0)),
    ],
)
def test_colors_read_as_hex_or_rgb(value: object, expected: tuple[float, float, float]) -> None:
    scene = load_scene("brown-jelly", {"look.bell_color": value})
    assert scene.look.bell_color == pytest.approx(expected)


@pytest.mark.parametrize("value", ["#ff80", "orange", [0.1, 0.2], [0.1, 0.2, 1.5], [True, 0, 0]])
def test_bad_colors_are_refused(value: object) -> None:
    with pytest.raises(InputError, match="look.bell_color"):
        load_scene("brown-jelly", {"look.bell_color": value})


def test_a_recorded_soft_bell_without_root_placement_hung_its_roots_from_the_particles() -> None:
    """Scene texts written before ``bell.root_placement`` (issue 25) are read as the runs that
    wrote them ran: a mass-spring bell's roots at its particles, not the "edge" default; a
    kinematic bell's text is left alone (the key does nothing there), and a recorded key is kept
    (a text of the "surface" days reads as "surface")."""
    from jellysim.config.load import recorded_tree, same_scene

    soft = load_scene("moon-jelly")
    text = scene_to_toml(soft)
    assert 'root_placement = "edge"' in text
    old = text.replace('root_placement = "edge"\n', "")
    assert scene_from_tree(recorded_tree(old)).bell.root_placement == "particles"
    assert scene_from_tree(recorded_tree(text)).bell.root_placement == "edge"
    surface = text.replace('root_placement = "edge"', 'root_placement = "surface"')
    assert scene_from_tree(recorded_tree(surface)).bell.root_placement == "surface"
    assert not same_scene(old, text)
    assert not same_scene(surface, text)
    kinematic = scene_to_toml(load_scene("brown-jelly"))
    assert same_scene(kinematic.replace('root_placement = "edge"\n', ""), kinematic)
    # where the key does nothing, a text of the "surface" days is today's scene (it resumes)
    for name in ("brown-jelly", "dam-break-2d"):
        text = scene_to_toml(load_scene(name))
        assert same_scene(text.replace('"edge"', '"surface"'), text), name


def test_a_recorded_soft_bell_without_arm_anchor_hung_its_arms_from_the_margin_plane() -> None:
    """Scene texts written before ``bell.arm_anchor`` (issue 25) are read as the runs that wrote
    them ran: a mass-spring bell's oral arms on the margin plane, not from the "subumbrella"
    default; a recorded key is kept; where the bell is not a mass-spring one the key does
    nothing and a text without it is today's scene."""
    from jellysim.config.load import recorded_tree, same_scene

    text = scene_to_toml(load_scene("moon-jelly"))
    assert 'arm_anchor = "subumbrella"' in text
    old = text.replace('arm_anchor = "subumbrella"\n', "")
    assert scene_from_tree(recorded_tree(old)).bell.arm_anchor == "margin"
    assert scene_from_tree(recorded_tree(text)).bell.arm_anchor == "subumbrella"
    plane = text.replace('arm_anchor = "subumbrella"', 'arm_anchor = "margin"')
    assert scene_from_tree(recorded_tree(plane)).bell.arm_anchor == "margin"
    assert same_scene(old, plane)
    assert not same_scene(old, text)
    for name in ("brown-jelly", "purple-jelly", "dam-break-2d"):
        text = scene_to_toml(load_scene(name))
        assert same_scene(text.replace('arm_anchor = "subumbrella"\n', ""), text), name
        assert same_scene(text.replace('"subumbrella"', '"margin"'), text), name
