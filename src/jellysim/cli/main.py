"""The ``jellysim`` command line (DESIGN §3). Exit status: 0 success, 2 invalid input,
3 the simulation went unstable, 1 anything else."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
from collections.abc import Sequence
from pathlib import Path

from jellysim.errors import (
    InputError,
    JellysimError,
    OutputError,
    RunInterrupted,
    SimulationUnstable,
)


class _Help(argparse.HelpFormatter):
    """Help that shows each option's default, unless its text already says it or there is none
    to show (a flag, an option that is unset by default)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        if (
            "default" in text
            or default is None
            or default is False  # a flag (0, a number, is shown)
            or default is argparse.SUPPRESS
            or (isinstance(default, list) and not default)
            or not action.option_strings
        ):
            return action.help
        return f"{text} (default: %(default)s)"


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args: object, **kwargs: object) -> None:
        kwargs.setdefault("formatter_class", _Help)
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]

    def error(self, message: str) -> None:  # type: ignore[override]
        # One line (DESIGN §3: at most three), pointing at the help instead of the usage block.
        self.exit(2, f"jellysim: error: {message} (see '{self.prog} --help')\n")


def _add_set_option(parser: argparse.ArgumentParser, metavar: str, help_text: str) -> None:
    """The repeatable ``--set KEY=VALUE`` of the commands that take scene overrides."""
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar=metavar, help=help_text
    )


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="jellysim", description="Simulate and animate jellyfish.")
    from jellysim._version import __version__

    parser.add_argument("--version", action="version", version=f"jellysim {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = sub.add_parser("run", help="simulate a scene (preset name or TOML file)")
    run.add_argument("scene", help="preset name (see 'jellysim presets') or path to a .toml")
    run.add_argument("--out", help="output folder (default: out/<scene name>)")
    _add_set_option(run, "KEY=VALUE", "override a scene key, VALUE read as TOML (repeatable)")
    run.add_argument(
        "--device",
        choices=("cpu", "cuda"),
        help="where the fluid is stepped (the same as --set fluid.device=...): 'cuda' for an "
        "NVIDIA GPU (a scene without MPS water runs on the CPU either way)",
    )
    run.add_argument("--resume", action="store_true", help="continue a killed run")
    run.add_argument("--force", action="store_true", help="replace an existing result")
    run.add_argument("--quiet", action="store_true", help="no progress and no messages")
    run.add_argument(
        "--no-estimate-check",
        action="store_true",
        help="run even when the estimated memory or disk exceeds what the machine has",
    )

    plot = sub.add_parser("plot", help="the paper's figures for a result")
    plot.add_argument("dir", help="folder holding result.h5")
    plot.add_argument("--out", help="folder for the figures (default: DIR/plots)")
    plot.add_argument("--quiet", action="store_true", help="print nothing")

    sweep = sub.add_parser(
        "sweep",
        help="run a scene once per point of one or more keys (a grid, or a list with --zip), "
        "the points at once; root and tip x against time, a table of the points",
    )
    sweep.add_argument("scene", help="preset name or path to a .toml")
    sweep.add_argument(
        "--vary",
        action="append",
        default=[],
        metavar="KEY=V1,V2,...",
        help="a scene key and its comma-separated TOML values (repeatable: every combination of "
        "the keys' values is a point)",
    )
    sweep.add_argument(
        "--zip",
        action="store_true",
        help="pair the --vary lists in order (point i takes each key's i-th value) instead of "
        "every combination",
    )
    sweep.add_argument("--key", help="a key to vary, with --values (the same as --vary KEY=...)")
    sweep.add_argument("--values", help="the comma-separated TOML values of --key")
    _add_set_option(sweep, "KEY=VALUE", "override a scene key for every run")
    sweep.add_argument(
        "--tentacle",
        type=int,
        default=0,
        help="which simulated tentacle, numbered across the tentacle groups in order (default 0)",
    )
    sweep.add_argument(
        "--out",
        default="out/sweeps",
        help="the sweep's folder: each point's run (points/), the table and the figure; run the "
        "same sweep again to keep its finished points and resume a killed one",
    )
    sweep.add_argument("--title", default="", help="figure title")
    sweep.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="points run at once, each in its own local process (default: one per core)",
    )
    sweep.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run the points on the Dask cluster whose scheduler is at ADDRESS (e.g. "
        "tcp://10.0.0.5:8786); its workers must share --out (docs/sweeps.md)",
    )
    sweep.add_argument(
        "--no-estimate-check",
        action="store_true",
        help="run points whose estimated memory or disk exceeds what the machine has",
    )
    sweep.add_argument("--quiet", action="store_true", help="print nothing")

    render = sub.add_parser("render", help="frames and a video of one or more results")
    render.add_argument("dirs", nargs="+", metavar="DIR", help="folder(s) holding result.h5")
    render.add_argument("--out", help="output folder (default: the first DIR/render)")
    render.add_argument(
        "--renderer",
        choices=("auto", "povray", "preview"),
        default="auto",
        help="POV-Ray, or the built-in preview (auto: POV-Ray when installed)",
    )
    render.add_argument(
        "--quality", choices=("draft", "final"), default="draft", help="picture quality"
    )
    render.add_argument("--size", default="640x480", metavar="WxH", help="picture size in pixels")
    render.add_argument(
        "--camera",
        choices=("auto", "fixed", "follow"),
        default="auto",
        help="frame the whole animation, or follow the swimmers (auto: follow when they travel)",
    )
    render.add_argument("--room", action="store_true", help="the paper's room with a water tank")
    render.add_argument(
        "--school", type=int, default=1, metavar="N", help="N jellyfish from the result(s)"
    )
    render.add_argument(
        "--interpolation",
        type=int,
        metavar="N",
        help="drawn tentacles per simulated one (thread groups; oral-arm ribbons keep their own)",
    )
    render.add_argument(
        "--fluid",
        choices=("auto", "spheres", "surface", "none"),
        default="auto",
        help="fluid particles as spheres, one blobby surface, or not at all (auto: spheres for "
        "fluid-only results, none when a jellyfish swims in the fluid)",
    )
    render.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the school's layout and of the water's particles and light shafts",
    )
    render.add_argument("--frames", metavar="A:B", help="render frames A to B-1 only")
    render.add_argument("--gif", action="store_true", help="also write movie.gif")
    render.add_argument("--no-video", action="store_true", help="frames only")
    render.add_argument("--jobs", type=int, help="frames rendered at once (default: the cores)")
    _add_set_option(
        render, "look.KEY=VALUE", "override a [look] key, e.g. look.bell_color=#ff9040 (repeatable)"
    )
    render.add_argument("--force", action="store_true", help="render every frame again")
    render.add_argument("--quiet", action="store_true", help="no progress")

    export = sub.add_parser(
        "export",
        help="files for other tools: vtk (ParaView), usd, gltf, obj, ply; xdmf (the sidecar "
        "through which ParaView and VisIt open result.h5, for a result written without one)",
    )
    export.add_argument("dir", help="folder holding result.h5")
    export.add_argument(
        "--format",
        required=True,
        dest="fmt",
        type=str.lower,
        metavar="{vtk,usd,gltf,obj,ply,xdmf}",
        help="the file format (any case)",
    )
    export.add_argument(
        "--out", help="output folder (default: DIR/export/FORMAT; for xdmf, DIR itself)"
    )
    export.add_argument("--frames", metavar="A:B", help="frames A to B-1 only")
    export.add_argument("--every", type=int, default=1, metavar="K", help="every K-th frame")
    export.add_argument(
        "--interpolation",
        type=int,
        metavar="N",
        help="drawn tentacles per simulated one (thread groups; oral-arm ribbons keep their own)",
    )
    export.add_argument(
        "--up",
        choices=("y", "z"),
        default="y",
        help="obj: the files' up axis (y, as OBJ readers such as Blender and trimesh expect; z, "
        "jellysim's own)",
    )
    export.add_argument("--quiet", action="store_true", help="print nothing")

    view = sub.add_parser("view", help="play a result in the web browser (a local web page)")
    view.add_argument("dir", help="folder holding result.h5")
    view.add_argument("--port", type=int, default=0, help="port to listen on (default: a free one)")
    view.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on (default 127.0.0.1: this machine only; docs/viewer.md)",
    )
    view.add_argument("--no-browser", action="store_true", help="only print the address")

    sub.add_parser("presets", help="list the presets")
    show = sub.add_parser("show", help="print a preset's TOML")
    show.add_argument("name")
    completion = sub.add_parser(
        "completion",
        help='print shell completion: eval "$(jellysim completion bash)" in ~/.bashrc (zsh '
        "likewise; fish: jellysim completion fish > ~/.config/fish/completions/jellysim.fish)",
    )
    completion.add_argument("shell", choices=("bash", "zsh", "fish"), help="the shell")
    sub.add_parser(
        "schema",
        help="print the JSON Schema of scene files, for editors (jellysim schema > "
        "scene.schema.json; then '#:schema ./scene.schema.json' atop a scene)",
    )
    return parser


