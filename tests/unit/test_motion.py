"""The tentacle motion measures of issue 25 ("Motion that reads on screen"): chord, bend and the
root-to-tip lag, against shapes and signals whose values are known in closed form."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import jellysim
from jellysim.io.motion import chord_and_bend, root_tip_lag, sideways, tentacle_motion


def test_a_straight_chain_has_chord_one_and_no_bend() -> None:
    chain = np.outer(np.arange(60) * 0.01, [0.3, -0.2, -0.9])
    chord, bend = chord_and_bend(chain)
    assert chord == pytest.approx(1.0, abs=1e-12)
    assert bend == pytest.approx(0.0, abs=1e-12)


def test_a_half_circle_has_chord_two_over_pi_and_bend_two_over_pi_squared() -> None:
    """A half circle of radius R: chord 2R over length pi R; the mean distance from the
    diameter, R times the mean of sin over [0, pi] = 2 R / pi, over pi R."""
    theta = np.linspace(0.0, np.pi, 2001)
    chain = np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], axis=-1)
    chord, bend = chord_and_bend(chain)
    assert chord == pytest.approx(2.0 / np.pi, rel=1e-6)
    assert bend == pytest.approx(2.0 / np.pi**2, rel=1e-3)


def test_the_lag_of_a_delayed_signal_is_its_delay() -> None:
    dt, delay = 1.0 / 30.0, 0.2
    t = np.arange(300) * dt
    root = np.stack([np.sin(2 * np.pi * t), 0.5 * np.sin(2 * np.pi * t + 1.0)], axis=1)
    tip = np.stack(
        [0.7 * np.sin(2 * np.pi * (t - delay)), 0.3 * np.sin(2 * np.pi * (t - delay) + 1.0)],
        axis=1,
    )
    lag, period, coherence = root_tip_lag(root, tip, dt)
    assert period == pytest.approx(1.0)
    assert lag == pytest.approx(delay, rel=1e-9)
    assert coherence > 0.99  # below 1 only as the tips' amplitudes differ from the roots'
    rigid, _, coherence = root_tip_lag(root, 2.0 * root, dt)
    assert rigid == pytest.approx(0.0, abs=1e-12) and coherence == pytest.approx(1.0)
    noise = np.random.default_rng(1).normal(size=root.shape)
    assert root_tip_lag(root, noise, dt)[2] < 0.9  # a tip that does not follow


def test_sideways_is_along_each_roots_direction_of_motion() -> None:
    t = np.linspace(0.0, 2.0, 100)
    direction = np.array([0.6, 0.8])
    root = np.sin(2 * np.pi * t)[:, None, None] * direction + [1.0, 2.0]
    tip = np.sin(2 * np.pi * t - 0.5)[:, None, None] * direction * 3.0 + [5.0, 0.0]
    r, s = sideways(root, tip)
    np.testing.assert_allclose(
        np.abs(r[:, 0]), np.abs(np.sin(2 * np.pi * t) - np.sin(2 * np.pi * t).mean()), atol=1e-12
    )
    assert np.corrcoef(r[:, 0], s[:, 0])[0, 1] == pytest.approx(np.cos(0.5), abs=0.05)


def test_the_forced_tentacle_is_measured_at_its_forcing(tmp_path: Path) -> None:
    """The paper's forced base point (Figs. 5, 7, 8): the root moves at 1 Hz, so the measured
    period is 1 s; the tentacle bends a little away from straight and its tip follows."""
    with jellysim.run(
        "forced-tentacles",
        tmp_path / "forced",
        overrides={"duration": 4.0, "tentacles.count": 2},
    ) as r:
        motion = tentacle_motion(r)
    assert motion.start == pytest.approx(2.0) and motion.end == pytest.approx(4.0)
    assert motion.period == pytest.approx(1.0, rel=0.05)  # the spectrum's resolution
    assert 0.0 <= motion.lag < motion.period
    assert 0.9 < motion.chord < 1.0 and 0.0 < motion.bend < 0.1
    assert motion.bend_peak >= motion.bend
    assert "root-to-tip lag" in motion.describe()
