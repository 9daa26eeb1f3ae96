"""The progress bar's delay: the default, or $JELLYSIM_PROGRESS_DELAY when it is a number."""

from __future__ import annotations

import pytest

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
