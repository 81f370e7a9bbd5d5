"""The run's books without ROS traffic: which Status a coordinator refuses, when a lost agent or
recorder stops the run, which recorder heartbeats count, and the summary's saturation and lateness."""

from __future__ import annotations

import pytest

from formation_msgs_py.lockstep import DISCOVERY_STEP, Status
from formation_sim.model.scenario import load_scenario
from formation_sim.runtime.errors import (
    AgentLostError,
    ConnectivityLostError,
    CoordinatorError,
    RecorderLostError,
    RobotLostError,
)
from formation_sim.runtime.nodes.run_book import RecorderBook, RunBook


def _status(agent: int, **fields) -> Status:
    values = dict(
        step_index=0, next_time=1.0, info_sent=0, info_received=0, commands_sent=0, triggers=0, ready=True
    )
    return Status(agent=agent, **{**values, **fields})


def test_a_simulator_refuses_triggers_it_never_served_a_coordinator_learns_them_from_the_agents():
    scenario = load_scenario('paper_single')
    simulator = RunBook(scenario, realtime=True)
    with pytest.raises(CoordinatorError, match='agent 2 reports 1 triggers, but was due 0 times'):
        simulator.accept_status(_status(2, triggers=1))
    coordinator = RunBook(scenario, realtime=True, serves_sensing=False)
    assert coordinator.accept_status(_status(2, triggers=1, last_planned=0.0)) is True  # a new trigger
    assert coordinator.accept_status(_status(2, triggers=1, info_received=1)) is False
    with pytest.raises(CoordinatorError, match='agent 2: status went backwards'):
        coordinator.accept_status(_status(2, triggers=0))
    with pytest.raises(
        CoordinatorError, match=r'status from agent 9, which is not in the scenario \[1, 2, 3\]'
    ):
        coordinator.accept_status(_status(9))


def test_lateness_is_each_trigger_against_the_plan_its_status_announced():
    book = RunBook(load_scenario('paper_single'), realtime=True, serves_sensing=False)
    book.accept_status(_status(1, triggers=1, last_planned=0.0))
    book.accept_status(_status(1, triggers=2, last_planned=0.5))
    book.accept_status(_status(1, triggers=3, last_planned=0.9))  # its trigger not seen (run ended)
    extra = book.lateness({1: [0.01, 0.53], 2: [], 3: []})
    assert extra['lateness'] == {'1': {'max': 0.53 - 0.5, 'mean': (0.01 + (0.53 - 0.5)) / 2}}
    assert extra['max_lateness'] == 0.53 - 0.5


def test_agents_lost_together_are_named_together_after_the_grace():
    book = RunBook(load_scenario('paper_single'), realtime=True)
    for agent in (1, 2, 3):
        book.note_liveliness(agent, alive_count=1, not_alive_count_change=0, finished=False, now=0.0)
    book.note_liveliness(2, alive_count=0, not_alive_count_change=1, finished=False, now=10.0)
    book.note_liveliness(
        3, alive_count=0, not_alive_count_change=0, finished=False, now=10.2
    )  # its writer deleted
    assert (
        book.lost_error(10.4, started=True, where='at t=1.0 (step 0)') is None
    )  # within LOST_GRACE of the first
    error = book.lost_error(10.6, started=True, where='at t=1.0 (step 0)')
    assert isinstance(error, AgentLostError) and error.agents == [2, 3]
    assert str(error) == (
        'agents 2, 3 lost at t=1.0 (step 0): its node left the graph; no sign of life for 1.0 s '
        '(DDS liveliness lease); the run stops'
    )
    # During discovery a lapsed lease may come back (a busy machine): only the agent that left counts.
    assert book.lost_error(10.6, started=False, where='during discovery') is None  # 0.4 s after agent 3 left
    assert book.lost_error(10.8, started=False, where='during discovery').agents == [3]
    book.agents[1].status = _status(1, step_index=DISCOVERY_STEP, ready=False)
    assert book.not_ready() == [1, 2, 3]


