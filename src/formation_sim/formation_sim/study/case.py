"""One case of a study: its team, its run through the exact engine (or a baseline), its row.

`scenario_of(case)` builds the team (formation_sim.model.generate.random_scenario),
`check_case(case)` validates it (formation_sim.model.validate) and `run_case(case)` runs it and
returns its row: the case's parameters, the scenario's key numbers, the run's summary numbers
(formation_sim.sim.summary.build_summary), for event-triggered runs the audit of the theorems'
guarantees (formation_sim.study.audit), and how long it took. A case that fails returns a row
with status 'failed' and its error; a row never depends on where or when it ran except for the
TIMING columns.
"""

from __future__ import annotations

import dataclasses
import math
import os
import socket
import time
import traceback
from typing import Any

from formation_sim.model.gains import beta_d_bound_corrected
from formation_sim.model.generate import random_scenario
from formation_sim.study.spec import PARAMETERS, Case

# The row's columns, in order (the results table's header).
CASE_COLUMNS = ('case', 'key', 'block', *PARAMETERS)
SCENARIO_COLUMNS = ('edges', 'beta0', 'rate', 'xi_min', 'beta_d_bound_paper', 'beta_d_bound_corrected')
RUN_COLUMNS = (
    'status',
    'error',
    'total_events',
    'events_per_agent',
    'messages_sent',
    'sensing_calls',
    'min_inter_event_time',
    'final_formation_error',
    'max_edge_length',
    'stop',
    'stop_time',
    'initial_formation_error',
)
AUDIT_COLUMNS = (
    'conn_checks',
    'conn_violations',
    'conn_margin',
    'max_edge_exact',
    'interior_maxima',
    'conv_checks',
    'conv_violations',
    'conv_margin',
    'zeno_checks',
    'zeno_violations',
    'zeno_margin',
    'printed_checks',
    'printed_violations',
    'printed_margin',
    'printed_first_violation',
)
TIMING_COLUMNS = ('wall_time', 'cpu_time', 'worker')
COLUMNS = CASE_COLUMNS + SCENARIO_COLUMNS + RUN_COLUMNS + AUDIT_COLUMNS + TIMING_COLUMNS


def scenario_of(case: Case):
    """The case's team: a random valid scenario of its family, gains and horizon."""
    p = case.params
    single = p['algorithm'] == 'eta1'
    options = (
        {}
        if single
        else {'beta1': p['beta1'], 'k3': p['k3'], 'beta_d': p['beta_d'], 'max_speed': p['max_speed']}
    )
    if single:
        options['beta'] = p['beta']
    if p['graph'] == 'geometric':
        options['degree'] = p['degree']
    scenario = random_scenario(
        n=p['n'],
        seed=p['seed'],
        dynamics='single' if single else 'double',
        dimension=p['p'],
        slack=p['slack'],
        delta=p['delta'],
        horizon=p['horizon'],
        alpha=p['alpha'],
        graph=p['graph'],
        name=f'case-{case.key}',
        **options,
    )
    if p['beta_d_bound'] == 'corrected' and p['beta_d'] is not None:  # of (2-k4)/λmax(P), not the printed
        rate = p['beta_d'] * beta_d_bound_corrected(scenario.gains)
        scenario = scenario.replace(gains=dataclasses.replace(scenario.gains, beta_d=rate))
    if p['speed_scale'] == 1.0 and p['threshold_floor'] == 0.0:
        return scenario
    gains = dataclasses.replace(
        scenario.gains, speed_scale=p['speed_scale'], threshold_floor=p['threshold_floor']
    )
    return scenario.replace(gains=gains)


def check_case(case: Case) -> str | None:
    """None if the case's team meets every hypothesis of its theorem, else what breaks it."""
    from formation_sim.model.validate import validate_scenario

    try:
        report = validate_scenario(scenario_of(case))
    except ValueError as error:
        return f'{case.describe()}: {error}'
    if report.ok:
        return None
    more = f' (and {len(report.errors) - 1} more)' if len(report.errors) > 1 else ''
    return f'{case.describe()}: {report.errors[0].format()}{more}'


