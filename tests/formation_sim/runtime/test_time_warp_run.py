"""A time warp on simulated robots (docs/SPEED_SCALE.md, "A time warp"; real processes, private ROS
domain 203): `formation run --backend unicycle --speed-scale auto` (ETA-1 on robots: the warp)
hands the observed warp to every agent, which runs its core in the paper's time and sends
κ(t) u_p; the team forms within the limits, with no command clipped."""

from __future__ import annotations

import json

import pytest
import yaml

from formation_agent.core.time_warp import TimeWarp
from formation_sim.cli import main

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group('formation_distributed')]


@pytest.mark.timeout(300)
def test_a_warped_unicycle_run_forms_within_the_limits(tmp_path):
    out = tmp_path / 'run'
    limits = ['--max-speed', '0.22', '--max-angular-speed', '2.84']
    arguments = ['run', 'robots_lab', '--backend', 'unicycle', *limits, '--speed-scale', 'auto']
    code = main(
        [*arguments, '--horizon', '12', '--domain-id', '203', '--out', str(out), '--quiet', '--no-plot']
    )
    assert code == 0
    summary = json.loads((out / 'summary.json').read_text())
    chosen = summary['extra']['speed_scale']
    warp = TimeWarp(
        paper_starts=tuple(chosen['observed']['paper_starts']), rates=tuple(chosen['observed']['rates'])
    )
    agents = yaml.safe_load((out / 'agents.params.yaml').read_text())
    for node in agents.values():
        assert node['ros__parameters']['time_warp'] == warp.to_parameter()
        assert node['ros__parameters']['speed_scale'] == 1.0
    assert summary['extra']['saturation']['total'] == 0  # κ(t) u_p within 0.22 m/s all along
    # robots_lab forms to 5 % (24 mm) after 2.1 s in the exact warped run; the robots within 1 cm by 12 s
    assert summary['final_formation_error'] < 0.01
    assert summary['max_edge_length'] < 3.0  # Δ
