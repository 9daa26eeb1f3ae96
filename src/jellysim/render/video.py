"""Frames to video with ffmpeg: H.264 MP4 and palette GIF, and a probe of what was written.

ffmpeg is the system's (on PATH) or, failing that, the static binary shipped by the PyPI package
``imageio-ffmpeg`` (a dependency), so encoding works without a system package. That binary comes
without ffprobe: :func:`probe` then reads what ``ffmpeg -i`` reports.

Frames are PNG files, given as either

- a folder: its files named ``frame_<number>.png`` (``frame_%05d.png`` as the renderers write
  them), in the order of their numbers; other files are ignored; or
- a sequence of PNG paths, in the order given (any names).

They are streamed to ffmpeg's standard input (``image2pipe``), so gaps in the numbering or names
do not matter; they must all be PNGs of one size. Each frame lasts exactly
``1 / fps``: the input is read at ``fps`` and the output is written at ``fps`` (constant frame
rate). Outputs are written under a temporary name in the target's folder and renamed when ffmpeg
succeeds, so a failed or interrupted encoding never leaves a truncated video under the final name.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import struct
import subprocess
import tempfile
from collections.abc import Sequence
from fractions import Fraction
from pathlib import Path
from typing import IO, TypedDict

from jellysim.errors import InputError, JellysimError

Frames = Path | str | Sequence[Path | str]
FRAME_NAME = re.compile(r"frame_(\d+)\.png")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
STDERR_TAIL_LINES = 15  # lines of ffmpeg's stderr quoted in a VideoError
X264_PRESET, X264_CRF = "medium", 18  # visually near-lossless, modest files
GIF_DITHER = "sierra2_4a"
# GIF frame delays are whole hundredths of a second, and browsers play delays under 2 as 10.
GIF_MAX_FPS = 50.0


class VideoError(JellysimError):
    """ffmpeg is missing, failed, or wrote something that cannot be read."""


class VideoInfo(TypedDict):
    """What :func:`probe` reports of a video's first video stream."""

    frames: int  # frames (packets) in the stream
    width: int  # px
    height: int  # px
    duration: float  # s, of the container; nan if it does not say
    codec: str  # ffmpeg's codec name: 'h264', 'gif', ...
    pix_fmt: str  # ffmpeg's pixel format: 'yuv420p', 'bgra', ...


def find_ffmpeg() -> tuple[str, str]:
    """The ffmpeg to use and where it comes from: ``(path, "system")`` for an ``ffmpeg`` on PATH,
    else ``(path, "imageio-ffmpeg")`` for the binary of the imageio-ffmpeg package."""
    system = shutil.which("ffmpeg")
    if system:
        return system, "system"
    try:
        import imageio_ffmpeg
    except ImportError as error:
        raise VideoError(
            "no ffmpeg: install one on PATH or the Python package imageio-ffmpeg"
        ) from error
    return imageio_ffmpeg.get_ffmpeg_exe(), "imageio-ffmpeg"


def frame_files(frames: Frames) -> list[Path]:
    """The PNG files of ``frames`` (a folder or a sequence, see the module docstring), in order."""
    if isinstance(frames, str | Path):
        folder = Path(frames)
        if not folder.is_dir():
            raise InputError(f"frames {str(folder)!r}: not a folder of frame_NNNNN.png files")
        numbered = [
            (int(match.group(1)), path)
            for path in folder.iterdir()
            if (match := FRAME_NAME.fullmatch(path.name))
        ]
        files = [path for _, path in sorted(numbered)]
    else:
        files = [Path(path) for path in frames]
    if not files:
        raise InputError(f"frames {frames!r}: no PNG frames to encode")
    return files


