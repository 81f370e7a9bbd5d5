"""docs/PARAMETERS.md (scripts/parameters_doc.py) is what the nodes declare, and each node command
says so: `--help` lists every parameter and exits 0, bad parameters are all named at once (exit 2,
no traceback), and `ros2 param describe` (the parameter services) explains each one."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / 'scripts' / 'parameters_doc.py'
DOMAIN_ID = 48


def _specs(command: str):
    from formation_agent.ros.config import AGENT_PARAMETERS, GAIN_PARAMETERS
    from formation_sim.runtime.nodes.coordinator import COORDINATOR_PARAMETERS
    from formation_sim.runtime.nodes.recorder import RECORDER_PARAMETERS
    from formation_sim.runtime.nodes.robot_node import SPECS
    from formation_sim.runtime.nodes.sim_node import SIMULATOR_PARAMETERS

    return {
        'formation_agent': (*AGENT_PARAMETERS, *GAIN_PARAMETERS['eta1'], *GAIN_PARAMETERS['eta2']),
        'formation_sim': SIMULATOR_PARAMETERS,
        'formation_coordinator': COORDINATOR_PARAMETERS,
        'formation_recorder': RECORDER_PARAMETERS,
        'formation_robot': SPECS,
    }[command]


# Per command: ROS arguments with several bad or missing parameters, and what the error must say.
BAD = {
    'formation_agent': (
        ['-r', '__ns:=/agent_1', '-p', 'delta:=-1.0', '-p', 'algorithm:=eta3'],
        [
            "parameter 'delta' (double) must be > 0, got -1.0",
            "parameter 'algorithm' (string) must be one of 'eta1', 'eta2', got 'eta3'",
            "parameter 'horizon' (double) is required",
        ],
    ),
    'formation_sim': (
        ['-p', 'clock_mode:=fast', '-p', 'stall_timeout:=0.0'],
        [
            "parameter 'scenario' (string) is required",
            "parameter 'clock_mode' (string) must be one of 'lockstep', 'realtime', got 'fast'",
            "parameter 'stall_timeout' (double) must be > 0, got 0.0",
        ],
    ),
    'formation_coordinator': (
        [
            '-p',
            'scenario:=robots_square',
            '-p',
            'robot:=tank',
            '-p',
            'robot_trajectory:=gps',
            '-p',
            'horizon:=-3.0',
        ],
        [
            "parameter 'robot' (string) must be one of 'holonomic', 'unicycle', 'car', got 'tank'",
            "parameter 'robot_trajectory' (string) must be one of 'true_odom', 'odom', 'pose', got 'gps'",
            "parameter 'horizon' (double) must be >= 0, finite, got -3.0",
        ],
    ),
    'formation_recorder': (
        ['-p', 'drain_limit:=-1.0', '-p', "topics:=['nameless']"],
        [
            "parameter 'output' (string) is required",
            "parameter 'drain_limit' (double) must be > 0, finite, got -1.0",
            "parameter 'topics': topic spec 'nameless' is not of the form '/name:package/msg/Type'",
        ],
    ),
    'formation_robot': (
        ['-p', 'model:=tank', '-p', 'seed:=-1'],
        [
            "parameter 'robot_id' (int) is required",
            "parameter 'model' (string) must be one of 'holonomic', 'unicycle', 'car', got 'tank'",
            "parameter 'seed' (int) must be >= 0, got -1",
        ],
    ),
}


def _command(name: str) -> list[str]:
    script = Path(sys.executable).with_name(name)
    if script.exists():  # the console script of the installed package
        return [str(script)]
    module = {
        'formation_agent': 'formation_agent.ros.main',
        'formation_sim': 'formation_sim.runtime.nodes.sim_node',
        'formation_coordinator': 'formation_sim.runtime.nodes.coordinator',
        'formation_recorder': 'formation_sim.runtime.nodes.recorder',
        'formation_robot': 'formation_sim.runtime.nodes.robot_node',
    }[name]
    return [sys.executable, '-m', module]


def _env(tmp_path: Path) -> dict[str, str]:
    return {
        **os.environ,
        'ROS_DOMAIN_ID': str(DOMAIN_ID),
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'ROS_LOG_DIR': str(tmp_path / 'ros_log'),
    }


def test_the_document_is_what_the_nodes_declare():
    done = subprocess.run(
        [sys.executable, str(SCRIPT), '--check'], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    text = (ROOT / 'docs' / 'PARAMETERS.md').read_text()
    for command in BAD:
        documented = {
            line.split('`')[1]
            for line in text.split(f'`{command}`: node', 1)[1].split('\n## ', 1)[0].splitlines()
            if line.startswith('| `')
        }
        assert documented == {spec.name for spec in _specs(command)}, command
        assert all(spec.description for spec in _specs(command))


@pytest.mark.parametrize('command', sorted(BAD))
def test_help_lists_every_parameter(command):
    shown = subprocess.run([*_command(command), '--help'], capture_output=True, text=True, timeout=60)
    assert shown.returncode == 0 and shown.stderr == ''
    table = shown.stdout.split('parameters (--ros-args -p name:=value, or --params-file FILE):\n', 1)[1]
    rows = [line.split()[0] for line in table.splitlines() if line.startswith('  ')]
    assert rows == [spec.name for spec in _specs(command)]


@pytest.mark.ros
@pytest.mark.parametrize('command', sorted(BAD))
def test_bad_parameters_are_named_at_once_without_a_traceback(command, tmp_path):
    arguments, complaints = BAD[command]
    done = subprocess.run(
        [*_command(command), '--ros-args', *arguments],
        capture_output=True,
        text=True,
        env=_env(tmp_path),
        timeout=60,
    )
    assert done.returncode == 2, done.stderr
    assert 'Traceback' not in done.stderr and done.stderr.startswith(f'{command}: ')
    for complaint in complaints:
        assert complaint in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1  # one error, every problem in it


@pytest.mark.ros
def test_the_parameter_services_describe_each_parameter(tmp_path):
    """What `ros2 param describe /formation_recorder <name>` prints comes from here."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter_client import AsyncParameterClient

    from formation_sim.runtime.nodes.recorder import RECORDER_PARAMETERS

    recorder = subprocess.Popen(
        [*_command('formation_recorder'), '--ros-args', '-p', f'output:={tmp_path / "bag"}'],
        env=_env(tmp_path),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=DOMAIN_ID)
    node = rclpy.create_node('describer', context=context)
    try:
        client = AsyncParameterClient(node, '/formation_recorder')
        assert client.wait_for_services(timeout_sec=60.0), (
            recorder.stderr.read() if recorder.poll() is not None else 'no services'
        )
        future = client.describe_parameters([spec.name for spec in RECORDER_PARAMETERS])
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        deadline = time.monotonic() + 60
        while not future.done() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        described = {d.name: d for d in future.result().descriptors}
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        recorder.send_signal(2)
        recorder.wait(timeout=60)
    for spec in RECORDER_PARAMETERS:
        descriptor = described[spec.name]
        assert (descriptor.type, descriptor.description, descriptor.additional_constraints) == (
            spec.type.value,
            spec.description,
            spec.constraint_text(),
        )
        assert descriptor.read_only
    assert described['flush_period'].additional_constraints == '> 0, finite'