def test_discovery_waits_for_every_agent_ready_and_an_agent_that_speaks_after_its_lease_lapsed_is_alive():
    book = RunBook(load_scenario('paper_single'), realtime=False)
    for agent in (1, 2, 3):
        book.note_liveliness(agent, alive_count=1, not_alive_count_change=0, finished=False, now=0.0)
    book.note_announcement(_status(1, step_index=DISCOVERY_STEP, ready=True))
    book.note_announcement(_status(2, step_index=DISCOVERY_STEP, ready=True))
    assert not book.all_announced() and not book.all_ready()
    book.note_announcement(_status(3, step_index=DISCOVERY_STEP, ready=False))
    assert book.all_announced() and not book.all_ready()
    book.note_announcement(_status(2, step_index=DISCOVERY_STEP, ready=False))  # a neighbour unmatched again
    book.note_announcement(_status(3, step_index=DISCOVERY_STEP, ready=True))
    assert not book.all_ready()
    book.note_liveliness(
        1, alive_count=0, not_alive_count_change=1, finished=False, now=1.0
    )  # a lease lapsed (busy machine)
    book.note_liveliness(
        3, alive_count=0, not_alive_count_change=0, finished=False, now=1.0
    )  # a writer deleted
    book.note_announcement(_status(1, step_index=DISCOVERY_STEP, ready=True))
    book.note_announcement(_status(3, step_index=DISCOVERY_STEP, ready=True))
    assert book.agents[1].lost is None  # it spoke: alive
    assert book.agents[3].lost is not None  # its node left: a late Status does not bring it back
    book.note_announcement(_status(2, step_index=DISCOVERY_STEP, ready=True))
    assert book.all_ready()


def test_a_recorder_lost_stops_the_run_after_the_grace_and_a_lapsed_lease_is_forgiven_during_discovery():
    recorders = RecorderBook()
    recorders.note_liveliness(alive_count=1, not_alive_count_change=0, now=0.0)
    recorders.note_liveliness(alive_count=0, not_alive_count_change=1, now=5.0)  # its lease expired (frozen)
    recorders.note_liveliness(
        alive_count=0, not_alive_count_change=0, now=5.3
    )  # the first loss is the one kept
    assert recorders.lost_error(5.5, started=True, where='at t=2.0 (step 7)') is None  # within LOST_GRACE
    error = recorders.lost_error(5.6, started=True, where='at t=2.0 (step 7)')
    assert isinstance(error, RecorderLostError)
    assert str(error) == (
        'the recorder lost at t=2.0 (step 7): no sign of life '
        'for 1.0 s (DDS liveliness lease: stopped or frozen?); '
        'what it did not acknowledge is overwritten, so the run stops'
    )
    assert recorders.lost_error(9.0, started=False, where='during discovery') is None  # it may come back
    recorders.note_liveliness(alive_count=1, not_alive_count_change=0, now=9.0)  # and it did
    assert recorders.lost is None
    recorders.note_liveliness(
        alive_count=0, not_alive_count_change=0, now=10.0
    )  # its writer deleted: it left
    assert str(recorders.lost_error(10.6, started=False, where='during discovery')).startswith(
        'the recorder lost during discovery: it left the graph;'
    )


def test_a_recorder_heartbeat_gives_its_latest_step_and_a_malformed_one_is_refused_with_the_reason():
    recorders = RecorderBook()
    assert recorders.accept_heartbeat('{"version": 1, "recorder": "/formation_recorder", "step": 4}') is None
    assert (
        recorders.accept_heartbeat('{"version": 1, "recorder": "/formation_recorder", "step": 3}') is None
    )  # late, out of order
    assert recorders.recorded_steps == {'/formation_recorder': 4}
    assert recorders.accept_heartbeat('{"version": 2, "recorder": "r", "step": 1}') == (
        """recorder heartbeat '{"version": 2, "recorder": "r", "step": 1}': version 2, step 1"""
    )
    assert recorders.accept_heartbeat('{"version": 1, "recorder": "r", "step": true}').endswith(
        'version 1, step True'
    )
    assert (
        recorders.accept_heartbeat('{"version": 1}') == """recorder heartbeat '{"version": 1}': 'recorder'"""
    )  # the field missing
    assert recorders.accept_heartbeat('not json').startswith("recorder heartbeat 'not json': Expecting value")
    assert recorders.recorded_steps == {'/formation_recorder': 4}


