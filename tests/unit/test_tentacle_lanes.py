"""The tentacle kernel's chains solved LANES at a time (jellysim.tentacle.lanes): each lane's
arithmetic is that of the scalar solve, and a chain moves as it would alone, whatever chains
share its batch (docs/theory/tentacle.md, Eq. T7; docs/decisions.md, "Chains in the lanes of a
vector")."""

import numpy as np
import pytest
from saddle import saddle_system

from jellysim.tentacle.contact import no_obstacle
from jellysim.tentacle.kernels import (
    DRAG_SLENDER,
    KKT_HALF_BANDWIDTH,
    KKT_PADDING,
    Medium,
    _band_ldlt_solve,
    advance_frame,
    project_lengths,
)
from jellysim.tentacle.lanes import LANES, band_ldlt_solve_lanes
from jellysim.tentacle.model import build_chain_model, rest_second_differences

B = KKT_HALF_BANDWIDTH


@pytest.mark.parametrize("n", [24, 236])
def test_every_lane_is_the_scalar_solve_bit_for_bit(n):
    rng = np.random.default_rng(11)
    systems = [saddle_system(rng, n) for _ in range(LANES)]
    band = np.ascontiguousarray(np.stack([s[1] for s in systems], axis=-1))
    rhs = np.ascontiguousarray(np.stack([s[2] for s in systems], axis=-1))
    # The last lane idle, as the kernel leaves one: the identity and a zero right-hand side.
    band[:, :, -1] = 0.0
    band[KKT_PADDING : KKT_PADDING + n, 0, -1] = 1.0
    rhs[:, -1] = 0.0
    pivots = np.empty(rhs.shape)
    band_ldlt_solve_lanes(band, pivots, rhs)
    for lane, (a, scalar_band, scalar_rhs) in enumerate(systems[:-1]):
        expected_rhs = scalar_rhs.copy()
        _band_ldlt_solve(scalar_band, np.empty(len(expected_rhs)), expected_rhs)
        np.testing.assert_array_equal(rhs[:, lane], expected_rhs)
        np.testing.assert_array_equal(band[:, :, lane], scalar_band)
        np.testing.assert_allclose(
            rhs[KKT_PADDING : KKT_PADDING + n, lane],
            np.linalg.solve(a, scalar_rhs[KKT_PADDING : KKT_PADDING + n]),
            rtol=1e-10,
            atol=1e-12,
        )
    np.testing.assert_array_equal(rhs[:, -1], 0.0)
    assert not np.any(rhs[:KKT_PADDING]) and not np.any(rhs[KKT_PADDING + n :])


@pytest.mark.parametrize(
    "shapes",
    [
        ((40, B + 1, LANES - 1), (40, LANES - 1), (40, LANES - 1)),
        ((40, B, LANES), (40, LANES), (40, LANES)),
        ((40, B + 1, LANES), (39, LANES), (40, LANES)),
        ((2 * B - 1, B + 1, LANES), (2 * B - 1, LANES), (2 * B - 1, LANES)),
    ],
)
def test_the_lanes_solve_refuses_a_wrong_shape(shapes):
    band, pivots, rhs = (np.zeros(s) for s in shapes)
    with pytest.raises(ValueError):
        band_ldlt_solve_lanes(band, pivots, rhs)


def chains_in_a_flow(rng, count, particles, d):
    """``count`` curled chains hanging from roots on a circle, in a flow that varies along them,
    with the inputs of one frame of three substeps."""
    substeps = 3
    angles = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
    roots = np.stack([0.1 * np.cos(angles), 0.1 * np.sin(angles), np.zeros(count)], axis=1)
    down = np.array([0.0, 0.0, -1.0])
    x = roots[:, None, :] + np.arange(particles)[None, :, None] * d * down
    x += rng.normal(scale=0.2 * d, size=x.shape) * (np.arange(particles) > 0)[None, :, None]
    for chain in x:
        project_lengths(
            chain,
            np.r_[0.0, np.ones(particles - 1)],
            d,
            1e-13,
            50,
            np.empty((particles - 1, 3)),
            np.empty((4, particles - 1)),
        )
    v = rng.normal(scale=0.05, size=x.shape)
    # Every other chain fast enough (2 m/s across 1 cm segments at 2 ms steps: turns of ~0.4
    # rad) that its linearised lengths are off by more than 1e-3 and it re-solves alone.
    v[::2] *= 40.0
    v[:, 0] = 0.0
    drift = np.array([0.02, 0.0, 0.01])
    root_positions = np.stack([roots + (s + 1) * 1e-3 * drift for s in range(substeps)])
    root_velocities = np.broadcast_to(drift, root_positions.shape).copy()
    directions = np.broadcast_to(down, root_positions.shape).copy()
    outward = np.zeros_like(root_positions)
    outward[..., 0] = np.cos(angles)
    outward[..., 1] = np.sin(angles)
    curl = rest_second_differences(particles, d, 4.0, 12.0, 0.5, 0.0)
    rest = np.stack([curl * (0.5 + rng.uniform()) for _ in range(count)])
    rest[1] = 0.0  # one straight chain among the curled ones
    flow = rng.normal(scale=0.1, size=(substeps, count, particles, 3))
    return x, v, root_positions, root_velocities, directions, outward, rest, flow


def advance(state, model, medium, dt, chains):
    """advance_frame on the chains ``chains`` (a slice) of ``state``; the new positions,
    velocities, diagnostics and drag impulses."""
    x, v, root_positions, root_velocities, directions, outward, rest, flow = state
    x, v = x[chains].copy(), v[chains].copy()
    count = x.shape[0]
    diagnostics = np.zeros((count, 3))
    impulse = np.zeros(x.shape)
    advance_frame(
        x,
        v,
        np.ascontiguousarray(root_positions[:, chains]),
        np.ascontiguousarray(root_velocities[:, chains]),
        np.ascontiguousarray(directions[:, chains]),
        np.ascontiguousarray(outward[:, chains]),
        np.ascontiguousarray(rest[chains]),
        np.ascontiguousarray(flow[:, chains]),
        model,
        medium,
        dt,
        diagnostics,
        impulse,
        no_obstacle(),
    )
    return x, v, diagnostics, impulse


@pytest.mark.parametrize("drag", ["sphere", "slender"])
def test_a_chain_moves_as_it_would_alone_whatever_its_batch(drag):
    # Eleven chains: a full batch and a part-filled one. Chain 6 starts with a non-finite
    # velocity and fails; the others must not notice it.
    rng = np.random.default_rng(5)
    count, particles, d = LANES + 3, 20, 0.01
    model = build_chain_model(
        particles, d, 1.0e4, 1050.0, drag=drag, normal_drag=1.2, tangential_drag=0.02
    )
    assert (model.drag_law == DRAG_SLENDER) == (drag == "slender")
    medium = Medium(1000.0, 1.0e-3, np.array([0.0, 0.0, -9.81]), 1050.0)
    state = chains_in_a_flow(rng, count, particles, d)
    state[1][6, 5, 0] = np.nan
    together = advance(state, model, medium, 2e-3, slice(None))
    assert together[2][6, 2] == 0  # the failed chain: at its first substep
    assert np.all(np.delete(together[2][:, 2], 6) == -1)
    assert np.max(np.delete(together[2][:, 0], 6)) < 1e-9  # lengths exact
    for chain in range(count):
        alone = advance(state, model, medium, 2e-3, slice(chain, chain + 1))
        for a, b in zip(alone, together, strict=True):
            np.testing.assert_array_equal(b[chain], a[0], err_msg=f"chain {chain}")
