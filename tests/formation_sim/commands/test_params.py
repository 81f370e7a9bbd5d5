"""`formation params`: the parameter files `formation run` writes, without a run; and the README's
commands that start a run by hand from them, run as written."""

from __future__ import annotations

import json
import os
import re
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from formation_sim.cli import main

README = Path(__file__).resolve().parents[3] / 'docs' / 'SEPARATE_MACHINES.md'  # moved from the README
DOMAIN_ID = 49
PARAMS_FILES = (
    'scenario.yaml',
    'agents.params.yaml',
    'recorder.params.yaml',
    'simulator.params.yaml',
    'coordinator.params.yaml',
    'robots.params.yaml',
)


def _written(folder: Path, run_folder: Path) -> dict[str, str]:
    """The input files in `folder`, with the folder's own path written as `run_folder`'s."""
    return {
        name: (folder / name).read_text().replace(str(folder.resolve()), str(run_folder.resolve()))
        for name in PARAMS_FILES
        if (folder / name).is_file()
    }


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
def test_params_writes_what_formation_run_wrote(distributed_single_run, tmp_path, capsys):
    run_folder = distributed_single_run.out_dir
    assert main(['params', 'paper_single', '--horizon', '2', '--out', str(tmp_path / 'inputs')]) == 0
    written = _written(tmp_path / 'inputs', run_folder)
    assert sorted(written) == [
        'agents.params.yaml',
        'recorder.params.yaml',
        'scenario.yaml',
        'simulator.params.yaml',
    ]
    assert written == {name: (run_folder / name).read_text() for name in written}
    assert sorted(p.name for p in (tmp_path / 'inputs').iterdir()) == sorted(
        [*written, 'run.key']
    )  # nothing else: no logs, no bag
    # Each folder its own key, readable by its owner only (docs/HOSTILE_TRAFFIC.md, Tags), named by
    # every node's parameters and held by none of them.
    key = tmp_path / 'inputs' / 'run.key'
    assert os.stat(key).st_mode & 0o777 == 0o600
    assert key.read_text() != (run_folder / 'run.key').read_text()
    agents = yaml.safe_load(written['agents.params.yaml'])
    assert {a['ros__parameters']['key_file'] for a in agents.values()} == {
        str((run_folder / 'run.key').resolve())
    }
    assert key.read_text().strip() not in ''.join(written.values())
    out = capsys.readouterr().out
    assert f'formation_sim --ros-args --params-file {tmp_path / "inputs" / "simulator.params.yaml"}' in out


def test_robot_backends_write_the_coordinators_and_the_robots_files(tmp_path, capsys):
    out = tmp_path / 'unicycle'
    assert (
        main(
            [
                'params',
                'robots_square',
                '--backend',
                'unicycle',
                '--max-speed',
                '0.22',
                '--no-record',
                '--out',
                str(out),
            ]
        )
        == 0
    )
    assert sorted(p.name for p in out.iterdir()) == [
        'agents.params.yaml',
        'coordinator.params.yaml',
        'robots.params.yaml',
        'run.key',
        'scenario.yaml',
    ]
    coordinator = yaml.safe_load((out / 'coordinator.params.yaml').read_text())['/formation_coordinator'][
        'ros__parameters'
    ]
    assert (coordinator['robot'], coordinator['backend'], coordinator['extra_subscribers']) == (
        'unicycle',
        'unicycle',
        0,
    )
    robot = yaml.safe_load((out / 'robots.params.yaml').read_text())['/agent_4/simulated_robot'][
        'ros__parameters'
    ]
    assert robot['robot_id'] == 4 and robot['max_linear_speed'] == 0.22
    printed = capsys.readouterr().out
    assert (
        f'formation_robot --robots 1,2,3,4 --ros-args --params-file {out / "robots.params.yaml"}' in printed
    )  # 8 robots to a process by default
    assert 'formation_recorder' not in printed
    assert (
        main(
            [
                'params',
                'robots_square',
                '--backend',
                'external',
                '--robot',
                'holonomic',
                '--out',
                str(tmp_path / 'external'),
            ]
        )
        == 0
    )
    assert not (tmp_path / 'external' / 'robots.params.yaml').exists()  # the robots are real ones


def test_an_occupied_folder_is_refused_unless_forced(tmp_path, capsys):
    out = tmp_path / 'inputs'
    assert main(['params', 'paper_single', '--out', str(out)]) == 0
    (out / 'summary.json').write_text('{}')  # a run was started by hand from it
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    capsys.readouterr()
    assert main(['params', 'paper_double', '--out', str(out)]) == 2
    assert 'already holds an earlier run' in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert main(['params', 'paper_double', '--out', str(out), '--force']) == 0
    assert not (
        out / 'summary.json'
    ).exists()  # the earlier run's files are gone, as with formation run --force
    assert (
        yaml.safe_load((out / 'agents.params.yaml').read_text())['/agent_1/formation_agent'][
            'ros__parameters'
        ]['algorithm']
        == 'eta2'
    )


