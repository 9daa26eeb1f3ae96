"""Every example in README.md and docs/**/*.md runs (issue 24: documented commands cannot rot).

The examples are the fenced code blocks. ``sh``/``bash``/``shell`` blocks hold commands, one a
line (``\\`` continues a line, ``&&`` chains, ``#`` starts a comment at the start of a word);
``console`` blocks hold commands after ``$ `` and output otherwise; ``python`` blocks are executed,
the blocks of one file as one session (a later block sees what an earlier one defined, as a
reader reading on). ``text`` blocks (diagrams) hold nothing to run. A block with another tag
or none, and a command-like line in an indented code block, fail
:func:`test_every_example_is_run_or_listed`, so nothing is skipped silently: every command is run
here, or listed in ``NOT_RUN`` with the reason and the test that covers it instead.

Each example runs in a fresh working folder, as a user would type it, with these mechanical
changes:

- ``jellysim`` and ``.venv/bin/jellysim`` run as ``python -m jellysim`` with this checkout first
  on ``PYTHONPATH``;
- ``run`` and ``sweep`` get ``--set duration=0.004 --set fps=F`` appended (``F`` gives 3 frames,
  or as many as the documented ``--frames A:B`` of a command that reads the folder need, at most
  5,000 a second), and the Python examples' ``jellysim.load_scene`` applies the same overrides; a
  folder handed to a reading example is run for that example's own ``--frames`` (3 frames where
  it names none), so a render of a whole result renders 3 frames, not the 141 that another
  example's ``--frames 140:141`` needs;
- ``DIR``, ``DIR1``, ``DIR2`` (docs/rendering.md) stand for documented result folders;
  ``--port 8000`` becomes a free port; ``view`` finds a ``BROWSER`` that records the address, and
  is stopped with SIGINT (Ctrl-C, as documented) once the page and the result's metadata were
  served;
- a folder that a command reads (``out/brown-jelly``) is the result of the first documented
  ``run`` that writes it (README first, then docs/ in name order), run here on its own; the
  user's own scene ``my_scene.toml`` is what ``jellysim show brown-jelly`` prints.

Every command must exit 0; what it prints as written files must exist, and so must every file
that the example's comment names (``# out/brown-jelly/render/movie.mp4``, ``# plots/thrust.png``).
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import re
import select
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import time
import tomllib
import urllib.parse
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

import jellysim
from jellysim.cli.main import _parser
from jellysim.view.server import TOKEN_HEADER

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
SOURCE = Path(jellysim.__file__).resolve().parents[1]  # this checkout's src/, as imported here

SHELL_TAGS = {"sh", "bash", "shell", "console"}
PYTHON_TAGS = {"python", "py"}
TEXT_TAGS = {"text"}  # diagrams: nothing to run
JELLYSIM = {"jellysim", ".venv/bin/jellysim"}

# Commands that cannot run inside the test suite, each with the reason and what covers it.
# An entry that no document holds any more fails the test, as does a command in neither list.
NOT_RUN = {
    "make demo": "creates .venv, pip-installs and apt-get-installs POV-Ray: not inside a test; "
    "its jellysim steps are run here (the README's run and render of brown-jelly) and in "
    "tests/integration/test_cli_smoke.py (plot of brown-jelly)",
    "make test": "runs the test suite (what CI runs), this test included",
    'pip install "jellysim[cuda]"': "downloads numba-cuda and the CUDA libraries: not inside a "
    "test (CI has no GPU); tests/unit/test_fluid_gpu.py runs the GPU kernels in Numba's CUDA "
    "simulator",
    "jellysim run tank-3d --device cuda": "needs an NVIDIA GPU, which CI has not; "
    "tests/unit/test_fluid_gpu.py runs the kernels in the simulator against the CPU path, and "
    "runs '--device cuda' without a GPU (exit 2, one line)",
    "jellysim run dam-break-2d --device cuda --out out/dam-break-2d-gpu": "needs an NVIDIA GPU; "
    "measured on one (docs/performance.md), and tests/unit/test_fluid_gpu.py runs the kernels "
    "in the simulator",
    "make web": "npm ci downloads three.js and the test tools from the registry (development "
    "only: the package ships three.js); 'make test' runs it before the suite",
    "blender --background --python out/brown-jelly/export/usd/import_into_blender.py -- "
    "out/brown-jelly/export/usd/brown-jelly.usdc --render out/brown-jelly/blender/jelly.png "
    "--save out/brown-jelly/blender/jelly.blend": "needs Blender, which CI does not install; "
    "tests/integration/test_blender_import.py runs the script with bpy (.venv-blender) with "
    "these options, and the export that writes it is run here (docs/exports.md)",
    "python out/brown-jelly/export/usd/import_into_blender.py "
    "out/brown-jelly/export/usd/brown-jelly.usdc --render out/brown-jelly/blender/jelly.png "
    "--frames 0:50 --size 640x480": "needs the bpy module, in its own venv (.venv-blender), not "
    "this one; tests/integration/test_blender_import.py runs it so, on a tiny result",
    "blender --background --python out/brown-jelly/export/gltf/import_into_blender.py -- "
    "out/brown-jelly/export/gltf/brown-jelly_part000.glb --render out/brown-jelly/blender/gltf.png "
    "--save out/brown-jelly/blender/gltf.blend": "needs Blender, which CI does not install; "
    "tests/integration/test_blender_import.py runs the glTF export's script with bpy "
    "(.venv-blender) with these options, and the export that writes it is run here",
    "python3.11 -m venv /work/venv-bench": "docs/performance.md's record of how the benchmark's "
    "environment was made (PyElastica from PyPI), not a jellysim command",
    '/work/venv-bench/bin/python -m pip install -e ".[bench]"': "the same record: it downloads "
    "PyElastica; benchmarks/ are run by hand, not by the suite",
    "ssh -L 8000:127.0.0.1:8000 remote": "needs a remote machine; the jellysim command it "
    "names ('view DIR --no-browser --port 8000') is run here from docs/viewer.md",
    "python benchmarks/motion_report.py brown-jelly purple-jelly lions-mane forced-tentacles": (
        "benchmarks/ are run by hand (whole preset runs); what it reports is "
        "tests/unit/test_motion.py's tentacle_motion, run there on the forced tentacles, per "
        "group as tests/integration/test_result_groups.py's motion_by_group"
    ),
    "python benchmarks/motion_report.py brown-jelly --set flow.speed=0.3 --set bell.swim_speed=0.3 "
    "--set tentacles.particles=60 --set tentacles.rest_curvature=0 "
    "--set tentacles.rest_curvature_tip=0": "the same benchmark with the paper's Case 1 values; "
    "that --set reaches the preset is tests/integration/test_cli_smoke.py's and "
    "test_preset_motion.py's, the straight step at a zero rest curvature "
    "tests/unit/test_tentacle_curl.py's",
}

TINY_DURATION = 0.004  # s of simulated time for every documented run ...
MAX_FPS = 5000.0  # ... or longer where many frames are needed (the schema allows 10,000)
MIN_FRAMES = 3
PLACEHOLDERS = {  # docs/rendering.md's folders of results
    "DIR": "out/brown-jelly",  # its comment: "300 drawn tentacles for brown-jelly"
    "DIR1": "out/brown-jelly",
    "DIR2": "runs/a",  # README: a second brown-jelly, from the user's my_scene.toml
}
INPUT_FILES = {"my_scene.toml": ["show", "brown-jelly"]}  # a user's scene: a preset's TOML
PATH_TOKEN = re.compile(
    r"^[\w.*-]*(/[\w.*-]*)+$"
    r"|^[\w*-][\w.*-]*\.(png|pvd|mp4|gif|glb|json|usdc|usda|py|h5|toml|csv|vtu|obj|ply)$"
)
INDENTED_COMMAND = re.compile(r"^( {4,}|\t)(\$ |jellysim |\.venv/|make |python|pip |import |from )")
TIMEOUT = 300  # s for one command


@dataclass(frozen=True)
class Example:
    doc: str  # path relative to the repository
    line: int  # 1-based line of the example's first line
    kind: str  # "shell" or "python"
    text: str  # the command line (continuations joined) or the Python source
    comment: str = ""  # the shell comment on the line or on comment lines right after it
    session: tuple[str, ...] = ()  # python: the file's earlier blocks

    @property
    def where(self) -> str:
        return f"{self.doc}:{self.line}"


def split_comment(line: str) -> tuple[str, str]:
    """``line`` as (code, comment): as in a POSIX shell, ``#`` outside quotes starts a comment
    only at the start of a word (``look.bell_color=#ff9040`` is one word)."""
    quote = ""
    for index, char in enumerate(line):
        if quote:
            if char == quote:
                quote = ""
        elif char in "'\"":
            quote = char
        elif char == "#" and (index == 0 or line[index - 1].isspace()):
            return line[:index].rstrip(), line[index + 1 :].strip()
    return line.rstrip(), ""


def extract(path: Path) -> tuple[list[Example], list[str]]:
    """The examples of one Markdown file, and what cannot be classified there."""
    doc = str(path.relative_to(ROOT))
    examples: list[Example] = []
    problems: list[str] = []
    python_blocks: list[str] = []
    lines = path.read_text(encoding="utf-8").splitlines()
    fence = re.compile(r"^\s*(```+|~~~+)\s*([\w+-]*)")
    index = 0
    while index < len(lines):
        opened = fence.match(lines[index])
        if not opened:
            previous = lines[index - 1] if index else ""
            opens_block = not previous.strip() or previous.startswith("    ")
            if opens_block and INDENTED_COMMAND.match(lines[index]):
                problems.append(f"{doc}:{index + 1}: indented code; put it in a fenced block")
            index += 1
            continue
        marker, tag = opened.group(1), opened.group(2).lower()
        start = index + 1
        end = start
        while end < len(lines) and not lines[end].strip().startswith(marker):
            end += 1
        body = lines[start:end]
        if tag in PYTHON_TAGS:
            source = "\n".join(body)
            examples.append(Example(doc, start + 1, "python", source, "", tuple(python_blocks)))
            python_blocks.append(source)
        elif tag in SHELL_TAGS:
            examples += _shell_examples(doc, start, body, tag == "console", problems)
        elif tag not in TEXT_TAGS:
            problems.append(
                f"{doc}:{start}: code block tagged {tag!r}: tag it sh, console, python (run "
                "here) or text (nothing to run)"
            )
        index = end + 1
    return examples, problems


def _shell_examples(
    doc: str, start: int, body: list[str], console: bool, problems: list[str]
) -> list[Example]:
    examples: list[Example] = []
    offset = 0
    while offset < len(body):
        first = offset
        line = body[offset]
        if console:
            if not line.startswith("$ "):
                offset += 1
                continue
            line = line[2:]
        code, comment = split_comment(line)
        while code.endswith("\\") and offset + 1 < len(body):
            offset += 1
            more, more_comment = split_comment(body[offset])
            code, comment = code[:-1].rstrip() + " " + more.strip(), more_comment or comment
        offset += 1
        if not code.strip():
            if comment and examples and not console:  # a comment line about the command above
                previous = examples[-1]
                examples[-1] = Example(
                    previous.doc,
                    previous.line,
                    "shell",
                    previous.text,
                    f"{previous.comment} {comment}".strip(),
                )
            continue
        text = " ".join(code.split())
        examples.append(Example(doc, start + first + 1, "shell", text, comment))
        if any(word in text.split() for word in ("|", ";", ">", "<")):
            problems.append(
                f"{doc}:{start + first + 1}: {text!r}: pipes and redirections are "
                "not run here; write one command a line (or chain with &&)"
            )
    return examples


def collect() -> tuple[list[Example], list[str]]:
    examples: list[Example] = []
    problems: list[str] = []
    for path in DOCS:
        found, trouble = extract(path)
        examples += found
        problems += trouble
    return examples, problems


EXAMPLES, PROBLEMS = collect()


def is_run(example: Example) -> bool:
    """Python blocks and jellysim commands, but for the jellysim commands NOT_RUN lists (those
    that need a GPU)."""
    if example.kind == "python":
        return True
    if example.text in NOT_RUN:
        return False
    return all(part[0] in JELLYSIM for part in parts(example.text))


def parts(text: str) -> list[list[str]]:
    """The commands of a shell line, split at ``&&``."""
    chained: list[list[str]] = [[]]
    for word in shlex.split(text):
        if word == "&&":
            chained.append([])
        else:
            chained[-1].append(word)
    return [part for part in chained if part]


RUN = [example for example in EXAMPLES if is_run(example)]


# --- what a command reads and writes ---------------------------------------------------------


@dataclass
class Command:
    """One jellysim command of an example, placeholders filled in, parsed by the real parser."""

    argv: list[str]  # after ``jellysim``
    args: argparse.Namespace = field(repr=False)

    @classmethod
    def parse(cls, words: list[str]) -> Command:
        argv = [PLACEHOLDERS.get(word, word) for word in words[1:]]
        try:
            args = _parser().parse_args(argv)
        except SystemExit as exit_:
            raise AssertionError(f"jellysim's parser refuses {argv} (exit {exit_.code})") from None
        return cls(argv, args)

    @property
    def name(self) -> str:
        return str(self.args.command)

    def reads(self) -> list[str]:
        """The result folders it reads."""
        args = self.args
        if self.name in ("plot", "export", "view"):
            return [args.dir]
        if self.name == "render":
            return list(args.dirs)
        return []

    def writes(self) -> str | None:
        """The result folder a ``run`` writes (None when it cannot be told before running)."""
        if self.name != "run":
            return None
        args = self.args
        if args.out:
            return str(Path(args.out))
        scene = args.scene
        return f"out/{scene}" if scene in jellysim.preset_names() else None

    def frames_needed(self) -> int:
        frames = getattr(self.args, "frames", None)
        return int(frames.split(":")[1]) if frames else 0


def commands(example: Example) -> list[Command]:
    return [Command.parse(part) for part in parts(example.text)]


def python_folders(example: Example) -> list[str]:
    source = "\n".join([*example.session, example.text])
    return re.findall(r"[\"']((?:out|runs)/[\w./-]+)[\"']", source)


def all_commands() -> Iterator[tuple[Example, Command]]:
    """The jellysim commands of every shell example that parses (one that does not fails in its
    own test case, not in every other)."""
    for example in RUN:
        if example.kind == "shell":
            try:
                parsed = commands(example)
            except AssertionError:
                continue
            for command in parsed:
                yield example, command


def provider(folder: str) -> Example | None:
    """The first documented example whose ``run`` writes ``folder``."""
    return next((ex for ex, command in all_commands() if command.writes() == folder), None)


def frames_for(folder: str | None) -> int:
    """Frames a tiny run writing ``folder`` needs: 3, or what documented ``--frames`` read."""
    needed = [command.frames_needed() for _, command in all_commands() if folder in command.reads()]
    return max([MIN_FRAMES, *needed])


def frames_read(example: Example, folder: str) -> int:
    """Frames ``example``'s own commands need of the folder they read: 3, or their ``--frames``."""
    try:
        parsed = commands(example) if example.kind != "python" else []
    except AssertionError:
        parsed = []
    needed = [command.frames_needed() for command in parsed if folder in command.reads()]
    return max([MIN_FRAMES, *needed])


def tiny(frames: int) -> tuple[float, float]:
    """(duration s, fps) of a tiny run of ``frames`` frames."""
    duration = max(TINY_DURATION, (frames - 1) / MAX_FPS)
    return duration, (frames - 1) / duration


def tiny_options(frames: int) -> list[str]:
    duration, fps = tiny(frames)
    return ["--set", f"duration={duration:g}", "--set", f"fps={fps:g}"]


# --- running ---------------------------------------------------------------------------------


def environment(browser: Path) -> dict[str, str]:
    env = {key: value for key, value in os.environ.items() if key != "JELLYSIM_DEBUG"}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(SOURCE), env.get("PYTHONPATH")]))
    env["BROWSER"] = str(browser)
    return env


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


