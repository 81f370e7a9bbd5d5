"""Closed-form factors of the double-integrator motion against 50-digit decimal arithmetic."""

from __future__ import annotations

from decimal import Decimal, getcontext

import numpy as np
import pytest

from formation_agent.core.closed_form import (
    SERIES_LIMIT,
    advance_double,
    one_minus_exp,
    z_minus_one_plus_exp,
    z_minus_one_plus_exp_float,
)

getcontext().prec = 50

ZS = [1e-12, 3.7e-9, 1e-6, 2.5e-4, 0.0123, 0.0999, 0.1, 0.1001, 0.73, 5.0, 40.0]


@pytest.mark.parametrize('z', ZS)
def test_factors_are_accurate_to_a_few_ulps(z):
    exact_a = 1 - (-Decimal(z)).exp()
    exact_b = Decimal(z) - 1 + (-Decimal(z)).exp()
    assert float(one_minus_exp(z)) == pytest.approx(float(exact_a), rel=4e-16)
    assert float(z_minus_one_plus_exp(z)) == pytest.approx(float(exact_b), rel=4e-16)


def test_advance_composes_over_split_intervals():
    x, q, u = np.array([1.0, -2.0]), np.array([0.5, 0.25]), np.array([-1.0, 3.0])
    whole = advance_double(x, q, u, 0.6, 2.0)
    half = advance_double(*advance_double(x, q, u, 0.6, 0.7), u, 0.6, 1.3)
    assert np.allclose(whole[0], half[0], rtol=1e-14)
    assert np.allclose(whole[1], half[1], rtol=1e-14)


def test_advance_solves_the_damped_double_integrator():
    # d/dt q = u - k3 q at t: check by a centred difference of the closed form.
    x, q, u, k3, t, h = np.array([0.0]), np.array([2.0]), np.array([1.0]), 0.6, 1.5, 1e-5
    (xp, qp), (xm, qm), (_x0, q0) = (advance_double(x, q, u, k3, t + s) for s in (h, -h, 0.0))
    assert (qp - qm) / (2 * h) == pytest.approx(u - k3 * q0, rel=1e-8)
    assert (xp - xm) / (2 * h) == pytest.approx(q0, rel=1e-8)


@pytest.mark.parametrize(
    'z', [0.0, 1e-300, 1e-12, 3.7e-9, 1e-6, 2.5e-4, 0.0123, 0.05, 0.0999, -0.0999, -1e-7]
)
def test_scalar_series_is_accurate_to_an_ulp(z):
    # The agents' plain-float path uses a shorter, unrolled series below SERIES_LIMIT.
    assert abs(z) < SERIES_LIMIT
    exact = Decimal(z) - 1 + (-Decimal(z)).exp()
    assert z_minus_one_plus_exp_float(z) == pytest.approx(float(exact), rel=2.5e-16, abs=0.0)
