"""formation_agent.core.kinds.unicycle: the arc's sinc is numpy's, bit for bit. The kind itself (its
commands, limits and arcs against the kinematics) is tested in tests/formation_agent/core/test_kinds.py,
tests/formation_agent/core/kinds/test_car.py (the car builds on it) and
tests/formation_sim/sim/test_robots.py."""

from __future__ import annotations

import math

import numpy as np

from formation_agent.core.kinds.unicycle import arc, sinc


def test_sinc_of_one_float_is_numpys_bit_for_bit():
    rng = np.random.default_rng(19)
    special = [0.0, -0.0, 5e-324, -5e-324, 1e-300, 1e-17, 1.0, -1.0, 0.5, 2.0, 1e300, math.inf, math.nan]
    values = [
        *special,
        *rng.normal(size=20000),
        *rng.normal(size=20000) * 1e-9,
        *rng.uniform(-1e6, 1e6, 2000),
    ]
    for u in values:
        ours, theirs = sinc(u), np.sinc(u)
        assert (np.isnan(ours) and np.isnan(theirs)) or ours.tobytes() == theirs.tobytes(), (u, ours, theirs)


def test_the_arc_is_the_one_drawn_with_numpys_sinc():
    """The arc as it was drawn with np.sinc, the same floats (the robots' poses do not move)."""
    rng = np.random.default_rng(7)
    for k in range(5000):
        position, yaw = rng.normal(size=2), float(rng.uniform(-math.pi, math.pi))
        v, omega = float(rng.normal()), 0.0 if k % 10 == 0 else float(rng.normal() * 3)
        duration = float(rng.uniform(0.0, 0.05))
        half = 0.5 * omega * duration
        chord = v * duration * np.sinc(half / math.pi)
        middle = yaw + half
        expected = position + chord * np.array([math.cos(middle), math.sin(middle)])
        got, got_yaw = arc(position, yaw, v, omega, duration)
        assert got.tobytes() == expected.tobytes() and got_yaw == yaw + omega * duration
