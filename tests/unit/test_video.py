"""Encoding frames with ffmpeg: MP4 (H.264, yuv420p, constant rate, faststart, even size), GIF,
the probe, and failures that say why."""

import os
import shutil
import struct
import subprocess

import numpy as np
import pytest
from matplotlib.image import imsave
from PIL import Image

from jellysim.errors import InputError
from jellysim.render.video import (
    VideoError,
    encode_gif,
    encode_mp4,
    find_ffmpeg,
    parse_ffmpeg_report,
    probe,
    probe_with_ffmpeg,
    probe_with_ffprobe,
)

FRAMES, FPS = 12, 12.0
WATER, SQUARE = (20, 60, 120), (250, 250, 250)


def write_frames(folder, width, height):
    """FRAMES PNGs frame_00000.png ... of a 10 px white square moving right on blue."""
    folder.mkdir()
    for index in range(FRAMES):
        image = np.empty((height, width, 3), np.uint8)
        image[:] = WATER
        image[5:15, 4 * index : 4 * index + 10] = SQUARE
        imsave(folder / f"frame_{index:05d}.png", image)
    return folder


@pytest.fixture(scope="module", params=[(64, 48), (65, 49)], ids=["even", "odd"])
def frames(request, tmp_path_factory):
    width, height = request.param
    return write_frames(tmp_path_factory.mktemp("frames") / "frames", width, height), width, height


def top_level_boxes(data):
    """Types of the top-level boxes of an MP4 file (ISO/IEC 14496-12 §4.2), in file order."""
    boxes, offset = [], 0
    while offset + 8 <= len(data):
        size, kind = struct.unpack(">I4s", data[offset : offset + 8])
        if size == 1:  # 64-bit size follows
            size = struct.unpack(">Q", data[offset + 8 : offset + 16])[0]
        boxes.append(kind.decode("latin-1"))
        if size == 0:  # to the end of the file
            break
        offset += size
    return boxes


def first_frame(video, tmp_path):
    """The first frame of a video decoded to RGB (H, W, 3) int with ffmpeg."""
    png = tmp_path / "first.png"
    command = [find_ffmpeg()[0], "-v", "error", "-y", "-i", str(video), "-frames:v", "1"]
    subprocess.run([*command, str(png)], check=True)
    return np.asarray(Image.open(png).convert("RGB")).astype(int)


def test_mp4_is_h264_yuv420p_constant_rate_with_the_index_first(frames, tmp_path):
    folder, width, height = frames
    out = encode_mp4(folder, FPS, tmp_path / "clip.mp4")
    info = probe(out)
    assert info["frames"] == FRAMES
    assert (info["width"], info["height"]) == (width + width % 2, height + height % 2)
    assert info["duration"] == pytest.approx(FRAMES / FPS, abs=0.02)
    assert (info["codec"], info["pix_fmt"]) == ("h264", "yuv420p")
    boxes = top_level_boxes(out.read_bytes())
    assert boxes[0] == "ftyp" and boxes.index("moov") < boxes.index("mdat")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["clip.mp4"]  # no partial file

    # The picture survives: the square's corner is where it was drawn, and an odd size is
    # padded by repeating the last column and row, not with black.
    image = first_frame(out, tmp_path)
    assert np.abs(image[10, 8] - SQUARE).max() < 12 and np.abs(image[30, 40] - WATER).max() < 12
    assert np.abs(image[-1, :] - WATER).max() < 12 and np.abs(image[:, -1] - WATER).max() < 12


def test_gif_has_every_frame_and_can_be_scaled_down(frames, tmp_path):
    folder, width, height = frames
    files = sorted(folder.glob("frame_*.png"))  # a list of files works as well as the folder
    for scaled, source in ((None, folder), (32, files)):
        out = encode_gif(source, tmp_path / f"clip-{scaled}.gif", FPS, width=scaled)
        with Image.open(out) as gif:
            assert gif.n_frames == FRAMES
            expected = (width, height) if scaled is None else (32, round(32 * height / width))
            assert gif.size == expected
            durations = []
            for index in range(gif.n_frames):
                gif.seek(index)
                durations.append(gif.info["duration"])
            assert sum(durations) == pytest.approx(1000.0 * FRAMES / FPS, abs=10)
            assert gif.info["loop"] == 0  # forever
        info = probe(out)
        assert (info["codec"], info["frames"]) == ("gif", FRAMES)