# Libraries whose INFO messages are theirs, not a run's: numba-cuda's driver logs every GPU
# allocation and free ("dealloc: cuMemFree 24 bytes") at INFO once the root logger has a handler.
QUIET_LOGGERS = ("numba", "numba_cuda")


def log_to_stderr() -> None:
    """A run's progress and notices (jellysim's INFO messages) on stderr, one per line; other
    libraries' only from WARNING up (numba-cuda's as it is configured where
    ``NUMBA_CUDA_LOG_LEVEL`` is set)."""
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    if os.environ.get("NUMBA_CUDA_LOG_LEVEL"):  # asked for: numba-cuda's own handler shows it
        return
    for name in QUIET_LOGGERS:
        logging.getLogger(name).setLevel(logging.WARNING)


def _cmd_run(args: argparse.Namespace) -> int:
    from jellysim.config import load_scene
    from jellysim.simulation import run

    overrides = list(args.overrides)
    if args.device is not None:
        overrides.append(f"fluid.device={args.device!r}")
    scene = load_scene(args.scene, overrides)
    if not args.quiet:
        log_to_stderr()
    result = run(
        scene,
        args.out,
        force=args.force,
        resume=args.resume,
        quiet=args.quiet,
        estimate_check=not args.no_estimate_check,
    )
    with result:
        if not args.quiet:
            print(f"wrote {result.path} ({result.frames} frames)")
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
    from jellysim.io.plots import plot_result
    from jellysim.io.result import open_result

    with open_result(args.dir) as result:
        folder = Path(args.out) if args.out else None
        try:
            paths = plot_result(result, folder)
        except OSError as err:
            raise InputError(f"cannot write the figures: {err}") from None
    _print_paths(paths, args.quiet)
    return 0


