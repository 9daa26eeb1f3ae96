"""The points of a sweep: a grid (every combination of several keys' values) or a list (the
keys' values paired in order), read from the command line's ``KEY=V1,V2,...`` or from Python."""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from jellysim.config.load import parse_value
from jellysim.errors import InputError

Point = dict[str, Any]  # scene key -> value


@dataclass(frozen=True)
class Plan:
    """The swept ``keys`` (in the user's order) and the ``points``, each a value per key."""

    keys: tuple[str, ...]
    points: tuple[Point, ...]


def grid(axes: Mapping[str, Sequence[Any]], paired: bool = False) -> Plan:
    """Every combination of the keys' values (the first key varying slowest), or with
    ``paired`` the values taken together in order (every list of one length)."""
    if not axes:
        raise InputError("give at least one key to sweep, e.g. --vary flow.speed=0,0.3,0.6")
    for key, values in axes.items():
        if isinstance(values, str | bytes) or not isinstance(values, Sequence):
            raise InputError(f"{key}: the values must be a list, not {values!r}")
        if not values:
            raise InputError(f"{key}: give at least one value")
    keys = tuple(axes)
    if paired:
        lengths = {key: len(values) for key, values in axes.items()}
        if len(set(lengths.values())) > 1:
            told = ", ".join(f"{key} {n}" for key, n in lengths.items())
            raise InputError(f"--zip pairs the values in order, so each key needs as many: {told}")
        rows: Sequence[tuple[Any, ...]] = list(zip(*axes.values(), strict=True))
    else:
        rows = list(itertools.product(*axes.values()))
    return Plan(keys, tuple(dict(zip(keys, row, strict=True)) for row in rows))


def listed(points: Sequence[Mapping[str, Any]]) -> Plan:
    """A list of points given one by one, each naming the same keys."""
    if not points:
        raise InputError("give at least one point to sweep")
    keys = tuple(points[0])
    for number, point in enumerate(points):
        if set(point) != set(keys):
            raise InputError(
                f"point {number} sets {', '.join(sorted(point))}; every point must set the same "
                f"keys as the first ({', '.join(keys)})"
            )
    if not keys:
        raise InputError("the points set no key")
    return Plan(keys, tuple({key: point[key] for key in keys} for point in points))


def split_values(text: str) -> list[str]:
    """``text`` split at the commas outside brackets and quotes, so a value may be a TOML array
    (``[0,0,-9.81],[0,0,-1.62]``) or a string with a comma (``"a,b"``)."""
    parts: list[str] = []
    current: list[str] = []
    depth, quote = 0, ""
    for char in text:
        if quote:
            quote = "" if char == quote else quote
        elif char in "\"'":
            quote = char
        elif char in "[{":
            depth += 1
        elif char in "]}":
            depth -= 1
        elif char == "," and depth == 0:
            parts.append("".join(current))
            current = []
            continue
        current.append(char)
    parts.append("".join(current))
    return [part for part in parts if part.strip()]


def read_values(text: str, option: str, example: str) -> list[Any]:
    """The TOML values of a comma-separated list; an empty list is refused naming ``option``."""
    values = [parse_value(item, option) for item in split_values(text)]
    if not values:
        raise InputError(f"{option}: give at least one value, e.g. {example}")
    return values


def read_axis(item: str) -> tuple[str, list[Any]]:
    """``KEY=V1,V2,...`` of ``--vary``."""
    key, sep, raw = item.partition("=")
    key = key.strip()
    if not sep or not key:
        raise InputError(f"--vary {item!r}: expected KEY=V1,V2,..., e.g. flow.speed=0,0.3,0.6")
    return key, read_values(raw, f"--vary {key}", f"--vary {key}=0,0.3,0.6")


def axes_from_command_line(
    key: str | None, values: str | None, vary: Sequence[str]
) -> dict[str, list[Any]]:
    """The keys and values of ``--key K --values V1,V2`` (the first key) and of each
    ``--vary KEY=V1,V2`` (in order); a key given twice is refused."""
    if (key is None) != (values is None):
        raise InputError("--key and --values go together: --key flow.speed --values 0,0.3,0.6")
    axes: dict[str, list[Any]] = {}
    pairs = [] if key is None else [(key, read_values(values or "", "--values", "--values 1,2"))]
    pairs += [read_axis(item) for item in vary]
    if not pairs:
        raise InputError(
            "give the keys to sweep: --vary KEY=V1,V2,... (repeatable), or --key KEY --values "
            "V1,V2,..."
        )
    for name, listed_values in pairs:
        if name in axes:
            raise InputError(f"{name} is swept twice; give each key once")
        axes[name] = listed_values
    return axes
