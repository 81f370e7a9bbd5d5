"""Strangers, duplicates and a frozen keeper without ROS: who may write which topic of a run, what
is found and named, which failure a keeper's freeze explains (issue 28)."""

from __future__ import annotations

import pytest

from formation_sim.model.scenario import load_scenario
from formation_sim.runtime.errors import (
    DuplicateAgentError,
    ForeignWriterError,
    KeeperFrozenError,
    RobotLostError,
)
from formation_sim.runtime.nodes.intruders import (
    FreezeWatch,
    GraphWatch,
    Watched,
    Writer,
    intrusions,
    protocol_watched,
    robot_watched,
    simulator_watched,
)

AGENT_2 = Writer(node='/agent_2/formation_agent', gid='01')
COORDINATOR = Writer(node='/formation_coordinator', gid='02')
ROGUE = Writer(node='/rogue', gid='0f')


def _command_2():
    (watched,) = [
        w
        for w in robot_watched(load_scenario('robots_square'), keeper='/formation_coordinator')
        if w.topic == '/agent_2/robot/cmd_vel'
    ]
    return watched


def test_a_robot_command_from_a_node_that_is_neither_its_agent_nor_the_coordinator_is_fatal_and_named():
    """The finding: an outside node on /agent_2/robot/cmd_vel drove robot 2 6 cm, nothing flagged."""
    watched = _command_2()
    assert intrusions(watched, [AGENT_2, COORDINATOR]) == []
    (found,) = intrusions(watched, [AGENT_2, ROGUE, COORDINATOR])
    assert found.fatal and found.kind == 'stranger'
    assert (
        found.text()
        == "a node outside the run, /rogue (writer gid 0f), writes robot 2's command (/agent_2/robot/cmd_vel)"
    )
    watch = GraphWatch([watched])
    assert watch.error() is None
    assert watch.note(watched, [AGENT_2, ROGUE], now=0.0) == [found]
    assert watch.note(watched, [AGENT_2, ROGUE], now=0.0) == []  # named once
    error = watch.error()
    assert isinstance(error, ForeignWriterError) and error.kind == 'foreign_writer'
    assert (
        str(error) == found.text() + ': the run stops' and error.nodes == ['/rogue'] and error.agents == [2]
    )
    assert watch.extra() == {
        'foreign_writers': [
            {
                'kind': 'stranger',
                'topic': '/agent_2/robot/cmd_vel',
                'writers': [{'node': '/rogue', 'gid': '0f'}],
            }
        ]
    }


def test_two_processes_claiming_one_agent_are_both_named():
    """The finding: a second agent 2 gave 'agent 2 is not due to sense at step 0 (due: [1, 2, 3])'."""
    (watched,) = [
        w for w in simulator_watched(load_scenario('paper_single')) if w.topic == 'rq/agent_2/senseRequest'
    ]
    assert watched.mangled and not watched.fatal
    twin = Writer(node='/agent_2/formation_agent', gid='aa')
    watch = GraphWatch([watched])
    (found,) = watch.note(watched, [twin, AGENT_2], now=0.0)
    assert found.fatal and found.text() == (
        'two processes claim agent 2: /agent_2/formation_agent (writer gid 01) and /agent_2/formation_agent '
        '(writer gid aa) both write rq/agent_2/senseRequest'
    )
    error = watch.error()
    assert isinstance(error, DuplicateAgentError) and error.kind == 'duplicate_agent' and error.agents == [2]


def test_a_stranger_on_a_protocol_topic_is_named_not_fatal_and_blamed_first_for_a_failure_that_follows():
    scenario = load_scenario('paper_single')
    watched = protocol_watched(scenario, keeper='/formation_simulator')
    assert len(watched) == 1 + 2 * len(scenario.edges)
    step = watched[0]
    assert step.topic == '/formation/step' and step.allowed == {'/formation_simulator'}
    watch = GraphWatch(watched)
    (found,) = watch.note(step, [Writer(node='/formation_simulator', gid='05'), ROGUE], now=0.0)
    assert not found.fatal and watch.error() is None
    assert watch.blame('agent 2 is not due to sense') == (
        'a node outside the run, /rogue (writer gid 0f), writes Steps (/formation/step); '
        'then: agent 2 is not due to sense'
    )


def test_a_second_writer_of_a_robots_poses_is_fatal_whoever_it_is():
    watched = Watched(topic='/agent_3/robot/odom', what="robot 3's poses", most=1, fatal=True)
    driver, other = Writer(node='/tb3_3/driver', gid='31'), Writer(node='/tb3_3/replay', gid='32')
    assert intrusions(watched, [driver]) == []
    (found,) = intrusions(watched, [driver, other])
    assert found.fatal and found.writers == (driver, other)


