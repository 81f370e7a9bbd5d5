"""The safety layer in the exact engine (docs/SAFETY.md): forward invariance of the separation and
of the edges on adversarial cases and seeded random placements, convergence, the layer off giving
main's events bit for bit, the scenario key and `formation simulate --min-separation`."""

from __future__ import annotations

import functools
import hashlib
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from formation_agent.core.safety import SafetyConfig
from formation_sim.cli import main
from formation_sim.model.errors import ScenarioError
from formation_sim.model.scenario import dump_scenario, load_scenario, scenario_from_dict, scenario_to_dict
from formation_sim.sim import safety_cases
from formation_sim.sim.engine import simulate
from formation_sim.sim.errors import EngineError

SAFETY = SafetyConfig(min_separation=0.25)
CASES = {
    'swap_two': safety_cases.swap_two,
    'swap_square': safety_cases.swap_square,
    'line_three': safety_cases.line_three,
    **{f'random_{seed}': functools.partial(safety_cases.random_square, seed) for seed in (1, 5, 13)},
}


@pytest.fixture(scope='module', params=sorted(CASES))
def case(request):
    scenario = CASES[request.param](safety=SAFETY)
    record = simulate(scenario, sample_dt=0.05)
    return scenario, record, np.asarray(record.samples.times), np.asarray(record.samples.positions)


def test_no_two_robots_come_closer_than_the_separation(case):
    """(S1)-(S3): h_ij(t) >= h_ij(0) e^{-γt} > 0; checked exactly between samples (every event is one)."""
    scenario, _, times, x = case
    closest, when, (a, b) = safety_cases.closest_approach(times, x)
    assert closest > SAFETY.min_separation, (closest, when, a, b)
    # the barrier's own bound, at every sample: ||r||² - D² >= (||r(0)||² - D²) e^{-γt}
    n = scenario.n
    for a in range(n):
        for b in range(a + 1, n):
            h = ((x[:, a] - x[:, b]) ** 2).sum(axis=1) - SAFETY.min_separation**2
            assert np.all(h >= h[0] * np.exp(-SAFETY.gamma * times) * (1 - 1e-9))


def test_every_edge_stays_within_its_capacity(case):
    """(S2), (S4): ||x_i - x_j - d_ij|| < Δ - ||d_ij||, so ||x_i - x_j|| < Δ (convex between samples)."""
    scenario, _, _, x = case
    heads, tails, d = scenario.edge_indices()
    y = np.linalg.norm(x[:, heads] - x[:, tails] - d, axis=2)
    assert np.all(y < scenario.delta - np.linalg.norm(d, axis=1))
    assert np.all(safety_cases.edge_maxima(scenario, x) < scenario.delta)


def test_the_team_reaches_the_formation_within_5_cm(case):
    scenario, _, times, x = case
    assert safety_cases.settling_time(scenario, times, x, 0.05) < 15.0


def test_every_agent_keeps_a_positive_inter_event_time(case):
    _, record, _, _ = case
    gaps = np.concatenate([np.diff(t) for t in record.trigger_times.values()])
    assert gaps.min() > 1e-3  # measured least: 0.06 s (docs/SAFETY.md)
    assert record.extra['safety']['min_separation'] == 0.25


@pytest.mark.parametrize('make', [safety_cases.swap_two, safety_cases.swap_square, safety_cases.line_three])
def test_without_the_layer_the_adversarial_cases_collide(make):
    """The cases are adversarial: ETA-1 alone drives robots through each other."""
    scenario = make(safety=None)
    record = simulate(scenario, sample_dt=0.05)
    closest, _, _ = safety_cases.closest_approach(record.samples.times, np.asarray(record.samples.positions))
    assert closest < 0.01


def test_head_on_swap_passes_on_the_right():
    """The tie-break turns each robot to its right: robot 1 (heading +x) passes below robot 2."""
    scenario = safety_cases.swap_two(safety=SAFETY)
    x = np.asarray(simulate(scenario, sample_dt=0.05).samples.positions)
    crossing = np.argmin(np.abs(x[:, 0, 0] - x[:, 1, 0]))
    assert x[crossing, 0, 1] < x[crossing, 1, 1]