def _print_paths(paths: Sequence[object], quiet: bool) -> None:
    """The files a command wrote, one a line on stdout, unless ``--quiet``."""
    if not quiet:
        for path in paths:
            print(path)


def _cmd_sweep(args: argparse.Namespace) -> int:
    from jellysim.studies import (
        grid,
        plot_sweep,
        run_sweep,
        summary_dataset,
        traces_from_dataset,
        write_table,
        write_traces_csv,
    )
    from jellysim.studies.plan import axes_from_command_line

    plan = grid(axes_from_command_line(args.key, args.values, args.vary), args.zip)
    done = run_sweep(
        args.scene,
        plan,
        args.overrides,
        args.tentacle,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        quiet=args.quiet,
        estimate_check=not args.no_estimate_check,
    )
    folder = Path(args.out)
    stem = folder / ("sweep_" + "_".join(key.replace(".", "_") for key in plan.keys))
    table = stem.with_name(stem.name + "_points.csv")
    netcdf = stem.with_suffix(".nc")
    try:
        write_table(
            summary_dataset(done.traces, plan.keys, done.point_folders, args.tentacle),
            table,
            netcdf,
        )
        import xarray

        with xarray.open_dataset(netcdf, engine="h5netcdf") as written:
            traces = traces_from_dataset(written)  # the figure draws what the table holds
        paths = [
            plot_sweep(traces, stem.with_suffix(".png"), args.title),
            write_traces_csv(traces, stem.with_suffix(".csv")),
            table,
            netcdf,
        ]
    except OSError as err:
        raise InputError(f"--out {folder}: cannot write ({err.strerror or err})") from None
    _print_paths(paths, args.quiet)
    if not args.quiet:
        print(
            f"jellysim sweep: {len(plan.points)} points in {folder}: {done.kept} finished "
            f"before, {done.resumed} resumed from a checkpoint, {done.started} run",
            file=sys.stderr,
        )
    return 0


def _parse_size(text: str) -> tuple[int, int]:
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.isdigit() for p in parts):
        raise InputError(f"--size {text!r}: expected WIDTHxHEIGHT in pixels, e.g. 640x480")
    width, height = int(parts[0]), int(parts[1])
    if not (16 <= width <= 8192 and 16 <= height <= 8192):
        raise InputError(f"--size {text}: each side must be 16 to 8192 pixels")
    return width, height


