"""Tests of `formation stop` (formation_sim.commands.stop): its refusals, its light start, and the
"no run answered" error on a domain where no run is (ROS domain 57).  A run stopped by it:
tests/formation_sim/runtime/nodes/test_operator_stop.py."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import threading
import time

import pytest

from formation_sim.commands import common, stop

DOMAIN_ID = 57  # no run ever uses it: nobody answers there


@pytest.mark.parametrize('text', ['0', '232', '233', '-1', 'x', '1.5', ''])
def test_its_domain_rule_is_common_domain_id_word_for_word(text):
    """The command has its own light argument types (no scenario model at start): the same rule
    and words as every other command's --domain-id."""

    def outcome(parse):
        try:
            return parse(text)
        except argparse.ArgumentTypeError as error:
            return str(error)

    assert outcome(stop._domain_id) == outcome(common.DOMAIN_ID)


@pytest.mark.parametrize('text', ['5', '0.01', '0', '-1', 'inf', 'nan', 'x'])
def test_its_timeout_rule_is_common_positive_word_for_word(text):
    def outcome(parse):
        try:
            return parse(text)
        except argparse.ArgumentTypeError as error:
            return str(error)

    assert outcome(stop._positive) == outcome(common.POSITIVE)


def _formation(*arguments: str, env: dict | None = None, code: str | None = None):
    command = (
        [sys.executable, '-m', 'formation_sim.cli', *arguments]
        if code is None
        else [sys.executable, '-c', code]
    )
    return subprocess.run(
        command, capture_output=True, text=True, timeout=120, check=False, env=env or dict(os.environ)
    )


def test_it_starts_without_the_scenario_model_and_refuses_bad_input_before_rclpy():
    """An emergency stop must not wait for scipy (seconds on a loaded machine): the command's
    parser is built alone, and a bad domain is refused before rclpy is loaded."""
    done = _formation(
        code=(
            'import sys\n'
            'from formation_sim.cli import main\n'
            "status = main(['stop', '--domain-id', '233'])\n"
            "heavy = {'scipy', 'rclpy', 'matplotlib', 'numpy'}\n"
            "heavy = sorted({m.split('.')[0] for m in sys.modules} & heavy)\n"
            'print(status, heavy)\n'
        )
    )
    assert done.stdout.strip() == '2 []', (done.stdout, done.stderr)
    assert 'argument --domain-id: must be an integer in [0, 232] (a ROS_DOMAIN_ID), got 233' in done.stderr


def test_a_bad_ros_domain_id_in_the_environment_is_named():
    done = _formation('stop', env={**os.environ, 'ROS_DOMAIN_ID': 'lab'})
    assert done.returncode == 2
    assert (
        "formation stop: error: ROS_DOMAIN_ID='lab' is not a ROS domain id (give --domain-id N)"
        in done.stderr
    )


@pytest.mark.ros
@pytest.mark.timeout(120)
@pytest.mark.parametrize('how', ['--domain-id', 'ROS_DOMAIN_ID'])
def test_no_run_answered_is_a_clear_failure_within_the_timeout(tmp_path, how):
    env = {**os.environ, 'ROS_LOG_DIR': str(tmp_path)}
    arguments = ['stop', '--timeout', '1']
    if how == '--domain-id':
        arguments += ['--domain-id', str(DOMAIN_ID)]
    else:
        env['ROS_DOMAIN_ID'] = str(DOMAIN_ID)
    began = time.monotonic()
    done = _formation(*arguments, env=env)
    spent = time.monotonic() - began
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert f'formation stop: no run answered on domain {DOMAIN_ID} within 1 s' in done.stderr
    assert done.stdout == '' and 'Traceback' not in done.stderr
    assert 1.0 <= spent < 1.0 + 30.0  # the wait itself, and a process's start on a loaded machine


@pytest.mark.ros
@pytest.mark.timeout(120)
def test_a_request_that_went_out_but_got_no_answer_is_not_called_no_run(tmp_path, ros):
    """A stop service that takes the request but answers late (a run stopping on a loaded machine):
    the command waits ANSWER_WAIT past a short --timeout, then says the request went out and the
    run may be stopping (exit 1), not that no service was reached."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_srvs.srv import Trigger

    from formation_msgs_py.topics import STOP_SERVICE

    taken = []

    def slow(request, response):
        taken.append(time.monotonic())
        time.sleep(stop.ANSWER_WAIT + 3.0)
        response.success, response.message = True, 'late'
        return response

    node = Node('slow_keeper', context=ros)
    node.create_service(Trigger, STOP_SERVICE, slow)
    executor = SingleThreadedExecutor(context=ros)
    executor.add_node(node)
    spinning = threading.Event()
    spinning.set()

    def spin() -> None:
        while spinning.is_set():
            executor.spin_once(timeout_sec=0.05)

    worker = threading.Thread(target=spin, daemon=True)
    worker.start()
    try:
        env = {**os.environ, 'ROS_LOG_DIR': str(tmp_path)}
        done = _formation('stop', '--domain-id', str(DOMAIN_ID), '--timeout', '3', env=env)
    finally:
        spinning.clear()
        worker.join(timeout=30.0)
        node.destroy_node()
    assert taken, done.stderr  # the request reached the service
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert (
        f'formation stop: no run answered on domain {DOMAIN_ID} within 3 s (the request went out to a '
        in (done.stderr)
    )
    assert 'but no answer came: that run may be stopping' in done.stderr