def test_a_recorder_heartbeat_names_the_watched_topics_it_has_not_heard_yet():
    recorders = RecorderBook()
    assert (
        recorders.accept_heartbeat(
            '{"version": 1, "recorder": "/r", "step": -1, "silent": ["/agent_2/robot/pose"]}'
        )
        is None
    )
    assert recorders.silent == {'/r': ['/agent_2/robot/pose']}
    assert recorders.accept_heartbeat('{"version": 1, "recorder": "/r", "step": -1, "silent": []}') is None
    assert recorders.silent == {'/r': []}
    assert (
        recorders.accept_heartbeat('{"version": 1, "recorder": "/q", "step": -1}') is None
    )  # watching nothing
    assert recorders.silent == {'/r': [], '/q': []}
    assert recorders.accept_heartbeat('{"version": 1, "recorder": "/r", "step": 0, "silent": [3]}').endswith(
        "': silent [3]"
    )
    assert recorders.accept_heartbeat('{"version": 1, "recorder": "/r", "step": 0, "silent": "/a"}').endswith(
        "': silent '/a'"
    )
    assert recorders.silent == {'/r': [], '/q': []}


def test_saturation_in_the_summary_adds_up_the_agents_reports():
    from dataclasses import dataclass

    from formation_sim.sim.summary import saturation_extra

    @dataclass
    class Clipped:  # the agent's AgentReport.saturation entries
        count: int
        largest_requested: float
        allowed: float

    @dataclass
    class Report:
        agent: int
        saturation: dict

    reports = [
        Report(1, {'linear_speed': Clipped(3, 0.31, 0.22), 'angular_speed': Clipped(0, 0.0, 2.84)}),
        Report(2, {'linear_speed': Clipped(2, 0.45, 0.22)}),
        None,  # an agent that never reported
        Report(4, {}),
    ]
    assert saturation_extra(reports) == {
        'total': 5,
        'by_kind': {'linear_speed': {'count': 5, 'largest_requested': 0.45, 'allowed': 0.22}},
        'by_agent': {'1': {'linear_speed': 3}, '2': {'linear_speed': 2}},
    }
    assert saturation_extra([None]) == {'total': 0, 'by_kind': {}, 'by_agent': {}}


def test_a_robot_silent_while_the_others_publish_is_lost_and_a_coordinator_that_slept_loses_none():
    from formation_sim.runtime.errors import RobotLostError
    from formation_sim.runtime.nodes.run_book import ALL_SILENT_AFTER, PoseWatch

    watch = PoseWatch([1, 2, 3, 4], silence=0.5)
    assert watch.silent(100.0) == []  # nothing heard yet (discovery)
    for robot in (1, 2, 3, 4):
        watch.note(robot, now=100.0, t=1.0)
    for robot in (1, 2, 4):  # robot 3 stops; the others go on
        watch.note(robot, now=100.6, t=1.6)
    assert watch.silent(100.6) == [3]
    assert watch.silent(100.6, fraction=2.0) == []
    error = watch.error([3], now=100.6, where='at t=1.6', topics='/agent_3/robot/true_odom')
    assert isinstance(error, RobotLostError) and error.kind == 'robot_lost' and error.agents == [3]
    assert str(error).startswith(
        'robot 3 lost at t=1.6: no pose on /agent_3/robot/true_odom '
        'for more than 0.5 s, while the other robots still published'
    )
    assert 'robot 3 at t=1.000 (0.60 s before)' in str(error)
    # A coordinator not scheduled for a while finds every robot equally old: none is lost ...
    watch = PoseWatch([1, 2], silence=0.5)
    watch.note(1, now=10.0, t=0.0)
    watch.note(2, now=10.0, t=0.0)
    assert watch.silent(10.0 + 0.5 + ALL_SILENT_AFTER) == []
    # ... unless all stay silent beyond the silence and ALL_SILENT_AFTER: every driver gone.
    assert watch.silent(10.0 + 0.5 + ALL_SILENT_AFTER + 0.01) == [1, 2]


def test_failures_are_the_agents_whose_final_report_names_an_error():
    from formation_msgs_py.lockstep import AgentReport

    book = RunBook(load_scenario('robots_square'), realtime=True, serves_sensing=False)
    book.accept_report(
        AgentReport(agent=1, final=True, rejected={}, failure='the pose of robot 2 is 0.6 s old')
    )
    book.accept_report(AgentReport(agent=2, final=False, rejected={}, failure='not final yet'))
    book.accept_report(AgentReport(agent=3, final=True, rejected={}))
    assert book.failures() == {1: 'the pose of robot 2 is 0.6 s old'}