def test_the_graph_is_looked_at_a_slice_at_a_time_round_robin():
    watch = GraphWatch([Watched(topic=f'/t{k}', what='t') for k in range(5)])
    assert [w.topic for w in watch.due(2)] + [w.topic for w in watch.due(2)] + [
        w.topic for w in watch.due(2)
    ] == ['/t0', '/t1', '/t2', '/t3', '/t4', '/t0']
    assert GraphWatch([]).due(3) == []


def test_a_keeper_frozen_longer_than_the_lease_is_named_as_the_cause_of_what_it_then_saw_lost():
    """The finding: a coordinator frozen 3 s (SIGSTOP) said "robots 1, 2, 3, 4 lost" although the
    robots were fine."""
    watch = FreezeWatch(period=0.1)
    lost = RobotLostError('robots 1, 2, 3, 4 lost at t=2.5 (step 0)', agents=[1, 2, 3, 4])
    for k in range(10):
        watch.tick(100.0 + 0.1 * k)
    assert watch.blame(lost, 101.0, who='coordinator') is lost  # no freeze: the robots' loss stands
    blamed = watch.blame(lost, 104.0, who='coordinator')  # 3.1 s since its last tick, none since
    assert isinstance(blamed, KeeperFrozenError) and blamed.kind == 'keeper_frozen'
    assert str(blamed).startswith('the coordinator itself was stopped or starved for 3.00 s')
    assert str(blamed).endswith(': robots 1, 2, 3, 4 lost at t=2.5 (step 0)')
    watch.tick(104.0)  # the tick after the freeze: a loss seen soon after is still the freeze's
    assert isinstance(watch.blame(lost, 105.5, who='coordinator'), KeeperFrozenError)
    for k in range(61):
        watch.tick(104.0 + 0.1 * k)
    assert watch.blame(lost, 110.0, who='coordinator') is lost  # long after, ticking: a loss of its own
    interrupted = KeyboardInterrupt()
    assert watch.blame(interrupted, 104.0, who='coordinator') is interrupted


@pytest.mark.parametrize('gap', [0.5, 0.95])
def test_a_tick_a_little_late_is_no_freeze(gap):
    watch = FreezeWatch(period=0.1)
    watch.tick(0.0)
    watch.tick(0.1 + gap)
    error = RobotLostError('robot 2 lost', agents=[2])
    assert watch.ended_at is None and watch.blame(error, 0.1 + gap, who='simulator') is error


def test_a_sensing_call_is_a_trigger_only_when_the_agents_own_information_stamped_with_it_follows():
    """The finding: 500 calls a second to /agent_2/sense became agent 2's triggers (1 062 sensing
    calls for 63 events)."""
    from formation_sim.runtime.nodes.intruders import SensingCalls

    calls = SensingCalls([1, 2])
    for t in (0.5, 0.51, 0.52):  # a stranger's two calls, then agent 2's own
        calls.asked(2, t)
    calls.asked(2, 0.53)  # a stranger's again, after agent 2's
    assert not calls.triggered(2, 0.4)  # no call was answered at 0.4: a replay or a forgery
    assert calls.triggered(2, 0.52) and calls.triggers == 1
    assert not calls.triggered(2, 0.52)  # its copy
    assert calls.foreign == {1: 0, 2: 2}
    calls.foreign_call(1)
    assert calls.extra() == {'foreign_sensing_calls': {'1': 1, '2': 3}}  # 0.53 never became a trigger
    assert SensingCalls([1]).extra() == {}


def test_a_writer_whose_node_is_not_known_yet_is_judged_after_the_grace_and_named_once_its_name_comes():
    from formation_sim.runtime.nodes.intruders import UNKNOWN_GRACE

    watched = _command_2()
    unknown = Writer(node='_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_', gid='0f')
    watch = GraphWatch([watched])
    assert watch.note(watched, [AGENT_2, unknown], now=10.0) == []  # its name may be on its way
    assert watch.note(watched, [AGENT_2, unknown], now=10.0 + UNKNOWN_GRACE / 2) == []
    (found,) = watch.note(watched, [AGENT_2, unknown], now=10.0 + UNKNOWN_GRACE)
    assert found.text().startswith(
        'a node outside the run, a writer of no known ROS node (writer gid 0f), writes'
    )
    assert watch.note(watched, [AGENT_2, ROGUE], now=20.0) == []  # the same writer: not news, but now named
    assert str(watch.error()).startswith('a node outside the run, /rogue (writer gid 0f)')


