"""The speed scale κ and the threshold floor c0 (docs/SPEED_SCALE.md): their rules and the gains
the agents derive from them (the engine's runs at κ: tests/formation_sim/sim/test_engine_speed_scale.py)."""

from __future__ import annotations

import math

import pytest

from formation_agent.core.errors import AgentError, ScaleError
from formation_agent.core.eta import Eta1Agent, Eta2Agent
from formation_agent.core.speed_scale import check_speed_scale, check_threshold_floor


@pytest.mark.parametrize('bad', [0.0, -1.0, math.nan, math.inf, -math.inf, 1e-7, 2e6, 'fast'])
def test_a_bad_speed_scale_is_refused_with_its_rule_and_value(bad):
    with pytest.raises(ScaleError, match=r'^speed_scale: must') as caught:
        check_speed_scale(bad)
    assert repr(bad if isinstance(bad, str) else float(bad)) in str(caught.value)
    with pytest.raises(AgentError, match='speed_scale'):
        Eta1Agent(agent_id=1, neighbours={2: (1.0, 0.0)}, delta=4.0, alpha=1.0, beta=0.1, speed_scale=bad)


@pytest.mark.parametrize('bad', [-1e-9, math.nan, math.inf, 'x'])
def test_a_bad_threshold_floor_is_refused_with_its_rule_and_value(bad):
    with pytest.raises(ScaleError, match=r'^threshold_floor: must be a finite number >= 0'):
        check_threshold_floor(bad)
    with pytest.raises(AgentError, match='threshold_floor'):
        Eta2Agent(
            agent_id=1,
            neighbours={2: (1.0, 0.0)},
            delta=4.0,
            alpha_d=1.0,
            beta_d=0.1,
            k1=1.0,
            k2=1.0,
            k3=1.0,
            threshold_floor=bad,
        )


def test_eta2_agent_runs_the_scaled_gains():
    """u^d = -κ²k1 Σ ω y - κk2 Σ ω q (damping κk3): the paper's controller in the time s = κt."""
    kappa = 0.37
    common = dict(
        agent_id=1, neighbours={2: (1.0, 0.0)}, delta=4.0, alpha_d=1.0, beta_d=0.1, k1=2.0, k2=3.0, k3=0.5
    )
    agent = Eta2Agent(**common, speed_scale=kappa)
    assert (agent.k1, agent.k2, agent.k3) == (kappa * kappa * 2.0, kappa * 3.0, kappa * 0.5)
    assert agent.threshold(2.0) == pytest.approx(kappa * kappa * math.exp(-kappa * 0.1 * 2.0), rel=1e-15)
    floored = Eta2Agent(**common, speed_scale=kappa, threshold_floor=0.25)
    assert floored.threshold(1e6) == pytest.approx(kappa * kappa * 0.25, rel=1e-15)