def _digest(record) -> str:
    text = ';'.join(f'{i}:' + ','.join(t.hex() for t in ts) for i, ts in sorted(record.trigger_times.items()))
    text += '|' + ','.join(float(v).hex() for v in record.samples.positions[-1].ravel())
    return hashlib.sha256(text.encode()).hexdigest()


@pytest.mark.parametrize(
    ('name', 'events', 'digest'),
    [
        ('paper_single', 187, '8930d8f9c51da2762cb6173b4d3f506a7accb27e0e8d2793abeae621dd777e4d'),
        ('robots_square', 259, 'f1e00b3197536b0806a4de1d880625bead78619c6092da778fc651f08eae8638'),
    ],
)
def test_the_layer_off_gives_mains_events_bit_for_bit(name, events, digest):
    """Digests of every triggering time and the final state (float.hex) of main at b089890, before
    the layer existed."""
    record = simulate(load_scenario(name), sample_dt=0.0)
    assert record.total_events == events
    assert _digest(record) == digest
    assert 'safety' not in record.extra


def test_the_scenario_key_round_trips_and_is_checked(tmp_path):
    scenario = safety_cases.swap_square(safety=SafetyConfig(min_separation=0.3, gamma=3.0))
    data = scenario_to_dict(scenario)
    assert data['safety'] == {
        'min_separation': 0.3,
        'sensing_radius': 2.0,
        'gamma': 3.0,
        'max_speed': 0.5,
        'turn': 1.5,
    }
    assert scenario_from_dict(data) == scenario
    dump_scenario(scenario, tmp_path / 's.yaml')
    assert load_scenario(tmp_path / 's.yaml') == scenario
    assert 'safety' not in scenario_to_dict(scenario.replace(safety=None))
    for change, message in (
        ({'min_separation': 0.3, 'speed': 1}, "safety: unknown key 'speed'"),
        ({'min_separation': 0.3, 'gamma': 0}, 'safety.gamma: must be a finite number > 0, got 0'),
    ):
        with pytest.raises(ScenarioError, match=message):
            scenario_from_dict({**data, 'safety': change})
    scenario_from_dict({**data, 'safety': {'min_separation': 1.0}})  # closer than D: recovers (S9)
    one_point = {**data['agents'], 2: data['agents'][1]}
    with pytest.raises(
        ScenarioError, match=r'safety: agents 1 and 2 start at the same point \(0.0 m apart\)'
    ):
        scenario_from_dict({**data, 'agents': one_point})
    double = scenario_to_dict(load_scenario('paper_double'))
    with pytest.raises(ScenarioError, match="safety: the collision layer runs with dynamics 'single'"):
        scenario_from_dict({**double, 'safety': {'min_separation': 0.1}})


def test_the_periodic_baseline_is_refused_with_the_layer():
    with pytest.raises(EngineError, match='the safety layer runs with event triggering only'):
        simulate(safety_cases.swap_two(safety=SAFETY), period=0.1)


def test_simulate_min_separation_turns_the_layer_on(tmp_path, capsys):
    path = tmp_path / 'swap.yaml'
    dump_scenario(safety_cases.swap_two(safety=None, horizon=8.0), path)
    out = tmp_path / 'run'
    assert (
        main(['simulate', str(path), '--min-separation', '0.3', '--out', str(out), '--quiet', '--no-plot'])
        == 0
    )
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['extra']['safety']['min_separation'] == 0.3
    assert sum(summary['extra']['safety']['interventions'].values()) > 0
    capsys.readouterr()
    assert main(['simulate', 'paper_double', '--min-separation', '0.3', '--out', str(tmp_path / 'r2')]) == 2
    err = capsys.readouterr().err
    assert "argument --min-separation: safety: the collision layer runs with dynamics 'single'" in err
    assert not (tmp_path / 'r2').exists()
    assert math.isfinite(summary['horizon'])


