"""The progress bar's delay: the default, or $JELLYSIM_PROGRESS_DELAY when it is a number."""

from __future__ import annotations

import pytest

import jellysim.progress as progress_module
from jellysim.progress import DELAY_ENV, _delay_from_environment, progress


@pytest.mark.parametrize(
    ("value", "expected"), [(None, 2.0), ("0", 0.0), ("0.5", 0.5), ("soon", 2.0), ("-1", 2.0)]
)
def test_delay_comes_from_the_environment_when_it_is_a_number(
    value: str | None, expected: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    if value is None:
        monkeypatch.delenv(DELAY_ENV, raising=False)
    else:
        monkeypatch.setenv(DELAY_ENV, value)
    assert _delay_from_environment(2.0) == expected


def test_bar_shows_at_once_with_no_delay(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv(DELAY_ENV, "0")
    with progress(3, 0, False, "simulating", delay=60.0) as bar:
        bar.update(3)
    assert "simulating" in capsys.readouterr().err


def test_quiet_shows_nothing(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv(DELAY_ENV, "0")
    with progress(3, 0, True, "simulating") as bar:
        bar.update(3)
    assert capsys.readouterr().err == ""


def test_a_log_gets_whole_lines_never_carriage_returns(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """stderr that is not a terminal (a batch job's log, CI's): plain lines, the first at
    once (no delay here), then one each 5 % of the work, the last at the end."""
    monkeypatch.setenv(DELAY_ENV, "0")
    with progress(300, 0, False, "simulating") as bar:
        for _ in range(300):
            bar.update(1)
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = err.splitlines()
    assert lines[0].startswith("simulating: 1/300 frames (0 %)")
    assert lines[-1].startswith("simulating: 300/300 frames (100 %)")
    assert [line.split(" frames")[0] for line in lines[1:]] == [
        f"simulating: {n}/300" for n in range(15, 301, 15)
    ]


def test_a_log_line_every_interval_with_the_time_left(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    clock = iter(float(t) for t in range(0, 10000, 25))  # 25 s a frame

    class Clock:  # the progress module's own clock, no one else's
        @staticmethod
        def monotonic() -> float:
            return next(clock)

    monkeypatch.setattr(progress_module, "time", Clock)
    monkeypatch.setenv(DELAY_ENV, "0")
    with progress(100, 40, False, "rendering") as bar:  # resumed: 40 of 100 done
        for _ in range(60):
            bar.update(1)
    lines = capsys.readouterr().err.splitlines()
    # A line each 5 % (45, 50, ... %) and one a minute between (frames 25 s apart); the rate
    # counts this run's frames only, 1 frame in 25 s.
    assert lines[0] == "rendering: 41/100 frames (41 %), 25 s, about 1475 s left"
    assert lines[1] == "rendering: 44/100 frames (44 %), 100 s, about 1400 s left"  # a minute on
    assert "rendering: 50/100 frames (50 %), 250 s, about 1250 s left" in lines
    assert lines[-1] == "rendering: 100/100 frames (100 %), 1500 s"


def test_a_terminal_gets_the_bar(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(progress_module, "_is_terminal", lambda stream: True)
    bar = progress(3, 0, False, "simulating")
    assert type(bar).__name__ == "tqdm"
    bar.close()