@dataclass
class Ran:
    """An example after running: its folder, and per command what it printed."""

    cwd: Path
    outputs: list[tuple[Command, str]] = field(default_factory=list)
    failure: str = ""


class Workspace:
    """Runs the examples in fresh folders under ``root``, each once, and hands the results
    that later examples read to them."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.browser = root / "browser"
        self.browser.write_text('#!/bin/sh\necho "$1" >> "$0.opened"\n', encoding="utf-8")
        self.browser.chmod(0o755)
        self.env = environment(self.browser)
        self.ran: dict[str, Ran] = {}

    def cli(self, argv: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "jellysim", *argv],
            capture_output=True,
            text=True,
            timeout=TIMEOUT,
            cwd=cwd,
            env=self.env,
        )

    def folder_for(self, example: Example, frames: int | None = None) -> Path:
        slug = re.sub(r"\W+", "-", example.where) + ("" if frames is None else f"-{frames}")
        folder = self.root / slug
        folder.mkdir()
        return folder

    def provide(self, folder: str, cwd: Path, reader: Example) -> None:
        """Copy the result ``folder`` that a documented run writes into ``cwd``."""
        if (cwd / folder / "result.h5").is_file():
            return
        source = provider(folder)
        assert source is not None, (
            f"{reader.where} reads {folder}, which no documented 'jellysim run' writes"
        )
        assert source != reader, f"{reader.where} reads {folder} before writing it"
        ran = self.run(source, frames_read(reader, folder))
        assert not ran.failure, f"{folder} comes from {source.where}, which failed: {ran.failure}"
        (cwd / folder).mkdir(parents=True)
        for name in ("result.h5", "scene.toml"):
            shutil.copy2(ran.cwd / folder / name, cwd / folder / name)

    def run(self, example: Example, frames: int | None = None) -> Ran:
        """Run ``example`` once; its runs last ``frames`` frames where given (a provider run for
        a reader), else as many as any documented reader of their folder needs."""
        key = example.where if frames is None else f"{example.where}@{frames}"
        if key not in self.ran:
            cwd = self.folder_for(example, frames)
            ran = Ran(cwd)
            self.ran[key] = ran
            try:
                if example.kind == "python":
                    self.run_python(example, ran)
                else:
                    self.run_shell(example, ran, frames)
            except AssertionError as error:
                ran.failure = str(error)
        return self.ran[key]

    def run_shell(self, example: Example, ran: Ran, frames: int | None = None) -> None:
        for name, argv in INPUT_FILES.items():
            if name in example.text.split():
                shown = self.cli(argv, ran.cwd)
                assert shown.returncode == 0, shown.stderr
                (ran.cwd / name).write_text(shown.stdout, encoding="utf-8")
        for command in commands(example):
            for folder in command.reads():
                self.provide(folder, ran.cwd, example)
            argv = list(command.argv)
            if "--port" in argv:
                argv[argv.index("--port") + 1] = str(free_port())
            if command.name in ("run", "sweep"):
                argv += tiny_options(frames or frames_for(command.writes()))
            if command.name == "view":
                printed = self.view(argv, ran.cwd)
            else:
                done = self.cli(argv, ran.cwd)
                assert done.returncode == 0, (
                    f"jellysim {' '.join(argv)}: exit {done.returncode}\n{done.stderr[-3000:]}"
                )
                assert "Traceback" not in done.stderr, done.stderr[-3000:]
                printed = done.stdout
            ran.outputs.append((command, printed))

    def view(self, argv: list[str], cwd: Path) -> str:
        """Start ``jellysim view``, fetch the page and the metadata at the address it prints,
        stop it with SIGINT; returns the address line."""
        opened = Path(f"{self.browser}.opened")
        opened.unlink(missing_ok=True)
        # Ctrl-C at a prompt finds SIGINT at its default, which a background job may not.
        process = subprocess.Popen(
            [sys.executable, "-m", "jellysim", *argv],
            cwd=cwd,
            env=self.env,
            text=True,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
        try:
            assert process.stdout is not None
            ready, _, _ = select.select([process.stdout], [], [], 60)
            line = process.stdout.readline() if ready else ""
            assert line.startswith("jellysim view: serving "), (
                f"jellysim {' '.join(argv)} printed {line!r}; "
                f"stderr: {process.stderr.read() if process.poll() is not None else ''}"
            )
            url = line.split(" at ")[1].split()[0]
            base, _, query = url.partition("?")
            if "--port" in argv:
                assert base.endswith(f":{argv[argv.index('--port') + 1]}/"), line
            with urllib.request.urlopen(url, timeout=30) as page:
                assert page.status == 200 and b"<html" in page.read().lower()
            # The page sends the session's token (in the printed address) with each data request.
            token = urllib.parse.parse_qs(query)["token"][0]
            request = urllib.request.Request(base + "meta.json", headers={TOKEN_HEADER: token})
            with urllib.request.urlopen(request, timeout=30) as meta:
                served = json.loads(meta.read())
            with jellysim.open_result(cwd / argv[1]) as result:
                assert served["frames"] == result.frames
            if "--no-browser" not in argv:  # "opens the browser"
                deadline = time.monotonic() + 30
                while not opened.exists() and time.monotonic() < deadline:
                    time.sleep(0.1)
                assert opened.exists() and opened.read_text().strip() == url, (
                    "the browser was not opened at the address"
                )
            process.send_signal(signal.SIGINT)
            _, err = process.communicate(timeout=30)
        finally:
            if process.poll() is None:
                process.kill()
                process.communicate()
        assert process.returncode == 0, f"exit {process.returncode} after Ctrl-C: {err}"
        assert "Traceback" not in err, err
        return line

    def run_python(self, example: Example, ran: Ran) -> None:
        for folder in python_folders(example):
            if provider(folder) is not None:
                self.provide(folder, ran.cwd, example)
        duration, fps = tiny(MIN_FRAMES)
        prelude = (  # leaves the example's namespace empty: it imports what it uses
            "import jellysim as _jellysim\n"
            "def _tiny(source, overrides=None, _load=_jellysim.load_scene):\n"
            "    scene = _load(source, overrides)\n"
            f"    return _load(scene, {{'duration': {duration}, 'fps': {fps}}})\n"
            "_jellysim.load_scene = _tiny\n"
            "del _jellysim, _tiny\n"
        )
        for earlier in example.session:  # the file's earlier blocks, as one session
            prelude += earlier + "\n"
        done = subprocess.run(
            [sys.executable, "-c", prelude + example.text],
            capture_output=True,
            text=True,
            timeout=TIMEOUT,
            cwd=ran.cwd,
            env=self.env,
        )
        assert done.returncode == 0, f"exit {done.returncode}\n{done.stderr[-3000:]}"


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Workspace]:
    yield Workspace(tmp_path_factory.mktemp("docs-examples"))


# --- what must exist after a command ---------------------------------------------------------


def main_folder(command: Command) -> str | None:
    reads = command.reads()
    return reads[0] if reads else command.writes()


def check_printed(command: Command, printed: str, cwd: Path) -> None:
    """What a command says it wrote exists, where the docs say."""
    args = command.args
    lines = [line for line in printed.splitlines() if line.strip()]
    if command.name == "run":
        folder = cwd / (command.writes() or "")
        with jellysim.open_result(folder) as result:
            assert result.complete and result.frames >= MIN_FRAMES
        assert (folder / "scene.toml").is_file()
    elif command.name in ("plot", "export", "sweep"):
        assert lines, f"jellysim {command.name} printed no file names"
        for line in lines:
            assert (cwd / line).exists() and (cwd / line).stat().st_size > 0, line
        if command.name == "plot":
            expected = Path(args.out) if args.out else Path(args.dir) / "plots"
            assert {Path(line).parent for line in lines} == {expected}
            assert all(line.endswith(".png") for line in lines)
        if command.name == "sweep":
            assert {Path(line).suffix for line in lines} == {".png", ".csv", ".nc"}
    elif command.name == "render":
        out = Path(args.out) if args.out else Path(args.dirs[0]) / "render"
        assert lines[0].startswith(str(out / "frames")), lines
        assert (cwd / out / "movie.mp4").is_file() != bool(args.no_video)
        assert (cwd / out / "movie.gif").is_file() == bool(args.gif)
        with jellysim.open_result(cwd / args.dirs[0]) as result:
            frames = result.frames
        first, stop = (0, frames) if not args.frames else map(int, args.frames.split(":"))
        assert len(list((cwd / out / "frames").glob("frame_*.png"))) == stop - first
    elif command.name == "presets":
        assert [line.split()[0] for line in lines] == jellysim.preset_names()
    elif command.name == "show":
        assert tomllib.loads(printed)["name"] == args.name


def commented_paths(example: Example, command: Command, cwd: Path) -> list[str]:
    """Files the example's comment names that are missing (``out/...`` from the working folder,
    ``DIR/...`` for the placeholder, ``plots/x.png`` from the command's folder, a bare name
    anywhere below it)."""
    missing = []
    base = cwd / (main_folder(command) or ".")
    for raw in example.comment.split():
        token = raw.strip("():,;")
        if not PATH_TOKEN.match(token) or token.startswith("http"):
            continue
        head, _, rest = token.partition("/")
        if head in PLACEHOLDERS:
            token = f"{PLACEHOLDERS[head]}/{rest}"
            head = token.partition("/")[0]
        if "/" not in token:
            found = list(base.rglob(token))
        elif (cwd / head).exists():
            found = glob.glob(str(cwd / token))
        else:
            found = glob.glob(str(base / token))
        if not found:
            missing.append(token)
    return missing


# --- the tests -------------------------------------------------------------------------------


def test_every_example_is_run_or_listed() -> None:
    assert RUN, "no examples found"
    problems = list(PROBLEMS)
    shell_texts = {example.text for example in EXAMPLES if example.kind == "shell"}
    for example in EXAMPLES:
        if not is_run(example) and example.text not in NOT_RUN:
            problems.append(
                f"{example.where}: {example.text!r} is neither run here nor in NOT_RUN "
                "(run it, or list it with the reason and the test that covers it)"
            )
    for text in NOT_RUN:
        if text not in shell_texts:
            problems.append(f"NOT_RUN lists {text!r}, which no document holds any more")
    assert not problems, "\n".join(problems)


def test_the_classifier_follows_the_shell() -> None:
    assert split_comment("jellysim render DIR --set look.bell_color=#ff9040  # hi") == (
        "jellysim render DIR --set look.bell_color=#ff9040",
        "hi",
    )
    assert split_comment("echo '# not a comment' # one") == ("echo '# not a comment'", "one")
    assert parts("jellysim run a && jellysim plot out/a") == [
        ["jellysim", "run", "a"],
        ["jellysim", "plot", "out/a"],
    ]
    assert PATH_TOKEN.match("plots/thrust.png") and PATH_TOKEN.match("bell_particles.pvd")
    assert not PATH_TOKEN.match("three.js") and not PATH_TOKEN.match("Figs.")


@pytest.mark.parametrize("example", RUN, ids=[example.where for example in RUN])
def test_documented_example_runs(example: Example, workspace: Workspace) -> None:
    ran = workspace.run(example)
    assert not ran.failure, f"{example.where}: {example.text}\n{ran.failure}"
    for command, printed in ran.outputs:
        check_printed(command, printed, ran.cwd)
    if ran.outputs:
        missing = commented_paths(example, ran.outputs[-1][0], ran.cwd)
        assert not missing, f"{example.where}: its comment names {missing}, not written"
    if example.kind == "python":
        for folder in re.findall(r"out=[\"']([\w./-]+)[\"']", example.text):
            assert (ran.cwd / folder / "result.h5").is_file(), f"{folder}/result.h5 not written"