def _parse_frames(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    parts = text.split(":")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise InputError(f"--frames {text!r}: expected A:B, e.g. 0:24")
    return int(parts[0]), int(parts[1])


def _cmd_render(args: argparse.Namespace) -> int:
    from jellysim.io.result import open_result
    from jellysim.render.pipeline import render

    size = _parse_size(args.size)
    frames = _parse_frames(args.frames)
    if args.school < 1 or args.school > 1000:
        raise InputError(f"--school {args.school}: expected 1 to 1000 jellyfish")
    if args.interpolation is not None and not 1 <= args.interpolation <= 1000:
        raise InputError(f"--interpolation {args.interpolation}: expected 1 to 1000")
    if args.jobs is not None and args.jobs < 1:
        raise InputError(f"--jobs {args.jobs}: expected at least 1")
    results = [open_result(folder) for folder in args.dirs]
    try:
        out = Path(args.out) if args.out else results[0].folder / "render"
        outputs = render(
            results,
            out,
            renderer=args.renderer,
            quality=args.quality,
            size=size,
            camera=args.camera,
            room=args.room,
            school=args.school,
            interpolation=args.interpolation,
            fluid=args.fluid,
            seed=args.seed,
            gif=args.gif,
            video=not args.no_video,
            jobs=args.jobs,
            frames=frames,
            look_overrides=args.overrides,
            force=args.force,
            quiet=args.quiet,
        )
    finally:
        for result in results:
            result.close()
    print(f"{outputs['frames']} ({outputs['rendered']} rendered, {outputs['kept']} kept)")
    for key in ("mp4", "gif"):
        if key in outputs:
            print(outputs[key])
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from jellysim.export import export
    from jellysim.io.result import open_result

    frames = _parse_frames(args.frames)
    with open_result(args.dir) as result:
        out = Path(args.out) if args.out else None
        paths = export(result, args.fmt, out, frames, args.every, args.interpolation, args.up)
        first, stop = frames if frames is not None else (0, result.frames)
    _print_paths(paths, args.quiet)
    if args.fmt in ("obj", "ply") and paths and not args.quiet:
        # A frame sequence: stdout names its first file; how many there are, on stderr.
        count = len(range(first, stop, args.every))
        print(f"jellysim: wrote {count} {args.fmt} files in {paths[0].parent}", file=sys.stderr)
    return 0


def _cmd_view(args: argparse.Namespace) -> int:
    from jellysim.view import serve

    return serve(args.dir, host=args.host, port=args.port, browser=not args.no_browser)


def _cmd_presets(args: argparse.Namespace) -> int:
    from jellysim.species import preset_names, preset_summary

    names = preset_names()
    width = max(map(len, names))
    for name in names:
        print(f"{name:<{width}}  {preset_summary(name)}")
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from jellysim.config.load import suggest
    from jellysim.species import preset_names, preset_text

    if args.name not in preset_names():
        raise InputError(
            f"unknown preset '{args.name}'{suggest(args.name, preset_names())}; "
            f"presets: {', '.join(preset_names())}"
        )
    sys.stdout.write(preset_text(args.name))
    return 0


def _cmd_completion(args: argparse.Namespace) -> int:
    from jellysim.cli.completion import script
    from jellysim.species import preset_names

    sys.stdout.write(script(args.shell, _parser(), list(preset_names())))
    return 0


def _cmd_schema(args: argparse.Namespace) -> int:
    from jellysim.config.json_schema import main as print_schema

    print_schema()
    return 0


COMMANDS = {
    "run": _cmd_run,
    "plot": _cmd_plot,
    "sweep": _cmd_sweep,
    "render": _cmd_render,
    "export": _cmd_export,
    "view": _cmd_view,
    "presets": _cmd_presets,
    "show": _cmd_show,
    "schema": _cmd_schema,
    "completion": _cmd_completion,
}


def main(argv: Sequence[str] | None = None) -> int:
    parser = _parser()
    if not (sys.argv[1:] if argv is None else list(argv)):  # no arguments: the help, not an error
        parser.print_help()
        return 0
    args = parser.parse_args(argv)
    try:
        return COMMANDS[args.command](args)
    except RunInterrupted as err:
        print(f"jellysim: stopped by {err}", file=sys.stderr)
        return err.exit_status
    except SimulationUnstable as err:
        print(f"jellysim: {err}", file=sys.stderr)
        print("jellysim: every frame written before stays readable", file=sys.stderr)
        return err.exit_status
    except JellysimError as err:
        print(f"jellysim: error: {err}", file=sys.stderr)
        return err.exit_status
    except KeyboardInterrupt:  # Ctrl-C outside a run's frame loop (a run stops at a frame)
        print("jellysim: stopped by SIGINT", file=sys.stderr)
        return 128 + signal.SIGINT
    except OSError as err:
        if os.environ.get("JELLYSIM_DEBUG"):
            raise
        if err.errno is None:  # HDF5's own error: a file it reads is damaged (input, status 2)
            print(f"jellysim: error: a result does not read, it is damaged: {err}", file=sys.stderr)
            return InputError.exit_status
        # The machine refused a file (disk full, read-only): one sentence.
        where = f"{err.filename}: " if err.filename else ""
        print(f"jellysim: error: {where}{err.strerror or err}", file=sys.stderr)
        return OutputError.exit_status
    except Exception as err:  # one line, no traceback, unless asked for
        if os.environ.get("JELLYSIM_DEBUG"):
            raise
        print(
            f"jellysim: internal error: {type(err).__name__}: {err} "
            "(set JELLYSIM_DEBUG=1 for the traceback)",
            file=sys.stderr,
        )
        return 1
