"""The warp a robot's limits allow (formation_sim.model.warp_choice): every command κ(t) u_p(s(t))
within the speed limit (times the margin) at every instant, each piece one window of real time,
the cap, the proofs' decaying bound, and the refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_agent.core.time_warp import TimeWarp
from formation_sim.model.errors import LimitsError
from formation_sim.model.speed_choice import OBSERVED_MARGIN, RobotLimits, Settling
from formation_sim.model.warp_choice import WarpChoice, guaranteed_warp, observed_warp, warp_limit

LIMITS = RobotLimits(max_speed=0.22, max_angular_speed=2.84, control_point_distance=0.1)
# A decaying step function of the team's largest command, as a κ = 1 run gives it.
TIMES = np.array([0.0, 0.05, 0.2, 0.7, 1.5, 3.0, 6.0])
LARGEST = np.array([2.0, 2.5, 1.2, 0.6, 0.3, 0.12, 0.05])


def _held(times, values, s):
    return values[np.searchsorted(times, s, side='right') - 1]


def test_observed_warp_keeps_every_command_within_the_limit_with_its_margin():
    warp = observed_warp(times=TIMES, largest=LARGEST, limits=LIMITS, horizons=(20.0, 60.0))
    real = np.linspace(0.0, warp.real(20.0), 200_001)
    worst = max(warp.rate(t) * _held(TIMES, LARGEST, warp.paper(t)) for t in real)
    assert worst <= 0.22 / 1.25 * (1.0 + 1e-12)
    assert worst >= 0.22 / 1.25 * 0.99  # and the limit is used: the first piece sits on it
    assert warp.rates[0] == pytest.approx(0.22 / (1.25 * 2.0))  # its first window ends before s = 0.05
    assert warp.paper_rate(0.05) == pytest.approx(0.22 / (1.25 * 2.5))  # the 2.5 from s = 0.05 on
    assert warp.max_rate == 1.0  # capped: 0.05 asks for κ = 3.5
    later = [k for s, k in zip(warp.paper_starts, warp.rates) if s >= 0.05]
    assert all(b >= a for a, b in zip(later, later[1:]))  # the command decays from s = 0.05: κ grows


def test_pieces_last_one_window_of_real_time_until_merged():
    warp = observed_warp(times=TIMES, largest=LARGEST, limits=LIMITS, horizons=(20.0, 60.0), window=0.25)
    lengths = np.diff(warp.real_starts)
    # merged pieces (the same κ twice in a row) last whole multiples of the window
    assert np.allclose(lengths / 0.25, np.round(lengths / 0.25), atol=1e-9)
    assert lengths.min() >= 0.25 * (1.0 - 1e-12)
    assert len(warp.rates) > 5


def test_turn_rate_binds_when_tighter():
    limits = RobotLimits(max_speed=0.5, max_angular_speed=1.0, control_point_distance=0.1)  # W l = 0.1
    warp = observed_warp(times=TIMES, largest=LARGEST, limits=limits, horizons=(5.0, 60.0), margin=1.0)
    assert warp.rates[0] == pytest.approx(0.1 / 2.0)
    assert warp.paper_rate(0.05) == pytest.approx(0.1 / 2.5)


def test_cap_bounds_the_rate_and_a_still_team_runs_at_the_cap():
    warp = observed_warp(times=[0.0], largest=[0.0], limits=LIMITS, horizons=(3.0, 60.0), cap=0.5)
    assert warp.rates == (0.5,)


def test_guaranteed_warp_follows_the_decaying_bound():
    speed, dotyi, beta = 3.9, 5.0, 0.4
    warp = guaranteed_warp(speed=speed, dotyi=dotyi, beta=beta, limits=LIMITS, horizons=(30.0, 60.0))
    for t in np.linspace(0.0, 60.0, 20_001):
        s = warp.paper(t)
        assert warp.rate(t) * min(speed, dotyi * math.exp(-beta * s)) <= 0.22 * (1.0 + 1e-12)
    assert warp.rates[0] == pytest.approx(0.22 / 3.9)
    assert warp.rates[-1] > 2 * warp.rates[0]


def test_horizons_stop_the_pieces():
    warp = observed_warp(times=TIMES, largest=LARGEST, limits=LIMITS, horizons=(1e9, 10.0))
    assert warp.real_starts[-1] < 10.0
    assert 10.0 - warp.real_starts[-1] <= 0.5 + 1e-12


@pytest.mark.parametrize(
    ('limits', 'dynamics', 'words'),
    [
        (LIMITS, 'double', 'time_warp: ETA-1 only'),
        (RobotLimits(max_acceleration=1.0, max_speed=0.2), 'single', 'max_acceleration 1 m/s²: ETA-1'),
        (RobotLimits(), 'single', 'needs at least one of --max-speed'),
    ],
)
def test_no_warp_where_it_does_not_apply(limits, dynamics, words):
    with pytest.raises(LimitsError, match=words):
        warp_limit(limits, dynamics, cap=1.0, window=0.5)


@pytest.mark.parametrize(('name', 'value'), [('cap', 0.0), ('window', math.inf), ('cap', math.nan)])
def test_bad_cap_or_window(name, value):
    kwargs = {'cap': 1.0, 'window': 0.5, name: value}
    with pytest.raises(LimitsError, match=f'time_warp: {name} must be a finite number > 0, got {value!r}'):
        warp_limit(LIMITS, 'single', **kwargs)


def test_bad_run_numbers_refused():
    with pytest.raises(LimitsError, match='one largest command per increasing event time from t = 0'):
        observed_warp(times=[0.0, 0.0], largest=[1.0, 1.0], limits=LIMITS, horizons=(1.0, 1.0))
    with pytest.raises(LimitsError, match='margin: must be a finite number >= 1, got 0.5'):
        observed_warp(times=[0.0], largest=[1.0], limits=LIMITS, horizons=(1.0, 1.0), margin=0.5)


def test_choice_maps_the_settling_time_and_compares_with_the_constant_kappa():
    warp = TimeWarp(paper_starts=(0.0, 1.0), rates=(0.1, 1.0))
    settling = Settling(initial_error=1.0, time=2.0, run_horizon=20.0)
    choice = WarpChoice(
        limits=LIMITS,
        observed=warp,
        guaranteed=None,
        guaranteed_missing='outside the hypotheses',
        settling=settling,
        margin=1.25,
        cap=1.0,
        window=0.5,
        event_rate=40.0,
    )
    assert choice.settle_time(warp) == pytest.approx(11.0)  # 1 / 0.1 + (2 - 1) / 1
    data = choice.to_dict()
    assert data['observed']['settle_time'] == pytest.approx(11.0)
    assert data['guaranteed'] is None and data['guaranteed_missing'] == 'outside the hypotheses'
    assert data['event_rate'] == 40.0
    text = '\n'.join(choice.lines(constant=0.1))
    assert '<= 40 events per agent per second' in text
    assert 'observed: 2 pieces, κ from 0.1 to 1; 5 % of the formation error after 11 s' in text
    assert 'the constant observed κ = 0.1: 5 % after 20 s' in text
    assert 'guaranteed: none: outside the hypotheses' in text


def test_the_events_cap_keeps_every_window_of_real_time_within_its_count():
    """A burst (the safety layer's triggers: 2000 events within 1 s of the paper's time, 3 agents)
    slows the warp there: no piece (the warp's 0.5 s windows of real time from t = 0) holds more
    than event_rate x agents x window of the exact run's events, counted at their real times."""
    rng = np.random.default_rng(7)
    quiet = np.sort(rng.uniform(0.0, 20.0, 60))
    burst = np.sort(rng.uniform(3.0, 4.0, 2000))
    events = np.concatenate([quiet, burst, np.zeros(3)])  # the 3 agents' triggers at t = 0 too
    limits = RobotLimits(max_speed=1.0)
    plain = observed_warp(times=TIMES, largest=LARGEST, limits=limits, horizons=(20.0, 60.0))
    capped = observed_warp(
        times=TIMES,
        largest=LARGEST,
        limits=limits,
        horizons=(20.0, 60.0),
        events=events,
        agents=3,
        event_rate=40.0,
    )
    real = np.array([capped.real(float(s)) for s in events])
    counts = np.bincount(np.floor(real / 0.5).astype(int))
    assert counts.max() <= 40.0 * 3 * 0.5 and counts.sum() == events.size
    # The burst takes at least 2000 / (40 x 3) s of real time; without the cap far less.
    assert capped.real(4.0) - capped.real(3.0) >= 2000 / 120 - 0.5
    assert plain.real(4.0) - plain.real(3.0) < 2.0
    # Every command stays within the limit as before (the cap only lowers κ).
    for s in np.linspace(0.0, 19.9, 2001):
        k = int(np.searchsorted(TIMES, s, side='right')) - 1
        assert capped.paper_rate(float(s)) * LARGEST[k] <= 1.0 / OBSERVED_MARGIN * (1 + 1e-12)


def test_the_events_cap_needs_room_for_an_event():
    with pytest.raises(LimitsError, match="the events' cap must allow at least one event a piece, got 0.5"):
        observed_warp(
            times=TIMES, largest=LARGEST, limits=LIMITS, horizons=(20.0, 60.0), events=[0.0], event_rate=1.0
        )