def test_validate_min_separation_prints_the_layers_radii(tmp_path, capsys):
    path = tmp_path / 'swap.yaml'
    dump_scenario(safety_cases.swap_square(safety=None), path)
    assert main(['validate', str(path), '--min-separation', '0.25', '--json']) == 0
    data = json.loads(capsys.readouterr().out)
    # (2 v̄ + sqrt(4 v̄² + γ² D²)) / γ = (1 + sqrt(1.25)) / 2; (R - ρ*) / (2 v̄) = 2 - ρ*
    assert data['safety']['guard_radius'] == pytest.approx(1.0590169943749475)
    assert data['safety']['heartbeat'] == pytest.approx(2.0 - 1.0590169943749475)
    assert main(['validate', str(path), '--min-separation', '3.0']) == 2  # ρ* = (1 + sqrt(37)) / 2 > R = 2
    assert (
        'must exceed the guard radius ρ* = (2 v̄ + sqrt(4 v̄² + γ² D²)) / γ = 3.54138 m'
        in capsys.readouterr().err
    )


def test_a_distributed_run_takes_the_layer_on_every_backend():
    """Wired into the agents on the simulator and on robots (tests/formation_sim/runtime/
    test_safety_run.py); the scenario's own rules still refuse what the layer cannot run."""
    from formation_sim.runtime.launch.run_options import RunOptions

    safe = safety_cases.swap_two(safety=SAFETY)
    assert RunOptions().check(safe).backend == 'exact'
    assert RunOptions(clock='realtime').check(safe).clock == 'realtime'
    assert RunOptions(backend='holonomic').check(safe).backend == 'holonomic'


def test_a_stress_team_keeps_its_separation_and_reaches_the_formation(capsys):
    """The stress sweep's team 4 (5 robots, complete graph, D = 0.253 m), through its printer."""
    scenario = safety_cases.random_team(4)
    assert scenario.n == 5 and scenario.safety.min_separation == pytest.approx(0.253, abs=5e-4)
    safety_cases.main(['--stress', '4', '5'])
    line = capsys.readouterr().out
    closest = float(line.split('closest=')[1].split()[0])
    settle = float(line.split('to 5 cm=')[1].split()[0])
    assert closest > scenario.safety.min_separation and settle < 30.0


def test_the_builtin_robots_anywhere_is_its_seeded_draw_and_forms_with_the_default_layer():
    """robots_anywhere (docs/SCENARIOS.md): random_square(0) in a 2 m square, each pair > 0.3 m apart
    (> 0.46 m: the Burgers' default D_s applies); with that layer the exact run keeps every two
    control points 0.46 m apart and forms within 5 cm inside its horizon, edges below Δ."""
    from formation_sim.model.scenario import load_scenario
    from formation_sim.sim.engine import simulate

    builtin = load_scenario('robots_anywhere')
    drawn = safety_cases.random_square(0, safety=None, side=2.0)
    assert np.array_equal(builtin.positions, drawn.positions)
    assert {e.pair: tuple(e.d) for e in builtin.edges} == {e.pair: tuple(e.d) for e in drawn.edges}
    assert (builtin.delta, builtin.gains, builtin.n) == (4.0, drawn.gains, 4)
    assert np.all(builtin.positions >= 0.0) and np.all(builtin.positions <= 2.0)
    assert safety_cases._closest(builtin.positions) > 0.46
    scenario = builtin.replace(safety=SafetyConfig(min_separation=0.46))
    record = simulate(scenario, sample_dt=0.01)
    times, x = record.samples.times, np.asarray(record.samples.positions)
    assert safety_cases.closest_approach(times, x)[0] >= 0.46
    assert safety_cases.settling_time(scenario, times, x, 0.05) < builtin.horizon
    assert safety_cases.edge_maxima(scenario, x).max() < builtin.delta


INSIDE = SafetyConfig(min_separation=0.45)  # D_s of two Burgers 0.26 m apart by their origins