def test_lock_step_waits_for_a_recorder_more_than_the_lag_behind_or_not_heard_yet():
    recorders = RecorderBook()
    assert not recorders.behind(9, recorders=0, lag=2)  # no recorder: never
    assert recorders.behind(0, recorders=1, lag=2)  # its first heartbeat not in yet
    recorders.accept_heartbeat('{"version": 1, "recorder": "/a", "step": 4}')
    assert not recorders.behind(6, recorders=1, lag=2) and recorders.behind(7, recorders=1, lag=2)
    assert recorders.behind(5, recorders=2, lag=2)  # the second recorder not heard yet
    recorders.accept_heartbeat('{"version": 1, "recorder": "/b", "step": 2}')
    assert recorders.behind(5, recorders=2, lag=2) and not recorders.behind(4, recorders=2, lag=2)


def _failure(error: BaseException, **overrides) -> dict:
    from formation_sim.runtime.nodes.run_book import failure_extra

    where = dict(interrupted=False, time=2.5, step=7, wall_time=1.25, detected_by='simulator')
    return failure_extra(error, **{**where, **overrides})


def test_a_failure_names_its_kind_agents_and_time_and_an_edge_its_length_and_a_start_its_breaches():
    from formation_sim.runtime.errors import InitialConditionError

    lost = _failure(AgentLostError('agent 2 lost', agents=[2]))
    assert lost == {
        'kind': 'agent_lost',
        'message': 'agent 2 lost',
        'agents': [2],
        'time': 2.5,
        'step': 7,
        'wall_time': 1.25,
        'detected_by': 'simulator',
    }
    edge = _failure(ConnectivityLostError('edge (2, 3) at Δ', time=1.75, edge=(2, 3), length=4.0))
    assert (edge['kind'], edge['agents'], edge['time']) == ('connectivity_lost', [2, 3], 1.75)  # its own time
    assert (edge['edge'], edge['length']) == ([2, 3], 4.0)
    breaches = [{'edge': [1, 2], 'length': 4.5}]
    start = _failure(InitialConditionError('apart', agents=[1, 2], breaches=breaches), step=None)
    assert start['kind'] == 'initial_condition' and start['breaches'] == breaches and start['step'] is None


def test_a_failure_without_words_is_named_by_its_kind_and_a_signal_is_an_interruption():
    assert (
        _failure(KeyboardInterrupt(), interrupted=True)['message'] == 'stopped by a signal (SIGINT/SIGTERM)'
    )
    assert _failure(KeyboardInterrupt(), interrupted=True)['kind'] == 'interrupted'
    error = _failure(ValueError(''))
    assert (error['kind'], error['message'], error['agents']) == ('error', 'ValueError', [])


def test_the_agents_that_stopped_after_the_first_cause_follow_it_in_its_message():
    from formation_sim.runtime.nodes.run_book import add_what_followed

    info = _failure(RobotLostError('robot 2 lost', agents=[2]))
    add_what_followed(info, {2: 'its pose stopped', 3: 'the pose of robot 2 is 0.52 s old', 1: 'likewise'})
    assert info['followed'] == {'3': 'the pose of robot 2 is 0.52 s old', '1': 'likewise'}
    assert info['message'] == 'robot 2 lost; then agents 1, 3 stopped: likewise'
    signal = _failure(KeyboardInterrupt(), interrupted=True)
    add_what_followed(signal, {1: 'stopped by a signal'})  # the signal stopped them all: nothing follows
    assert 'followed' not in signal and signal['message'] == 'stopped by a signal (SIGINT/SIGTERM)'
    add_what_followed(None, {1: 'why'})  # no failure: nothing to add to


def test_run_marks_say_when_the_run_reached_each_mark_on_a_clock_they_are_given():
    from formation_sim.runtime.nodes.run_book import RunMarks

    marks = RunMarks(created=100.0)  # monotonic seconds; the book reads no clock
    assert marks.discovery_wall_time == 0.0 and marks.since_start(104.0) == 4.0  # not started: from creation
    marks.mark('agents_announced', 101.0, once=True)
    marks.mark('agents_announced', 101.5, once=True)  # a later announcement round: the first counts
    marks.mark('node_up', 100.25)
    assert marks.timestamps(offset=1000.0) == {
        'node_created': 1100.0,
        'agents_announced': 1101.0,
        'node_up': 1100.25,
    }  # no step0, no final_step: a run that did not start
    marks.start(102.0)
    marks.finish(110.0)
    marks.finish(111.0)  # the final Step goes out once: the first time stands
    assert (marks.started, marks.finished_at, marks.discovery_wall_time) == (102.0, 110.0, 2.0)
    assert marks.since_start(112.5) == 10.5
    stamps = marks.timestamps(offset=-100.0)
    assert (stamps['step0'], stamps['final_step'], stamps['node_created']) == (2.0, 10.0, 0.0)
