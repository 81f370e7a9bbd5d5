"""A distributed lock-step run at a speed scale κ != 1 (docs/SPEED_SCALE.md) equals the in-process
engine bit for bit (real processes, private ROS domains 20-23): `formation run --speed-scale`
writes κ into every agent's parameters, the simulator's world closes it, the agents run it."""

from __future__ import annotations

import json

import pytest
import yaml

from formation_sim.cli import main
from formation_sim.model.scenario import load_scenario
from formation_sim.sim.engine import simulate

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group('formation_distributed')]


@pytest.mark.timeout(300)
@pytest.mark.parametrize(
    ('name', 'options', 'horizon', 'domain_id'),
    [
        ('paper_single', ['--speed-scale', '0.5'], 2.0, 20),
        ('paper_double', ['--speed-scale', '2.5', '--threshold-floor', '0.01'], 0.6, 21),
    ],
)
def test_a_scaled_lockstep_run_equals_the_engine_bit_for_bit_and_analyzes(
    tmp_path, name, options, horizon, domain_id
):
    out = tmp_path / 'run'
    code = main(
        [
            'run',
            name,
            *options,
            '--horizon',
            str(horizon),
            '--domain-id',
            str(domain_id),
            '--out',
            str(out),
            '--quiet',
            '--no-plot',
        ]
    )
    assert code == 0
    kappa = float(options[1])
    floor = float(options[3]) if len(options) > 2 else 0.0
    summary = json.loads((out / 'summary.json').read_text())
    reference = simulate(
        load_scenario(name).with_scale(speed_scale=kappa, threshold_floor=floor), horizon=horizon
    )
    assert reference.total_events > 3 * reference.scenario.n
    got = {int(agent): times for agent, times in summary['trigger_times'].items()}
    assert got == reference.trigger_times  # the same floats
    assert summary['messages_sent'] == reference.messages_sent
    agents = yaml.safe_load((out / 'agents.params.yaml').read_text())
    assert {node['ros__parameters']['speed_scale'] for node in agents.values()} == {kappa}
    assert {node['ros__parameters']['threshold_floor'] for node in agents.values()} == {floor}
    # The bag alone, analysed in real time (rates × κ, ξ_i / κ, the floor's bounds): every check holds.
    assert main(['analyze', str(out), '--no-figures', '--no-animation', '--quiet']) == 0
