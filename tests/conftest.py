"""Fixtures shared by every test package."""

from __future__ import annotations

import contextlib
import copy
import fcntl
import os

import pytest

if os.environ.get('CI'):
    # CI (which runs .ci/run with CI=true) runs the property tests on hypothesis' fixed examples, so that a
    # submission's CI run is repeatable; developers' runs draw new examples each time and keep the
    # failures they find in .hypothesis/ (a fresh-clone run found a cut odometry message that way).
    from hypothesis import settings as _hypothesis_settings

    _hypothesis_settings.register_profile('ci', derandomize=True, database=None)
    _hypothesis_settings.load_profile('ci')

# Section 5 of the paper, typed in from the text (not from the built-in YAML, so tests can compare).
_PAPER_SINGLE = {
    'name': 'typed_in',
    'dynamics': 'single',
    'communication_radius': 4.0,
    'horizon': 10.0,
    'agents': {1: {'position': [2.0, 4.0]}, 2: {'position': [3.5, 7.0]}, 3: {'position': [4.5, 5.5]}},
    'edges': [
        {'i': 1, 'j': 2, 'd': [0.0, -2.0]},
        {'i': 1, 'j': 3, 'd': [-2.0, 0.0]},
        {'i': 2, 'j': 3, 'd': [-2.0, 2.0]},
    ],
    'gains': {'alpha': 10.0, 'beta': 1.0},
}
_PAPER_VELOCITIES = {1: [1.0, 2.0], 2: [-1.0, -2.0], 3: [-1.0, -1.0]}
_PAPER_DOUBLE_GAINS = {'alpha_d': 10.0, 'beta_d': 1.0, 'beta1': 1.5, 'k3': 0.6}


def _paper_scenario_dict(dynamics: str = 'single', **gains: float) -> dict:
    """The paper's example as a fresh scenario dict; `gains` override single entries of its gains."""
    data = copy.deepcopy(_PAPER_SINGLE)
    if dynamics == 'double':
        data['dynamics'] = 'double'
        for agent, q in _PAPER_VELOCITIES.items():
            data['agents'][agent]['velocity'] = list(q)
        data['gains'] = dict(_PAPER_DOUBLE_GAINS)
    elif dynamics != 'single':
        raise ValueError(f"dynamics must be 'single' or 'double', got {dynamics!r}")
    data['gains'].update(gains)
    return data


@pytest.fixture(scope='session')
def paper_scenario_dict():
    """`paper_scenario_dict(dynamics='single', **gains) -> dict`: Section 5's example, a new copy each call.

    Double integrators get the paper's velocities and α_d = 10, β_d = 1, β1 = 1.5, k3 = 0.6.
    """
    return _paper_scenario_dict


@pytest.fixture(scope='session')
def long_run_scenario(tmp_path_factory) -> str:
    """A scenario file whose distributed run is still stepping when a test stops or kills part of it.

    Section 5's single-integrator example with β = 0.05 up to t = 600: ~3 000 events, tens of
    seconds of lock-step. (The example itself, β = 1, stops at the rounding floor at t ≈ 34.4 after
    about a second of stepping: a kill that comes later meets a finished run.)
    """
    import yaml

    data = _paper_scenario_dict(beta=0.05)
    data['name'] = 'long_run'
    data['horizon'] = 600.0
    path = tmp_path_factory.mktemp('long_run') / 'long_run.yaml'
    path.write_text(yaml.safe_dump(data))
    return str(path)


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's own, which reads the groups
def pytest_collection_modifyitems(items):
    """The tests that use `ros` (a module's own `DOMAIN_ID`) run on one pytest-xdist worker per
    module (`--dist loadgroup`): two tests of one module on two workers at once were one ROS domain
    with, say, two robots 1 publishing on one topic.  A test already in a group keeps it."""
    for item in items:
        if 'ros' in getattr(item, 'fixturenames', ()) and item.get_closest_marker('xdist_group') is None:
            item.add_marker(pytest.mark.xdist_group(f'ros_domain_{item.module.DOMAIN_ID}'))


@pytest.fixture(scope='module')
def ros(request, tmp_path_factory):
    """An rclpy context on the test module's own `DOMAIN_ID`, discovery limited to this machine; an id
    `formation run` may pick is held against runs of other tests (`testing.hold_domain`)."""
    import rclpy

    from formation_sim.runtime.launch.plan import DOMAIN_RANGE
    from formation_sim.runtime.testing import hold_domain

    os.environ.setdefault('ROS_LOG_DIR', str(tmp_path_factory.mktemp('ros_log')))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    domain = request.module.DOMAIN_ID
    with contextlib.ExitStack() as held:
        if DOMAIN_RANGE[0] <= domain <= DOMAIN_RANGE[1]:  # a run picking a free domain skips it
            held.enter_context(hold_domain(domain))
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        try:
            yield context
        finally:
            rclpy.shutdown(context=context)


@pytest.fixture(autouse=True)
def _share_of_the_machine(request, tmp_path_factory):
    """A test marked `alone` measures a wall-clock bound of the system (a safety stop's latency,
    a service's answer time): no other ROS test of the session runs beside it.  ROS tests share
    the machine with each other.

    Two locks in the session's base folder (shared by pytest-xdist's workers): every ROS test
    takes the gate, then the machine (shared, or exclusive when alone), then lets the gate go; an
    alone test that waits for the machine holds the gate, so the other worker cannot start ROS
    test after ROS test in front of it.  The bound itself is the system's: the test measures the
    run as on a machine that runs it, not one that also runs the other half of the suite.
    """
    marks = {mark.name for mark in request.node.iter_markers()}
    if not marks & {'ros', 'alone'}:
        yield
        return
    folder = tmp_path_factory.getbasetemp().parent
    with (
        open(folder / 'formation-tests.gate', 'a') as gate,
        open(folder / 'formation-tests.machine', 'a') as machine,
    ):
        fcntl.flock(gate, fcntl.LOCK_EX)
        try:
            fcntl.flock(machine, fcntl.LOCK_EX if 'alone' in marks else fcntl.LOCK_SH)
        finally:
            fcntl.flock(gate, fcntl.LOCK_UN)
        try:
            yield
        finally:
            with contextlib.suppress(OSError):
                fcntl.flock(machine, fcntl.LOCK_UN)