def _readme_commands() -> list[str]:
    """The README's block that starts a run by hand (Agents on separate machines)."""
    block = re.search(
        r'```bash\n(\s*formation params paper_single .*?)```', README.read_text(), flags=re.DOTALL
    )
    assert block, 'docs/SEPARATE_MACHINES.md: the block starting with formation params paper_single is gone'
    return [line.strip() for line in block.group(1).splitlines() if line.strip()]


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_the_readmes_commands_run_a_formation_by_hand(tmp_path):
    """Each command as the README writes it (its folder moved under tmp_path), in its own process;
    the lock-step run they make is the in-process engine's, triggering time for triggering time."""
    from formation_agent.ros.process import teardown_status
    from formation_msgs_py.middleware import FASTDDS_PROFILE
    from formation_sim.model.scenario import load_scenario
    from formation_sim.runtime.launch.plan import with_our_packages
    from formation_sim.sim.engine import simulate

    commands = [command.replace('runs/by-hand', str(tmp_path / 'by-hand')) for command in _readme_commands()]
    assert [shlex.split(c)[0] for c in commands] == ['formation', 'formation_recorder', 'formation_sim'] + [
        'formation_agent'
    ] * 3
    env = with_our_packages(
        {
            **os.environ,
            'ROS_DOMAIN_ID': str(DOMAIN_ID),
            'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
            'ROS_LOG_DIR': str(tmp_path / 'ros_log'),
            'FASTRTPS_DEFAULT_PROFILES_FILE': str(FASTDDS_PROFILE),
        }
    )
    bin_dir = Path(sys.executable).parent

    def argv(command: str) -> list[str]:
        name, *rest = shlex.split(command)
        return [str(bin_dir / name), *rest]

    subprocess.run(argv(commands[0]), env=env, check=True, capture_output=True, timeout=120)
    processes = []
    try:
        for k, command in enumerate(commands[1:]):
            log = (tmp_path / f'process{k}.log').open('w')
            processes.append(
                subprocess.Popen(
                    argv(command), env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
                )
            )
        recorder, simulator, *agents = processes

        def left_cleanly(k: int) -> bool:
            """Exit 0, or 0 meant before its ROS teardown hung in C code and was cut short."""
            lines = (tmp_path / f'process{k}.log').read_text().splitlines()
            return processes[k].returncode == 0 or teardown_status(lines) == 0

        simulator.wait(timeout=240)
        assert left_cleanly(1), (tmp_path / 'process1.log').read_text()
        for k, agent in enumerate(agents, start=2):
            agent.wait(timeout=60)
            assert left_cleanly(k), (tmp_path / f'process{k}.log').read_text()
        time.sleep(0.5)
        recorder.send_signal(signal.SIGINT)
        recorder.wait(timeout=60)
        assert left_cleanly(0), (tmp_path / 'process0.log').read_text()
    finally:
        for process in processes:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
    summary = json.loads((tmp_path / 'by-hand' / 'summary.json').read_text())
    reference = simulate(load_scenario('paper_single'), horizon=10.0)
    assert summary['trigger_times'] == {str(agent): times for agent, times in reference.trigger_times.items()}
    assert (tmp_path / 'by-hand' / 'bag' / 'metadata.yaml').is_file()


def test_params_writes_the_safety_layer_formation_run_takes_on_robots(tmp_path, capsys):
    """Issue 27 leftover 2: the agents' files carry the layer as `formation run` sets it on robots:
    the Burgers' footprints by default (control points 0.46 m), --min-separation between origins,
    0 for off."""

    def agent_separation(*extra: str) -> float | None:
        out = tmp_path / '-'.join(['u', *extra])
        arguments = ['params', 'robots_square', '--backend', 'unicycle', '--no-record', '--out', str(out)]
        assert main([*arguments, *extra]) == 0
        agents = yaml.safe_load((out / 'agents.params.yaml').read_text())
        return agents['/agent_1/formation_agent']['ros__parameters'].get('min_separation')

    assert agent_separation() == pytest.approx(2 * 0.105 + 0.05 + 2 * 0.1)
    assert (
        "formation params: the safety layer keeps the robots' origins 0.26 m apart" in capsys.readouterr().err
    )
    assert agent_separation('--min-separation', '0.3') == pytest.approx(0.5)
    assert agent_separation('--min-separation', '0') is None  # the agent's default: the layer off