@pytest.mark.parametrize(
    'scenario',
    [
        safety_cases.swap_two(safety=INSIDE, gap=0.2),  # head on, set down 0.2 m apart
        safety_cases.line_three(safety=INSIDE, spacing=0.3),  # the middle one boxed in by both
        safety_cases.random_square(100, safety=INSIDE, side=2.2),  # issue 27: agents 1, 3 0.305 m apart
        safety_cases.random_square(101, safety=INSIDE, side=2.2),  # agents 2, 4 0.307 m apart
    ],
    ids=['head_on_0.2', 'line_0.3', 'random_100', 'random_101'],
)
def test_from_a_start_inside_the_margin_the_separation_grows_until_it_holds_then_is_never_lost(scenario):
    """(S9): every pair set down closer than D moves apart monotonically (the samples hold every
    event, between which motion is linear) until it is D apart, and from then on the exact closest
    approach stays >= D; pairs set down farther never come within D; the edges stay within Δ and
    the team forms (5 cm) within the horizon."""
    record = simulate(scenario, sample_dt=0.01)
    times, x = np.asarray(record.samples.times), np.asarray(record.samples.positions)
    d = INSIDE.min_separation
    inside = 0
    for a in range(x.shape[1]):
        for b in range(a + 1, x.shape[1]):
            gap = np.linalg.norm(x[:, a] - x[:, b], axis=1)
            if gap[0] < d:
                inside += 1
                k = int(np.argmax(gap >= d))
                assert k > 0 and times[k] < 1.0, (a, b, times[k])  # recovered within a second
                assert np.all(np.diff(gap[: k + 1]) >= 0.0), (a, b)
                start = k
            else:
                start = 0
            pair = x[start:, [a, b]]
            assert safety_cases.closest_approach(times[start:], pair)[0] >= d, (a, b)
    assert inside >= 1
    assert safety_cases.edge_maxima(scenario, x).max() < scenario.delta
    assert safety_cases.settling_time(scenario, times, x, 0.05) < scenario.horizon


def _safety_cases(*arguments: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, '-m', 'formation_sim.sim.safety_cases', *arguments],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def test_the_command_has_a_help_and_refuses_a_bad_seed_count_naming_the_rule_and_value():
    """`python -m formation_sim.sim.safety_cases --help` printed a traceback (int('--help')): now
    argparse's help, exit 0, nothing run; a count that is no integer >= 0 is refused by name, exit 2."""
    shown = _safety_cases('--help')
    assert shown.returncode == 0, shown.stderr
    assert shown.stdout.startswith('usage: python -m formation_sim.sim.safety_cases')
    assert (
        '--stress FIRST STOP' in shown.stdout and 'SEEDS' in shown.stdout and '| seed |' not in shown.stdout
    )
    for bad, complaint in (
        ('x', "argument SEEDS: must be an integer >= 0, got 'x'"),
        ('-3', 'argument SEEDS: must be an integer >= 0, got -3'),
    ):
        done = _safety_cases(bad)
        assert done.returncode == 2 and complaint in done.stderr, done.stderr
        assert 'Traceback' not in done.stderr and done.stdout == ''


@pytest.mark.parametrize(
    ('arguments', 'complaint'),
    [
        (['--stress', '5', '3'], 'argument --stress: FIRST must be < STOP, got FIRST 5 and STOP 3'),
        (['--stress', '4', '4'], 'argument --stress: FIRST must be < STOP, got FIRST 4 and STOP 4'),
        (['--stress', '1'], 'argument --stress: expected 2 arguments'),
        (['--stress', '0', 'y'], "argument --stress: must be an integer >= 0, got 'y'"),
        (
            ['3', '--stress', '1', '2'],
            'SEEDS and --stress exclude each other (the table or the sweep), got SEEDS 3',
        ),
    ],
)
def test_the_stress_sweep_refuses_a_bad_range_before_running_anything(capsys, arguments, complaint):
    with pytest.raises(SystemExit) as exited:
        safety_cases.main(arguments)
    captured = capsys.readouterr()
    assert exited.value.code == 2 and complaint in captured.err, captured.err
    assert captured.out == ''  # no table, no sweep line