def test_a_nameless_writer_named_late_as_the_agent_itself_is_taken_back():
    """The finding: a fresh-clone CI run named agent 2's own writer, seen before its node's name
    came, "a node outside the run", and blamed the run's failure on it."""
    from formation_sim.runtime.nodes.intruders import UNKNOWN_GRACE

    watched = _command_2()
    own = Writer(node='_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_', gid='0a')
    stranger = Writer(node='_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_', gid='0f')
    watch = GraphWatch([watched])
    watch.note(watched, [own, stranger], now=0.0)
    (found,) = watch.note(watched, [own, stranger], now=UNKNOWN_GRACE)
    assert [w.gid for w in found.writers] == ['0a', '0f']
    late = Writer(node=AGENT_2.node, gid='0a')
    assert watch.note(watched, [late, stranger], now=UNKNOWN_GRACE + 1) == []
    (kept,) = watch.found.values()
    assert [w.gid for w in kept.writers] == ['0f']  # the real stranger stays named
    watch.note(watched, [late, Writer(node=COORDINATOR.node, gid='0f')], now=UNKNOWN_GRACE + 2)
    assert watch.found == {} and watch.blame('the failure') == 'the failure'


def _status(agent, *, sent, received):
    from formation_msgs_py.lockstep import Status

    return Status(
        agent=agent,
        step_index=0,
        next_time=1.0,
        info_sent=sent,
        info_received=received,
        commands_sent=1,
        triggers=1,
        ready=True,
    )


def test_more_information_taken_than_sent_is_foreign_and_its_writer_named():
    """The finding: a forged but plausible TriggerInfo "from agent 2" on the wall clock gave agent
    1 813 events instead of ~81, and the run said done."""
    from formation_sim.runtime.errors import ForeignInformationError
    from formation_sim.runtime.nodes.intruders import foreign_information_error, information_excess

    honest = [_status(1, sent=10, received=12), _status(2, sent=12, received=10), None]
    assert information_excess(honest, slack=4) is None
    in_flight = [_status(1, sent=10, received=14), _status(2, sent=10, received=10)]  # a Status on its way
    assert information_excess(in_flight, slack=4) is None
    forged = [_status(1, sent=10, received=90), _status(2, sent=10, received=10)]
    assert information_excess(forged, slack=4) == (100, 20)
    (watched,) = [
        w
        for w in protocol_watched(load_scenario('paper_single'), keeper='/k')
        if w.topic == '/agent_2/trigger_info/to_1'
    ]
    watch = GraphWatch([watched])
    watch.note(watched, [AGENT_2, ROGUE], now=0.0)
    error = foreign_information_error(100, 20, watch)
    assert isinstance(error, ForeignInformationError) and error.kind == 'foreign_information'
    assert str(error) == (
        "a node outside the run, /rogue (writer gid 0f), writes agent 2's triggering information to agent 1 "
        '(/agent_2/trigger_info/to_1): the agents took 100 messages of triggering information, but sent only '
        '20: 80 came from outside the run, and the run is not its own any more: the run stops'
    )
    assert error.nodes == ['/rogue'] and error.agents == [2]
    assert str(foreign_information_error(100, 20, GraphWatch([]))).startswith(
        'no stranger seen in the graph yet: '
    )


def test_one_process_on_several_topics_is_named_once_with_every_topic():
    scenario = load_scenario('paper_single')
    watched = [
        w for w in protocol_watched(scenario, keeper='/k') + simulator_watched(scenario) if w.agent == 2
    ]
    twin = Writer(node='/agent_2/formation_agent', gid='aa')
    watch = GraphWatch(watched)
    for w in watched:
        watch.note(w, [AGENT_2, twin], now=0.0)
    topics = ', '.join(w.topic for w in watched)
    assert str(watch.error()) == (
        'two processes claim agent 2: /agent_2/formation_agent (writer gid 01) and /agent_2/formation_agent '
        f'(writer gid aa) both write {topics}: the run stops'
    )


def test_a_second_server_of_an_agents_sensing_service_is_fatal_and_named():
    """A stranger serving /agent_2/sense: agent 2's client may take its answer for the world's
    (an agent with the run's key refuses it and stops; one without would use it)."""
    (watched,) = [
        w for w in simulator_watched(load_scenario('paper_single')) if w.topic == 'rr/agent_2/senseReply'
    ]
    simulator = Writer(node='/formation_simulator', gid='05')
    assert intrusions(watched, [simulator]) == []
    (found,) = intrusions(watched, [simulator, ROGUE])
    assert found.fatal
    assert found.text() == (
        'a node outside the run, /rogue (writer gid 0f), writes answers of /agent_2/sense '
        '(rr/agent_2/senseReply)'
    )
