"""The paper's three observations on Case 1 (Hirato & Kawaguchi §5, Figs. 7 and 8).

One forced-tentacles tentacle (60 particles at 0.01 m), its root forced radially at 1 Hz, ±0.03 m;
measures over the last half of 10 s (after the start-up transient).
"""

import numpy as np

from jellysim.studies import sweep

BASE = {"tentacles.count": 1, "flow.noise": 0.0, "duration": 10.0}


def test_the_tip_oscillates_more_as_youngs_modulus_grows():
    # Fig. 7: "the higher the Young's modulus, the easier it is for the oscillation compelled at
    # the base to propagate to the tip".
    traces = sweep(
        "forced-tentacles", "tentacles.youngs_modulus", [1e2, 1e4, 2.4e5, 5e6, 9e9], BASE
    )
    ratios = [trace.tip_to_root_range() for trace in traces]
    assert all(a < b for a, b in zip(ratios, ratios[1:], strict=False)), ratios
    assert ratios[0] < 0.5 and abs(ratios[-1] - 1.0) < 0.05  # soft: damped; wood: rigid


def test_the_tip_oscillates_more_as_the_flow_grows():
    # Fig. 8 (E = 0.1 kPa): "when v is large, the propagation of oscillations becomes large".
    traces = sweep("forced-tentacles", "flow.speed", [0.0, 0.3, 0.6, 1.0], BASE)
    ratios = [trace.tip_to_root_range() for trace in traces]
    assert all(a < b for a, b in zip(ratios, ratios[1:], strict=False)), ratios


def test_with_flow_the_tip_converges_to_the_roots_range():
    # Fig. 8: comparing v = 0 with v > 0, "the coordinate value of the tip converges towards the
    # range of the root's oscillation".
    still, flowing = sweep("forced-tentacles", "flow.speed", [0.0, 0.3], BASE)
    for trace, expect_inside in ((still, False), (flowing, True)):
        root, tip = trace.late()
        inside = np.mean((tip >= root.min()) & (tip <= root.max()))
        if expect_inside:
            assert inside == 1.0
            assert abs(tip.mean() - root.mean()) < 0.1 * np.ptp(root)
        else:
            assert inside < 0.5
            assert abs(tip.mean() - root.mean()) > np.ptp(root)
