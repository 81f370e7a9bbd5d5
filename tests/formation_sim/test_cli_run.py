"""`formation run` refuses bad requests before it starts any process."""

from __future__ import annotations

import pytest

from formation_sim.cli import main


@pytest.mark.parametrize(
    ('arguments', 'complaint'),
    [
        (['--domain-id', '300'], 'domain id must lie in [0, 232], got 300'),
        (['--agents-per-process', '0'], 'agents_per_process must be >= 1, got 0'),
        (['--horizon', '-1'], 'horizon must be a finite number > 0, got -1.0'),
    ],
)
def test_bad_run_requests_are_refused_with_the_rule_broken(tmp_path, capsys, arguments, complaint):
    assert main(['run', 'paper_single', '--out', str(tmp_path / 'run'), '--quiet', *arguments]) == 2
    assert complaint in capsys.readouterr().err
    assert not (tmp_path / 'run' / 'logs').exists()  # nothing was started


def test_an_existing_bag_is_never_overwritten(tmp_path, capsys):
    (tmp_path / 'run' / 'bag').mkdir(parents=True)
    assert main(['run', 'paper_single', '--out', str(tmp_path / 'run'), '--quiet']) == 2
    assert 'bag exists; the recorder never overwrites a bag' in capsys.readouterr().err


def test_an_unknown_scenario_is_refused(tmp_path, capsys):
    assert main(['run', 'no_such_scenario', '--out', str(tmp_path / 'run')]) == 2
    assert 'no such scenario file and not a built-in scenario' in capsys.readouterr().err
