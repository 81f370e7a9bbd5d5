"""Communication and sensing: event triggering against periodic sampling and continuous control.

For one scenario and horizon:

* event-triggered (`engine.simulate`): triggering-information messages, sensing calls;
* periodic (`engine.simulate(period=P)`): the largest P (searched: a geometric scan down to the
  first period that works, then bisection) with which the run keeps every edge in range and ends
  with a formation error no larger than the event-triggered run's;
* continuous (`baselines.simulate_continuous`): no messages, sensing at every instant (the
  integrator's right-hand-side evaluations are reported).

Convergence time: the first sample time after which the formation error (max over edges of
||x_i - x_j - d_ij||) stays below `level`.
"""

from __future__ import annotations

import math
import time

import numpy as np

from formation_sim.model import theory


def convergence_time(record, level: float) -> float | None:
    errors = np.array([theory.formation_error(record.scenario, x) for x in record.sample_positions])
    above = np.flatnonzero(errors >= level)
    if not above.size:
        return 0.0
    if above[-1] == len(errors) - 1:
        return None  # not below the level at the horizon
    return float(record.sample_times[above[-1] + 1])


def _final_error(record) -> float:
    return theory.formation_error(record.scenario, record.sample_positions[-1])


def _periodic(scenario, horizon: float, period: float, target: float):
    """(works, record or reason) for periodic sampling with `period`."""
    from formation_sim.sim.engine import simulate
    from formation_sim.sim.errors import EngineError

    try:
        record = simulate(scenario, horizon=horizon, period=period, sample_dt=0.01)
    except (EngineError, ValueError) as error:
        return False, str(error).splitlines()[0][:120]
    final = _final_error(record)
    if not final <= target:
        return False, f'final formation error {final:.3g} > {target:.3g}'
    return True, record


def largest_period(
    scenario,
    horizon: float,
    target: float,
    *,
    start: float = 1.0,
    shrink: float = 2.0,
    refine: int = 4,
    floor: float = 1e-5,
):
    """Largest period that works (see the module docstring); (period, record, tried)."""
    tried = []
    period, failed = start, None
    while period >= floor:
        works, outcome = _periodic(scenario, horizon, period, target)
        tried.append((period, works or outcome))
        if works:
            break
        failed, period = period, period / shrink
    else:
        return None, None, tried
    best, record = period, outcome
    low, high = period, failed
    for _ in range(refine if high is not None else 0):
        middle = math.sqrt(low * high)
        works, outcome = _periodic(scenario, horizon, middle, target)
        tried.append((middle, works or outcome))
        if works:
            low, best, record = middle, middle, outcome
        else:
            high = middle
    return best, record, tried


def compare(scenario, *, horizon: float, level: float = 1e-3) -> dict:
    from formation_sim.sim.baselines import simulate_continuous
    from formation_sim.sim.engine import simulate

    started = time.perf_counter()
    event = simulate(scenario, horizon=horizon, sample_dt=0.01)
    target = _final_error(event)
    degree_sum = 2 * len(scenario.edges)
    rows = {
        'event-triggered': {
            'messages': event.messages_sent,
            'sensing_calls': event.sensing_calls,
            'events': event.total_events,
            'final_error': target,
            'convergence_time': convergence_time(event, level),
        }
    }
    period, periodic, tried = largest_period(scenario, horizon, target)
    if periodic is not None:
        samples = len(periodic.trigger_times[scenario.agent_ids[0]])
        rows['periodic'] = {
            'period': period,
            'messages': periodic.messages_sent,
            'sensing_calls': periodic.sensing_calls,
            'events': periodic.total_events,
            'final_error': _final_error(periodic),
            'convergence_time': convergence_time(periodic, level),
            'samples_per_agent': samples,
        }
        assert periodic.messages_sent == samples * degree_sum
    else:
        rows['periodic'] = {'period': None}
    rows['periodic']['search'] = [(p, w if w is True else str(w)) for p, w in tried]
    continuous = simulate_continuous(scenario, horizon=horizon, sample_dt=0.01)
    rows['continuous'] = {
        'messages': 0,
        'sensing_calls': math.inf,
        'rhs_evaluations': continuous.extra['rhs_evaluations'],
        'final_error': _final_error(continuous),
        'convergence_time': convergence_time(continuous, level),
    }
    return {
        'scenario': scenario.name,
        'n': scenario.n,
        'horizon': horizon,
        'level': level,
        'rows': rows,
        'wall_s': time.perf_counter() - started,
    }
