"""`formation generate`: random valid teams as scenario files that read back exactly."""

from __future__ import annotations

import pytest

from formation_sim.cli import main
from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import load_scenario
from formation_sim.model.validate import validate_scenario


@pytest.mark.parametrize('suffix', ['.json', '.yaml'])
def test_the_file_is_the_generated_team_and_valid(tmp_path, capsys, suffix):
    out = tmp_path / f'team{suffix}'
    assert (
        main(
            [
                'generate',
                '--agents',
                '40',
                '--seed',
                '7',
                '--dynamics',
                'double',
                '--dimension',
                '3',
                '--horizon',
                '2',
                '--out',
                str(out),
            ]
        )
        == 0
    )
    assert capsys.readouterr().out.startswith(f'{out}: random_double_n40_seed7, 40 agents, ')
    team = load_scenario(out)
    assert team == random_scenario(n=40, seed=7, dynamics='double', dimension=3, horizon=2.0)
    assert validate_scenario(team).ok


def test_an_existing_file_is_kept_unless_forced(tmp_path, capsys):
    out = tmp_path / 'team.json'
    out.write_text('mine')
    assert main(['generate', '--agents', '5', '--out', str(out)]) == 2
    assert f'{out} exists; nothing was changed' in capsys.readouterr().err and out.read_text() == 'mine'
    assert main(['generate', '--agents', '5', '--out', str(out), '--force']) == 0
    assert load_scenario(out).n == 5


@pytest.mark.parametrize(
    ('arguments', 'complaint'),
    [
        (['--agents', '1'], 'argument --agents: a formation needs at least 2 agents, got 1'),
        (['--agents', '0'], 'argument --agents: must be an integer >= 1, got 0'),
        (['--agents', '5', '--slack', '1.5'], 'argument --slack: must be a number in (0, 1], got 1.5'),
        (['--agents', '5', '--degree', '-1'], 'argument --degree: must be a finite number > 0, got -1.0'),
        (['--agents', '5', '--colour', 'red'], 'unrecognized arguments: --colour red'),
    ],
    ids=['one agent', 'zero agents', 'slack', 'degree', 'unknown'],
)
def test_bad_arguments_write_nothing(tmp_path, capsys, arguments, complaint):
    out = tmp_path / 'team.json'
    assert main(['generate', *arguments, '--out', str(out)]) == 2
    assert complaint in capsys.readouterr().err and not out.exists()


def test_the_file_name_says_the_format(tmp_path, capsys):
    assert main(['generate', '--agents', '5', '--out', str(tmp_path / 'team.txt')]) == 2
    assert 'a scenario file ends in .json or .yaml' in capsys.readouterr().err
    assert main(['generate', '--agents', '5', '--out', str(tmp_path / 'no' / 'team.json')]) == 2
    assert f'no folder {tmp_path / "no"}' in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_a_team_too_large_for_yaml_is_refused_with_the_way_out(tmp_path, capsys, monkeypatch):
    import formation_sim.model.scenario as scenario_module

    monkeypatch.setattr(scenario_module, 'MAX_YAML_NODES', 500)  # ~9 000 agents, made small
    out = tmp_path / 'team.yaml'
    assert main(['generate', '--agents', '60', '--out', str(out)]) == 2
    err = capsys.readouterr().err
    assert 'holds more than 500 nodes' in err and 'nothing was written; write .json instead' in err
    assert not out.exists()
    assert main(['generate', '--agents', '60', '--out', str(tmp_path / 'team.json')]) == 0
