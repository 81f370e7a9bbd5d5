"""`RunSummary` (formation_sim.sim.summary): summary.json read and written through one type, key
for key in the documented order, and the same bytes when read and written again."""

from __future__ import annotations

import json
import re

import pytest

from formation_sim.model.scenario import load_scenario
from formation_sim.sim import summary as summary_module
from formation_sim.sim.engine import simulate
from formation_sim.sim.errors import SummaryError
from formation_sim.sim.summary import (
    SCHEMA,
    SUMMARY_FILE,
    RunSummary,
    load_summary,
    run_failure,
    unstarted_summary,
    write_summary,
)


def _documented_keys() -> list[str]:
    """The top-level keys the module docstring documents, in its order."""
    keys = []
    for line in summary_module.__doc__.splitlines():
        if match := re.match(r'- (`\w+`(?:, `\w+`)*):', line):
            keys += [key.strip('`') for key in match.group(1).split(', ')]
    return keys


@pytest.mark.parametrize('name', ['paper_single', 'paper_double'])
def test_an_engine_runs_summary_is_in_the_documented_order_and_read_and_written_again_is_the_same_bytes(
    tmp_path, name
):
    record = simulate(load_scenario(name), horizon=3.0)
    path = write_summary(record, tmp_path / 'run')
    text = path.read_text()
    assert list(json.loads(text)) == _documented_keys()
    typed = RunSummary.read(tmp_path / 'run')  # the folder or the file
    assert typed.started and typed.failure is None and typed.total_events == record.total_events
    assert typed.trigger_times == {str(a): list(t) for a, t in record.trigger_times.items()}
    assert (typed.final_velocities is None) == (name == 'paper_single')
    again = typed.write(tmp_path / 'again.json')
    assert again.read_bytes() == path.read_bytes()
    assert load_summary(path) == json.loads(text)


def test_a_run_without_samples_has_none_of_the_sampled_keys_and_round_trips(tmp_path):
    failure = run_failure('discovery', 'agents 2 did not connect', agents=[2], detected_by='simulator')
    summary = unstarted_summary(load_scenario('paper_single'), horizon=5.0, mode='distributed', extra={})
    summary.extra['failure'] = failure
    path = summary.write(tmp_path / SUMMARY_FILE)
    data = json.loads(path.read_text())
    documented = _documented_keys()
    assert list(data) == [key for key in documented if key not in summary_module._SAMPLED_KEYS]
    assert 'trigger_times' in documented and 'trigger_times' not in data and data['wall_time'] is None
    typed = RunSummary.read(path)
    assert not typed.started and typed.failure == failure
    assert typed.write(tmp_path / 'again.json').read_bytes() == path.read_bytes()


def test_a_failure_has_its_keys_in_one_order_whoever_builds_it():
    # The time keeper's (every key), and the orchestrator's (no time, step, wall time known).
    full = run_failure(
        'connectivity_lost',
        'edge (1,2) reached Δ',
        edge=[1, 2],
        detected_by='simulator',
        wall_time=1.5,
        step=12,
        time=0.25,
        agents=(1, 2),
    )
    assert list(full) == ['kind', 'message', 'agents', 'time', 'step', 'wall_time', 'detected_by', 'edge']
    assert full['agents'] == [1, 2]
    bare = run_failure(
        'process_failed', 'agent_1 exited with status 1', agents=[], detected_by='orchestrator'
    )
    assert list(bare) == ['kind', 'message', 'agents', 'detected_by']


def test_what_is_not_a_summary_is_refused_naming_the_rule_and_the_value(tmp_path):
    path = tmp_path / SUMMARY_FILE
    good = unstarted_summary(load_scenario('paper_single'), horizon=5.0, mode='robots', extra={}).to_dict()
    cases = [
        ([1, 2], 'a summary is a JSON object, got list'),
        ({**good, 'schema': 'formation-summary/0'}, f"not a {SCHEMA} file (schema='formation-summary/0')"),
        ({k: v for k, v in good.items() if k != 'delta'}, "has the keys ['delta']; this one has not"),
        ({**good, 'colour': 'red'}, "keys a formation-summary/1 summary does not have: ['colour']"),
        ({**good, 'extra': []}, 'extra is an object, got list'),
        ({**good, 'trigger_times': {}}, "has the keys ['event_counts', 'total_events',"),
    ]
    for data, complaint in cases:
        path.write_text(json.dumps(data))
        with pytest.raises(SummaryError) as caught:
            RunSummary.read(path)
        assert str(caught.value).startswith(f'{path}: ') and complaint in str(caught.value), caught.value
    path.write_text('{"schema": ')
    with pytest.raises(ValueError, match=r'summary.json: not JSON \('):
        load_summary(path)