def frame_size(files: list[Path]) -> tuple[int, int]:
    """(width, height) px shared by all the PNG ``files``, read from their headers; a file that
    is not a PNG or has another size is refused here, before ffmpeg drops or rescales it."""
    size = png_size(files[0])
    for path in files[1:]:
        if png_size(path) != size:
            raise InputError(
                f"frame {str(path)!r}: {png_size(path)} px, not {size} like {str(files[0])!r}"
            )
    return size


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) px of a PNG file, from its header."""
    with open(path, "rb") as file:
        head = file.read(24)
    if len(head) < 24 or head[:8] != PNG_SIGNATURE or head[12:16] != b"IHDR":
        raise InputError(f"frame {str(path)!r}: not a PNG file")
    width, height = struct.unpack(">II", head[16:24])
    return int(width), int(height)


def frame_rate(fps: float) -> str:
    """``fps`` as the rational ffmpeg reads exactly: 12 -> '12/1', 29.97 -> '2997/100'."""
    if not fps > 0.0:
        raise InputError(f"fps {fps!r}: expected a positive number of frames per second")
    rate = Fraction(fps).limit_denominator(1001)
    return f"{rate.numerator}/{rate.denominator}"


def encode_mp4(frames: Frames, fps: float, out: Path, crf: int = X264_CRF) -> Path:
    """Encode ``frames`` into the MP4 ``out``: H.264 (libx264, ``crf``), yuv420p, constant frame
    rate ``fps``, the index (moov) before the data (``+faststart``) so that playback can start
    while downloading.

    yuv420p needs an even width and height: an odd one is padded by one column (right) or row
    (bottom) that repeats its neighbour, so a 65 x 49 frame becomes a 66 x 50 video.
    """
    files = frame_files(frames)
    width, height = frame_size(files)
    pad_x, pad_y = width % 2, height % 2
    # Pad and smear in RGB: the trailing format pins the links between, else ffmpeg may choose
    # to pad the odd-sized yuv420p frame, whose chroma then mixes with the black padding.
    filters = ["format=rgb24"]
    if pad_x or pad_y:
        filters += [
            f"pad={width + pad_x}:{height + pad_y}:0:0",
            f"fillborders=right={pad_x}:bottom={pad_y}:mode=smear",
            "format=rgb24",
        ]
    rate = frame_rate(fps)
    with _staging(Path(out)) as partial:
        _ffmpeg(
            [*_pipe_input(rate), "-vf", ",".join(filters), "-c:v", "libx264"]
            + ["-preset", X264_PRESET, "-crf", str(crf), "-pix_fmt", "yuv420p", "-r", rate]
            + ["-movflags", "+faststart", "-f", "mp4", str(partial)],
            files,
        )
    return Path(out)


def encode_gif(frames: Frames, out: Path, fps: float, width: int | None = None) -> Path:
    """Encode ``frames`` into the looping GIF ``out`` at ``fps``, optionally scaled (Lanczos) to
    ``width`` px keeping the aspect ratio.

    Two passes: the first builds one 256-colour palette from all frames (``palettegen``), the
    second maps the frames to it with ``sierra2_4a`` error diffusion (``paletteuse``). GIF
    stores frame delays in hundredths of a second: at rates that do not divide 100 the delays
    alternate (8 and 9 at 12 fps) so that the total duration stays right. Above
    ``GIF_MAX_FPS`` only every k-th frame is kept, k = ceil(fps / GIF_MAX_FPS), played at fps / k
    (a 200 fps dam break becomes a 50 fps GIF of every 4th frame, as long as the MP4).
    """
    files = frame_files(frames)
    frame_size(files)
    frame_rate(fps)  # refuses fps <= 0
    step = max(1, math.ceil(fps / GIF_MAX_FPS))
    files = files[::step]
    rate = frame_rate(fps / step)
    scale = f"scale={int(width)}:-1:flags=lanczos," if width else ""
    with tempfile.TemporaryDirectory(prefix="jellysim-gif-") as folder:
        palette = Path(folder) / "palette.png"
        _ffmpeg(
            [*_pipe_input(rate), "-vf", f"{scale}palettegen=stats_mode=full"]
            + ["-frames:v", "1", "-update", "1", "-f", "image2", str(palette)],
            files,
        )
        with _staging(Path(out)) as partial:
            _ffmpeg(
                [*_pipe_input(rate), "-i", str(palette)]
                + ["-lavfi", f"[0:v]{scale}format=rgb24[x];[x][1:v]paletteuse=dither={GIF_DITHER}"]
                + ["-r", rate, "-loop", "0", "-f", "gif", str(partial)],
                files,
            )
    return Path(out)


def probe(path: Path) -> VideoInfo:
    """Frame count, size, duration, codec and pixel format of the first video stream of
    ``path``: with ffprobe when it is on PATH, else from ``ffmpeg -i path -map 0:v:0 -c copy -f
    null -`` (which counts the stream's packets without decoding them)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"video {str(path)!r}: no such file")
    ffprobe = shutil.which("ffprobe")
    if ffprobe:
        return probe_with_ffprobe(ffprobe, path)
    return probe_with_ffmpeg(find_ffmpeg()[0], path)


def probe_with_ffprobe(ffprobe: str, path: Path) -> VideoInfo:
    """:func:`probe` by ffprobe's JSON."""
    command = [ffprobe, "-v", "error", "-select_streams", "v:0", "-count_packets"]
    entries = "stream=codec_name,pix_fmt,width,height,nb_read_packets:format=duration"
    command += ["-show_entries", entries, "-of", "json", str(path)]
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise VideoError(_failure("ffprobe", done.returncode, done.stderr))
    report = json.loads(done.stdout)
    if not report.get("streams"):
        raise VideoError(f"ffprobe: no video stream in {str(path)!r}")
    stream = report["streams"][0]
    duration = report.get("format", {}).get("duration")
    return VideoInfo(
        frames=int(stream["nb_read_packets"]),
        width=int(stream["width"]),
        height=int(stream["height"]),
        duration=float(duration) if duration not in (None, "N/A") else float("nan"),
        codec=str(stream["codec_name"]),
        pix_fmt=str(stream["pix_fmt"]),
    )


def probe_with_ffmpeg(ffmpeg: str, path: Path) -> VideoInfo:
    """:func:`probe` by parsing ffmpeg's report of a stream copy to nowhere."""
    command = [ffmpeg, "-hide_banner", "-nostdin", "-i", str(path)]
    command += ["-map", "0:v:0", "-c", "copy", "-f", "null", "-"]
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise VideoError(_failure("ffmpeg", done.returncode, done.stderr))
    return parse_ffmpeg_report(done.stderr)


def parse_ffmpeg_report(report: str) -> VideoInfo:
    """The :class:`VideoInfo` in ffmpeg's stderr for ``-i INPUT -map 0:v:0 -c copy -f null -``:
    the input's ``Duration:`` line, its first ``Stream ... Video:`` line (codec, pixel format,
    size: the first three fields at parenthesis depth 0) and the last ``frame=`` count."""
    header = report.split("\nOutput #0", 1)[0]
    stream = re.search(r"Stream #0:\d+.*?: Video: (.*)", header)
    counts = re.findall(r"frame=\s*(\d+)", report)
    if stream is None or not counts:
        raise VideoError("ffmpeg reported no video stream:\n" + _tail(report))
    fields = _top_level_fields(stream.group(1))
    sizes = (re.match(r"(\d+)x(\d+)\b", field) for field in fields[1:])
    size = next((match for match in sizes if match), None)
    if size is None:
        raise VideoError("ffmpeg reported no frame size:\n" + _tail(report))
    clock = re.search(r"Duration: (\d+):(\d+):(\d+(?:\.\d+)?)", header)
    duration = (
        3600.0 * int(clock.group(1)) + 60.0 * int(clock.group(2)) + float(clock.group(3))
        if clock
        else float("nan")
    )
    return VideoInfo(
        frames=int(counts[-1]),
        width=int(size.group(1)),
        height=int(size.group(2)),
        duration=duration,
        codec=fields[0].split()[0],
        pix_fmt=fields[1].split("(")[0].strip(),
    )


def _top_level_fields(text: str) -> list[str]:
    """``text`` split at the commas outside parentheses, each field stripped."""
    fields, depth, start = [], 0, 0
    for index, char in enumerate(text):
        if char == "(":
            depth += 1
        elif char == ")":
            depth -= 1
        elif char == "," and depth == 0:
            fields.append(text[start:index].strip())
            start = index + 1
    fields.append(text[start:].strip())
    return fields


def _pipe_input(rate: str) -> list[str]:
    """ffmpeg's arguments for PNG frames on standard input at ``rate`` frames per second."""
    return ["-f", "image2pipe", "-framerate", rate, "-c:v", "png", "-i", "-"]


class _staging:
    """A temporary name next to ``out`` (same suffix, hidden), renamed to ``out`` when the block
    succeeds and removed when it fails."""

    def __init__(self, out: Path) -> None:
        self.out = out
        self.partial = out.with_name(f".{out.stem}.partial{out.suffix}")

    def __enter__(self) -> Path:
        return self.partial

    def __exit__(self, kind: type[BaseException] | None, *_: object) -> None:
        if kind is None:
            os.replace(self.partial, self.out)
        else:
            self.partial.unlink(missing_ok=True)


def _ffmpeg(arguments: list[str], files: list[Path]) -> None:
    """Run ffmpeg with ``arguments`` (overwriting its output), streaming ``files`` to its
    standard input; raise :class:`VideoError` with the tail of its stderr if it fails."""
    executable, _ = find_ffmpeg()
    # -xerror: a frame that does not decode is an error, not a silently shorter video.
    command = [executable, "-hide_banner", "-loglevel", "error", "-xerror", "-y", *arguments]
    # stderr goes to a file, not a pipe: a pipe that nobody reads fills up and blocks ffmpeg
    # while this process blocks writing its stdin.
    with tempfile.TemporaryFile(mode="w+b") as stderr:
        process = subprocess.Popen(
            command, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=stderr
        )
        _feed(process.stdin, files)
        status = process.wait()
        if status != 0:
            stderr.seek(0)
            text = stderr.read().decode("utf-8", errors="replace")
            raise VideoError(_failure("ffmpeg", status, text, command))


def _feed(stdin: IO[bytes] | None, files: list[Path]) -> None:
    """Write the files' bytes to ffmpeg's stdin and close it; stop quietly if ffmpeg has
    exited (its status and stderr tell why)."""
    assert stdin is not None
    try:
        for path in files:
            stdin.write(Path(path).read_bytes())
    except BrokenPipeError:
        pass
    finally:
        try:
            stdin.close()
        except BrokenPipeError:
            pass


def _tail(text: str) -> str:
    return "\n".join(text.strip().splitlines()[-STDERR_TAIL_LINES:])


def _failure(tool: str, status: int, stderr: str, command: list[str] | None = None) -> str:
    ran = f"\n  command: {' '.join(command)}" if command else ""
    return f"{tool} failed (exit status {status}){ran}\n  its last lines:\n{_tail(stderr)}"
