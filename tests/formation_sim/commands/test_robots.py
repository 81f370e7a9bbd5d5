"""`formation robots` refuses bad requests before it starts any robot."""

from __future__ import annotations

import pytest

from formation_sim.cli import main


@pytest.mark.parametrize(
    ('arguments', 'complaint'),
    [
        (['robots_square'], '--model holonomic|unicycle|car is required'),
        (
            ['robots_square', '--model', 'unicycle', '--domain-id', '300'],
            'argument --domain-id: must be an integer in [0, 232] (a ROS_DOMAIN_ID), got 300',
        ),
        (
            ['robots_square', '--model', 'unicycle', '--pose-noise', '-1'],
            'argument --pose-noise: must be a finite number >= 0, got -1.0',
        ),
        (
            ['robots_square', '--model', 'holonomic', '--max-speed', '0'],
            'argument --max-speed: must be a finite number > 0, got 0.0',
        ),
        (['no_such_scenario', '--model', 'unicycle'], 'no such scenario file and not a built-in scenario'),
    ],
)
def test_bad_robot_requests_are_refused_and_start_nothing(
    tmp_path, capsys, monkeypatch, arguments, complaint
):
    import subprocess

    def refuse(*args, **options):
        raise AssertionError(f'a process was started: {args}')

    monkeypatch.setattr(subprocess, 'Popen', refuse)
    domain = [] if '--domain-id' in arguments else ['--domain-id', '42']
    assert main(['robots', *arguments, *domain, '--out', str(tmp_path / 'fleet')]) == 2
    assert complaint in capsys.readouterr().err
    assert not (tmp_path / 'fleet').exists()
