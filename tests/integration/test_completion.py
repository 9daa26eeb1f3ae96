"""Shell completion (issue 27): ``jellysim completion bash`` prints a bash function that, sourced
in a real bash, completes commands, options, option values, preset names and folders."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

BASH = shutil.which("bash")


def complete(script: Path, words: list[str], cwd: Path) -> list[str]:
    """COMPREPLY for the command line ``words`` (the last one being completed)."""
    quoted = " ".join(f"'{w}'" for w in words)
    program = (
        f"source {script}; COMP_WORDS=({quoted}); COMP_CWORD={len(words) - 1}; _jellysim; "
        'printf "%s\\n" "${COMPREPLY[@]}"'
    )
    assert BASH is not None
    done = subprocess.run(
        [BASH, "--norc", "-c", program], capture_output=True, text=True, cwd=cwd, check=True
    )
    return [line for line in done.stdout.splitlines() if line]


@pytest.fixture(scope="module")
def script(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if BASH is None:
        pytest.skip("bash is not installed")
    done = subprocess.run(
        [sys.executable, "-m", "jellysim", "completion", "bash"],
        capture_output=True,
        text=True,
        check=True,
    )
    path = tmp_path_factory.mktemp("completion") / "jellysim.bash"
    path.write_text(done.stdout)
    return path


def test_commands_options_values_presets_and_folders(script: Path, tmp_path: Path) -> None:
    (tmp_path / "out-moon").mkdir()
    (tmp_path / "my_scene.toml").write_text("duration = 1\n")
    assert complete(script, ["jellysim", "re"], tmp_path) == ["render"]
    assert complete(script, ["jellysim", "sch"], tmp_path) == ["schema"]
    assert sorted(complete(script, ["jellysim", "run", "moon-jelly-"], tmp_path)) == [
        "moon-jelly-fine",
        "moon-jelly-real-size",
        "moon-jelly-weightless",
    ]
    assert complete(script, ["jellysim", "run", "my_"], tmp_path) == ["my_scene.toml"]
    assert complete(script, ["jellysim", "run", "x", "--res"], tmp_path) == ["--resume"]
    assert complete(script, ["jellysim", "render", "d", "--quality", ""], tmp_path) == [
        "draft",
        "final",
    ]
    assert complete(script, ["jellysim", "export", "d", "--format", "g"], tmp_path) == ["gltf"]
    assert complete(script, ["jellysim", "view", "out-"], tmp_path) == ["out-moon"]
    assert complete(script, ["jellysim", "show", "lions"], tmp_path) == ["lions-mane"]
    # Names with spaces complete whole (bash escapes them: the function says -o filenames).
    (tmp_path / "my runs").mkdir()
    (tmp_path / "my scene.toml").write_text("duration = 1\n")
    assert complete(script, ["jellysim", "view", "my"], tmp_path) == ["my runs"]
    assert sorted(complete(script, ["jellysim", "run", "my"], tmp_path)) == [
        "my runs",
        "my scene.toml",
        "my_scene.toml",
    ]
    assert "complete -o filenames -F _jellysim jellysim" in script.read_text()


def test_zsh_gets_the_same_function_through_bashcompinit(script: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "jellysim", "completion", "zsh"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert done.stdout.splitlines()[:2] == [
        "(( $+functions[compdef] )) || { autoload -Uz compinit && compinit; }",
        "autoload -U +X bashcompinit && bashcompinit",
    ]
    assert done.stdout.endswith(script.read_text())


FISH = shutil.which("fish")


def test_fish_completes_commands_presets_and_values(tmp_path: Path) -> None:
    if FISH is None:
        if os.environ.get("CI"):
            pytest.fail("fish is not installed: make test installs it as root")
        pytest.skip("fish is not installed (make fish)")
    done = subprocess.run(
        [sys.executable, "-m", "jellysim", "completion", "fish"],
        capture_output=True,
        text=True,
        check=True,
    )
    script = tmp_path / "jellysim.fish"
    script.write_text(done.stdout)

    def complete(line: str) -> list[str]:
        asked = subprocess.run(
            [FISH, "--no-config", "-c", f"source {script}; complete -C '{line}'"],
            capture_output=True,
            text=True,
            check=True,
        )
        return [entry.split("\t")[0] for entry in asked.stdout.splitlines()]

    assert complete("jellysim ru") == ["run"]
    assert complete("jellysim run moon-jelly-") == [
        "moon-jelly-fine",
        "moon-jelly-real-size",
        "moon-jelly-weightless",
    ]
    assert complete("jellysim render d --quality ") == ["draft", "final"]
    assert complete("jellysim export d --format g") == ["gltf"]


def test_no_arguments_prints_the_help() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "jellysim"], capture_output=True, text=True, check=False
    )
    assert done.returncode == 0
    assert done.stdout.startswith("usage: jellysim") and "completion" in done.stdout