def test_a_gif_above_50_fps_keeps_every_kth_frame_and_the_duration(frames, tmp_path):
    # GIF counts delays in hundredths of a second: 200 fps (the dam break's) cannot be stored,
    # and ffmpeg refused it ("Non-monotonic DTS") before every 4th frame was kept.
    folder, _, _ = frames
    out = encode_gif(folder, tmp_path / "fast.gif", 200.0)
    with Image.open(out) as gif:
        assert gif.n_frames == FRAMES // 4
        durations = []
        for index in range(gif.n_frames):
            gif.seek(index)
            durations.append(gif.info["duration"])
    assert durations == [20] * (FRAMES // 4)  # 50 fps
    assert sum(durations) == pytest.approx(1000.0 * FRAMES / 200.0)


def test_a_frame_ffmpeg_cannot_decode_fails_with_its_last_lines_and_leaves_nothing(tmp_path):
    folder = write_frames(tmp_path / "frames", 64, 48)
    frame = folder / "frame_00005.png"
    frame.write_bytes(frame.read_bytes()[:60])  # a valid header, then nothing
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(VideoError, match="exit status") as raised:
        encode_mp4(folder, FPS, out / "clip.mp4")
    assert "Invalid data" in str(raised.value)  # ffmpeg's own words
    assert list(out.iterdir()) == []


def test_frames_of_another_size_or_not_png_are_refused(tmp_path):
    folder = write_frames(tmp_path / "frames", 64, 48)
    imsave(folder / "frame_00012.png", np.zeros((48, 66, 3), np.uint8))
    with pytest.raises(InputError, match="frame_00012.png"):
        encode_mp4(folder, FPS, tmp_path / "clip.mp4")
    (folder / "frame_00012.png").write_text("not a picture")
    with pytest.raises(InputError, match="not a PNG"):
        encode_gif(folder, tmp_path / "clip.gif", FPS)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(InputError, match="no PNG frames"):
        encode_mp4(empty, FPS, tmp_path / "clip.mp4")


def test_find_ffmpeg_falls_back_to_imageio_ffmpeg(monkeypatch):
    path, origin = find_ffmpeg()
    assert origin in ("system", "imageio-ffmpeg") and os.access(path, os.X_OK)
    monkeypatch.setenv("PATH", "")
    path, origin = find_ffmpeg()
    assert origin == "imageio-ffmpeg"
    assert subprocess.run([path, "-version"], capture_output=True).returncode == 0


def test_ffmpeg_report_is_parsed_at_the_top_level_commas():
    report = """Input #0, mov,mp4,m4a,3gp,3g2,mj2, from 'clip.mp4':
  Duration: 00:01:02.50, start: 0.000000, bitrate: 35 kb/s
  Stream #0:0[0x1](und): Video: h264 (High) (avc1 / 0x31637661), yuv420p(tv, bt709, \
progressive), 1920x1080 [SAR 1:1 DAR 16:9], 30 kb/s, 24 fps, 24 tbr, 12288 tbn (default)
Output #0, null, to 'pipe:':
  Stream #0:0(und): Video: h264 (High) (avc1 / 0x31637661), yuv420p, 8x8
frame=  700 fps=0.0 q=-1.0 size=N/A time=00:00:29.12 bitrate=N/A speed= 900x
frame= 1500 fps=0.0 q=-1.0 Lsize=N/A time=00:01:02.45 bitrate=N/A speed=1e+03x
"""
    assert parse_ffmpeg_report(report) == {
        "frames": 1500,
        "width": 1920,
        "height": 1080,
        "duration": 62.5,
        "codec": "h264",
        "pix_fmt": "yuv420p",
    }


@pytest.mark.skipif(shutil.which("ffprobe") is None, reason="no ffprobe on PATH")
def test_ffprobe_and_ffmpeg_probes_agree(frames, tmp_path):
    folder, _, _ = frames
    out = encode_mp4(folder, FPS, tmp_path / "clip.mp4")
    by_ffprobe = probe_with_ffprobe(shutil.which("ffprobe"), out)
    by_ffmpeg = probe_with_ffmpeg(find_ffmpeg()[0], out)
    assert by_ffprobe == pytest.approx(by_ffmpeg, abs=0.01)
