"""ETA-2's velocity reference: dq/dt = u^d - k3 q in closed form, held exactly to an acceleration limit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from formation_agent.core.velocity_reference import VelocityReference


def test_without_a_limit_it_is_the_closed_form_of_uxdouble():
    k3, q0, u = 0.6, np.array([1.0, -2.0]), np.array([0.3, 0.9])
    reference = VelocityReference(k3=k3, velocity=q0, time=2.0)
    assert reference.update(2.0, u) == pytest.approx(float(np.linalg.norm(u - k3 * q0)), rel=1e-15)
    for t in (2.0, 2.001, 2.5, 4.0, 30.0):
        expected = u / k3 + (q0 - u / k3) * math.exp(-k3 * (t - 2.0))  # (stateqiqj)
        assert np.allclose(reference.velocity(t), expected, rtol=1e-14, atol=1e-15)


def test_an_update_re_anchors_without_a_jump():
    reference = VelocityReference(k3=0.6, velocity=[1.0, -2.0], time=0.0, max_acceleration=0.5)
    reference.update(0.0, [4.0, 0.0])
    before = reference.velocity(1.25)
    reference.update(1.25, [-1.0, 1.0])
    assert np.array_equal(reference.velocity(1.25), before)
    with pytest.raises(ValueError, match=r'asked for t=1.0, before its last update at t=1.25'):
        reference.velocity(1.0)


def _limited_rate(k3, u, a):
    def rate(_t, q):
        w = u - k3 * q
        norm = np.linalg.norm(w)
        return w if norm <= a else w * (a / norm)

    return rate


@pytest.mark.parametrize(
    ('q0', 'u'), [([1.0, -2.0], [4.0, 0.0]), ([0.0, 0.0], [0.0, -3.0]), ([0.2, 0.1], [0.1, 0.0])]
)
def test_the_acceleration_limit_holds_exactly_and_matches_the_saturated_dynamics(q0, u):
    k3, a = 0.6, 0.5
    q0, u = np.array(q0), np.array(u)
    reference = VelocityReference(k3=k3, velocity=q0, time=0.0, max_acceleration=a)
    requested = reference.update(0.0, u)
    assert requested == pytest.approx(float(np.linalg.norm(u - k3 * q0)), rel=1e-15)
    times = np.linspace(0.0, 12.0, 241)
    solution = solve_ivp(
        _limited_rate(k3, u, a),
        (0.0, 12.0),
        q0,
        method='DOP853',
        rtol=1e-12,
        atol=1e-12,
        t_eval=times,
        max_step=0.01,
    )
    ours = np.array([reference.velocity(t) for t in times])
    assert np.abs(ours - solution.y.T).max() < 1e-8
    # ||dq/dt|| <= a everywhere (central differences of the exact reference).
    h = 1e-6
    rates = [
        np.linalg.norm(reference.velocity(t + h) - reference.velocity(t - h)) / (2 * h) for t in times[1:]
    ]
    assert max(rates) <= a * (1 + 1e-6)
    if requested > a:  # held at the limit, along a fixed direction, until (|w0| - a) / (k3 a)
        switch = (requested - a) / (k3 * a)
        assert rates[0] == pytest.approx(a, rel=1e-6)
        assert np.allclose(
            reference.velocity(switch), q0 + a * switch * (u - k3 * q0) / requested, atol=1e-15
        )


def test_bad_gains_are_refused():
    with pytest.raises(ValueError, match='k3 must be a finite number > 0, got 0.0'):
        VelocityReference(k3=0.0, velocity=[0.0], time=0.0)
    with pytest.raises(ValueError, match='max_acceleration must be > 0, got -1.0'):
        VelocityReference(k3=1.0, velocity=[0.0], time=0.0, max_acceleration=-1.0)
