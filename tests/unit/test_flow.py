"""The water around the tentacles: uniform flow relative to the bell plus smooth seeded noise."""

import numpy as np
import pytest

import jellysim
from jellysim.tentacle.flow import FlowNoise, flow_noise_for, water_velocity


def test_water_velocity_is_relative_to_the_bell():
    # DESIGN §3: in the world frame the water moves at v_bell - speed * axis (+ noise).
    axis = np.array([[0.0, 0.0, 1.0]])
    bell = np.array([[0.0, 0.0, 0.2]])
    noise = np.zeros((1, 2, 3))
    u = water_velocity(0.3, axis, bell, noise)
    np.testing.assert_allclose(u, [[[0, 0, -0.1], [0, 0, -0.1]]])


def test_noise_is_reproducible_per_seed_and_differs_per_tentacle():
    times = np.linspace(0, 5, 200)
    a = FlowNoise(0.02, 0.5, 5.0, 4, seed=7).sample(times)
    b = FlowNoise(0.02, 0.5, 5.0, 4, seed=7).sample(times)
    c = FlowNoise(0.02, 0.5, 5.0, 4, seed=8).sample(times)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    assert not np.allclose(a[:, 0], a[:, 1])
    # More tentacles or a longer run do not change the first tentacle's noise.
    d = FlowNoise(0.02, 0.5, 9.0, 6, seed=7).sample(times)
    np.testing.assert_allclose(d[:, :4], a, rtol=0, atol=1e-15)


def test_noise_does_not_depend_on_how_it_is_sampled():
    noise = FlowNoise(0.05, 0.3, 4.0, 2, seed=1)
    times = np.linspace(0, 4, 401)
    together = noise.sample(times)
    apart = np.concatenate([noise.sample(times[i : i + 1]) for i in range(times.size)])
    np.testing.assert_array_equal(together, apart)


def test_noise_is_smooth_and_has_the_requested_amplitude():
    tau, sigma = 0.5, 0.02
    noise = FlowNoise(sigma, tau, 2000.0, 1, seed=3)
    times = np.linspace(0, 2000, 400_001)
    u = noise.sample(times)[:, 0]

    # C1: the slope's change between samples shrinks with the sample spacing (a kink at a knot
    # would keep it finite).
    def largest_slope_change(spacing):
        t = np.arange(0.0, 3.0, spacing)
        slope = np.diff(noise.sample(t)[:, 0], axis=0) / spacing
        return np.abs(np.diff(slope, axis=0)).max()

    assert largest_slope_change(1e-4) < 0.2 * largest_slope_change(1e-3)
    # Amplitude: the knots are an Ornstein-Uhlenbeck process of standard deviation sigma; the
    # cubic interpolation between them keeps it within 20 %.
    assert u.std() == pytest.approx(sigma, rel=0.2)
    # Correlated over tau, decorrelated over several tau.
    lag = int(round(tau / (times[1] - times[0])))
    corr = [np.corrcoef(u[:-k, 0], u[k:, 0])[0, 1] for k in (lag // 10, 5 * lag)]
    assert corr[0] > 0.9 and abs(corr[1]) < 0.1


def test_noise_stays_bounded_up_to_the_last_frame():
    # The last frame, round(duration * fps) / fps, may fall after the duration.
    scene = jellysim.load_scene(
        "brown-jelly",
        {"duration": 1.02, "fps": 30.0, "flow.noise": 0.02, "flow.noise_correlation_time": 0.01},
    )
    noise = flow_noise_for(scene)
    times = np.linspace(0.0, (scene.frame_count - 1) / scene.fps, 5000)
    assert np.abs(noise.sample(times)).max() < 6 * scene.flow.noise