def _scenario_numbers(scenario) -> dict[str, Any]:
    from formation_sim.model import theory

    constants = theory.theorem_constants(scenario)
    numbers = {'edges': len(scenario.edges), 'beta0': constants.beta0}
    if constants.theorem == 1:
        numbers['rate'] = scenario.gains.beta
    else:
        numbers.update(
            rate=scenario.gains.beta_d,
            beta_d_bound_paper=constants.beta_d_bound_paper,
            beta_d_bound_corrected=constants.beta_d_bound_corrected,
        )
    numbers['xi_min'] = None if constants.xi is None else min(constants.xi.values())
    return numbers


def _simulate(case: Case, scenario, watch):
    from formation_sim.sim.baselines import simulate_continuous
    from formation_sim.sim.engine import simulate

    p = case.params
    if p['sampling'] == 'continuous':
        return simulate_continuous(scenario, horizon=p['horizon'], sample_dt=p['horizon'] / 100.0)
    if p['sampling'] == 'periodic':
        return simulate(scenario, horizon=p['horizon'], sample_dt=0.0, period=p['period'])
    return simulate(
        scenario,
        horizon=p['horizon'],
        sample_dt=0.0,
        on_event=watch.on_event,
        until_error=p['until_error'],
        stop_at_floor=p['until_error'] is not None,
    )


def _run_numbers(case: Case, scenario) -> dict[str, Any]:
    from formation_sim.analysis.checks import run_series, theory_bounds
    from formation_sim.sim.summary import build_summary
    from formation_sim.study.audit import EdgeWatch, theorem_audit

    event = case.params['sampling'] == 'event'
    watch = EdgeWatch(scenario) if event else None
    record = _simulate(case, scenario, watch)
    summary = build_summary(record)
    gaps = [g for g in summary['min_inter_event_time'].values() if g is not None]
    numbers = {
        'status': 'ok',
        'total_events': summary['total_events'],
        'events_per_agent': summary['total_events'] / scenario.n,
        'messages_sent': summary['messages_sent'],
        'sensing_calls': summary['sensing_calls'],
        'min_inter_event_time': min(gaps) if gaps else None,
        'final_formation_error': summary['final_formation_error'],
        'max_edge_length': summary['max_edge_length'],
    }
    stop = record.extra.get('stop')
    if stop is not None:  # until_error: which stop ended the run (formation_sim.sim.stop)
        numbers.update(
            stop=stop['reason'], stop_time=stop['time'], initial_formation_error=stop['initial_error']
        )
    if event:
        watch.finish(record.horizon)
        numbers.update(watch.result())
        numbers.update(theorem_audit(record, run_series(record), theory_bounds(scenario)))
    return numbers


def run_case(case: Case) -> dict[str, Any]:
    """The case's row (COLUMNS): its run's numbers, or status 'failed' and the error."""
    wall, cpu = time.perf_counter(), time.process_time()
    row: dict[str, Any] = {'case': case.index, 'key': case.key, 'block': case.block, **case.params}
    try:
        scenario = scenario_of(case)
        row.update(_scenario_numbers(scenario))
        row.update(_run_numbers(case, scenario))
    except Exception as error:  # noqa: BLE001 - a failed case is a row, never the end of the study
        row['status'] = 'failed'
        row['error'] = f'{type(error).__name__}: {error}'.strip() or traceback.format_exc(limit=1)
    row['wall_time'] = time.perf_counter() - wall
    row['cpu_time'] = time.process_time() - cpu
    row['worker'] = f'{socket.gethostname()}:{os.getpid()}'
    return {column: _plain(row.get(column)) for column in COLUMNS}


def failed_row(case: Case, error: str) -> dict[str, Any]:
    """The row of a case that could not run at all (its worker died every time it was tried)."""
    row = {
        'case': case.index,
        'key': case.key,
        'block': case.block,
        **case.params,
        'status': 'failed',
        'error': error,
    }
    return {column: _plain(row.get(column)) for column in COLUMNS}


def _plain(value: Any) -> Any:
    """Python scalars only; non-finite floats as None (a CSV cell is then empty)."""
    if hasattr(value, 'item'):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
