"""The simulator node in one process: bad messages refused and counted, connectivity watched,
and what a run that stops early reports (no other process is started)."""

from __future__ import annotations

import numpy as np
import pytest

from formation_sim.model.scenario import load_scenario

pytestmark = pytest.mark.ros

DOMAIN_ID = 97


@pytest.fixture
def simulator(ros):
    from formation_sim.runtime.nodes.sim_node import FormationSimulatorNode

    nodes = []

    def build(scenario='paper_single'):
        node = FormationSimulatorNode(scenario=load_scenario(scenario), context=ros)
        nodes.append(node)
        return node

    yield build
    for node in nodes:
        node.destroy_node()


def test_with_the_runs_key_statuses_and_reports_without_its_tag_are_refused_as_foreign(ros, tmp_path):
    """docs/HOSTILE_TRAFFIC.md, Tags: the keeper's readers check the tag before decoding; what a
    holder of the key sends passes, once; summary.json counts untagged + forged as foreign."""
    from rclpy.parameter import Parameter

    from formation_msgs_py.codec import encode_agent_report, encode_status, tag_array, tag_string
    from formation_msgs_py.lockstep import DISCOVERY_STEP, AgentReport, Status
    from formation_msgs_py.tags import Signer, new_key, write_key
    from formation_msgs_py.topics import REPORT_TOPIC, STATUS_TOPIC
    from formation_sim.runtime.nodes.sim_node import FormationSimulatorNode
    from formation_sim.runtime.nodes.time_keeper import _tagged, message_counts

    key = new_key()
    node = FormationSimulatorNode(
        scenario=load_scenario('paper_single'),
        context=ros,
        parameter_overrides=[Parameter('key_file', value=str(write_key(tmp_path / 'run.key', key)))],
    )
    try:
        assert node.signer is not None and node.signer.writer == 'formation_simulator'
        status = Status(
            agent=2,
            step_index=DISCOVERY_STEP,
            next_time=1.0,
            info_sent=0,
            info_received=0,
            commands_sent=0,
            triggers=0,
            ready=False,
        )
        agent_2, stranger = Signer(key, writer='agent_2'), Signer(new_key(), writer='agent_2')
        taken = []
        _tagged(node, STATUS_TOPIC, encode_status(status), taken.append)  # untagged
        _tagged(node, STATUS_TOPIC, tag_array(encode_status(status), stranger, STATUS_TOPIC), taken.append)
        signed = tag_array(encode_status(status), agent_2, STATUS_TOPIC)
        _tagged(node, STATUS_TOPIC, signed, taken.append)
        _tagged(node, STATUS_TOPIC, signed, taken.append)  # a replay
        report = encode_agent_report(AgentReport(agent=2, final=False, rejected={}))
        _tagged(node, REPORT_TOPIC, report, taken.append)  # untagged
        _tagged(node, REPORT_TOPIC, tag_string(report, agent_2, REPORT_TOPIC), taken.append)
        assert [type(msg).__name__ for msg in taken] == ['Float64MultiArray', 'String']
        assert node.rejected == {'untagged': 2, 'forged': 1, 'replayed': 1}
        assert message_counts(node)['foreign_messages'] == 3
    finally:
        node.destroy_node()


def test_malformed_statuses_and_reports_are_refused_and_counted(simulator):
    from std_msgs.msg import Float64MultiArray, String

    from formation_msgs_py.codec import encode_agent_report
    from formation_msgs_py.lockstep import AgentReport
    from formation_sim.runtime.nodes.time_keeper import message_counts

    node = simulator()
    node._on_status(Float64MultiArray(data=[1.0, 2.0, 0.0]))  # too short
    node._on_status(Float64MultiArray(data=[3.0, 1, -1, 0.0, 0, 0, 0, 0, 1, 0.0]))  # layout version 3
    node._on_report(String(data='not json'))
    node._on_report(encode_agent_report(AgentReport(agent=9, final=True, rejected={})))  # no agent 9
    assert node.rejected == {'length': 1, 'version': 1, 'field': 2}
    assert all(book.status is None and book.report is None for book in node.agents.values())

    node._on_report(encode_agent_report(AgentReport(agent=2, final=True, rejected={'sender': 3}, dropped=4)))
    node._on_report(
        encode_agent_report(AgentReport(agent=2, final=False, rejected={}))
    )  # after the final one
    counts = message_counts(node)
    assert counts['rejected_messages'] == {
        'total': 3 + 4,
        'by_reason': {'field': 2, 'length': 1, 'sender': 3, 'version': 1},
        'by_agent': {'2': {'sender': 3}},
        'simulator': {'length': 1, 'version': 1, 'field': 2},
    }
    assert counts['injected_faults']['dropped'] == 4
    assert counts['reports_missing'] == [1, 3]


def test_an_edge_reaching_delta_stops_the_run_with_the_edge_time_and_waiting_agents(simulator):
    from formation_msgs_py.lockstep import Status
    from formation_sim.runtime.errors import ConnectivityLostError

    node = simulator()
    scenario = node.scenario
    x = np.array(scenario.positions, dtype=float)
    node.world.on_sample(0.0, x, None)  # the initial state: every edge shorter than Δ
    node.agents[3].status = Status(
        agent=3,
        step_index=4,
        next_time=np.inf,
        info_sent=2,
        info_received=1,
        commands_sent=1,
        triggers=1,
        ready=False,
    )
    k2, k3 = scenario.index(2), scenario.index(3)
    x[k3] = x[k2] - np.array([0.0, scenario.delta])  # edge (2, 3) exactly at Δ (not < Δ), the others short
    with pytest.raises(ConnectivityLostError) as caught:
        node.world.on_sample(1.25, x, None)
    error = caught.value
    assert (error.time, error.edge, error.length) == (1.25, (2, 3), scenario.delta)
    assert 'edge (2, 3) reached the communication radius at t=1.25' in str(error)
    assert "agents [3] are still waiting for a neighbour's triggering information" in str(error)
    node.marks.started = node.marks.created
    node.step = None
    node.fail(error)
    assert node.failure_info['kind'] == 'connectivity_lost'
    assert node.failure_info['time'] == 1.25 and node.failure_info['edge'] == [2, 3]


def test_a_run_stopped_early_counts_only_triggers_whose_command_acted(simulator):
    from formation_sim.runtime.errors import AgentLostError

    node = simulator()
    node.world.sampler.event()
    for book in node.agents.values():
        book.trigger_times = [0.0, 0.5]
        book.commands_received = 2
    node.agents[2].commands_received = 1  # sensed at 0.5, lost before its command
    node.fail(AgentLostError('agent 2 lost', agents=[2]))
    record = node.world.record()
    assert record.trigger_times == {1: [0.0, 0.5], 2: [0.0], 3: [0.0, 0.5]}
    assert record.extra['failure']['kind'] == 'agent_lost' and record.extra['failure']['agents'] == [2]


def test_discovery_says_what_it_still_waits_for(simulator):
    from formation_msgs_py.lockstep import DISCOVERY_STEP, Status
    from formation_sim.runtime.nodes.time_keeper import discovery_gaps

    node = simulator()  # alone in its domain: no agent has matched anything
    gaps = discovery_gaps(node)
    assert '/formation/step readers 0/3' in gaps
    assert '/formation/status writers 0/3' in gaps
    assert 'agents whose command writer is not matched: 1, 2, 3' in gaps
    assert 'agents not ready (their own endpoints unmatched): 1, 2, 3' in gaps
    ready = dict(
        step_index=DISCOVERY_STEP,
        next_time=0.0,
        info_sent=0,
        info_received=0,
        commands_sent=0,
        triggers=0,
        ready=True,
    )
    node.agents[2].status = Status(agent=2, **ready)
    node.agents[3].lost = (0.0, 'no sign of life')
    gaps = discovery_gaps(node)
    assert 'agents not ready (their own endpoints unmatched): 1, 3' in gaps
    assert 'agents whose liveliness lease expired: 3' in gaps
    assert not node._connected()


# -- sensing calls from outside the run (issue 28) --------------------------------------------------


def _rogue_client(ros, node, agent):
    """A node outside the run with a client of agent `agent`'s sensing service, seen in the graph."""
    import time

    import rclpy
    from rcl_interfaces.srv import SetParameters

    from formation_msgs_py.topics import sense_service

    rogue = rclpy.create_node('curious', namespace='/outside', context=ros)
    rogue.create_client(SetParameters, sense_service(agent))
    deadline = time.monotonic() + 10.0
    topic = f'rq{sense_service(agent)}Request'
    while not node.get_publishers_info_by_topic(topic, no_mangle=True) and time.monotonic() < deadline:
        time.sleep(0.05)
    return rogue


def test_a_sensing_call_out_of_turn_from_outside_is_refused_counted_and_its_caller_named(ros, simulator):
    """The finding: one call of /agent_2/sense from outside ended a lock-step run with "agent 2 is
    not due to sense", the caller never named.  With a stranger calling the service the call is
    refused and counted as foreign; at agent 2's own step the same state is given again; with no
    stranger it is agent 2's protocol violation, as before."""
    from formation_msgs_py.codec import decode_sensed_state
    from formation_msgs_py.lockstep import Step

    alone = simulator()
    assert alone.world.sensing.on_sense(2).results[0].successful is False
    assert str(alone.failure) == 'agent 2 is not due to sense at step -1 (due: [])'
    node = simulator()
    rogue = _rogue_client(ros, node, 2)
    try:
        refusal = node.world.sensing.on_sense(2)
        (result,) = refusal.results
        assert result.successful is False and result.reason.endswith(': refused')
        assert node.failure is None and node.world.sensing.calls.foreign == {1: 0, 2: 1, 3: 0}
        node.world.pacing.publish_step(Step(index=0, time=0.0, due=(1, 2, 3)))
        sense = node.world.sensing.on_sense
        first = decode_sensed_state(sense(2))  # the stranger's call, or agent 2's: one answer
        again = decode_sensed_state(sense(2))  # the other one: the same state again
    finally:
        rogue.destroy_node()
    assert again == first and node.failure is None
    assert node.world.sensing.sensing_calls == 1 and node.world.sensing.calls.foreign[2] == 2
    assert node.world.sensing.calls.extra() == {'foreign_sensing_calls': {'2': 2}}


def test_with_the_runs_key_a_sensing_call_without_the_agents_tag_is_refused_and_the_run_goes_on(
    ros, tmp_path
):
    """Issue 28 item 2: the sensing request carries the caller's tag.  A call without it (ros2
    service call, a stranger) or with another agent's is refused before the world is read,
    counted as a foreign call and a foreign message, never a trigger and never agent 2's fault;
    agent 2's own call is answered, with the simulator's tag."""
    from rclpy.parameter import Parameter

    from formation_msgs_py.codec import check_sensing_answer, decode_sensed_state, sensing_request
    from formation_msgs_py.lockstep import Step
    from formation_msgs_py.tags import Signer, Verifier, new_key, split_text, write_key
    from formation_msgs_py.topics import sense_service
    from formation_sim.runtime.nodes.sim_node import FormationSimulatorNode, _sense_call
    from formation_sim.runtime.nodes.time_keeper import message_counts

    key, service = new_key(), sense_service(2)
    node = FormationSimulatorNode(
        scenario=load_scenario('paper_single'),
        context=ros,
        parameter_overrides=[Parameter('key_file', value=str(write_key(tmp_path / 'run.key', key)))],
    )
    try:
        node.world.pacing.publish_step(Step(index=0, time=0.0, due=(1, 2, 3)))
        strangers = [
            sensing_request(None, service),
            sensing_request(Signer(new_key(), writer='agent_2'), service),
            sensing_request(Signer(key, writer='agent_3'), service),
        ]
        refusals = [_sense_call(node.world, 2, request).results[0] for request in strangers]
        assert [r.successful for r in refusals] == [False] * 3
        assert split_text(refusals[0].reason)[0] == f"{service}: a message without the run's tag: refused"
        answer = _sense_call(node.world, 2, sensing_request(Signer(key, writer='agent_2'), service))
        check_sensing_answer(Verifier(key), service, answer)  # the agent's check passes
        assert decode_sensed_state(answer).agent == 2
        assert node.failure is None and node.world.sensing.sensing_calls == 1
        assert node.world.sensing.calls.extra() == {'foreign_sensing_calls': {'2': 3}}
        assert node.rejected == {'untagged': 1, 'forged': 2}
        assert message_counts(node)['foreign_messages'] == 3
    finally:
        node.destroy_node()


def test_wall_clock_sensing_calls_are_triggers_only_when_the_agents_information_follows(simulator, ros):
    import time

    from rclpy.parameter import Parameter

    from formation_msgs_py.codec import decode_sensed_state, encode_trigger_info
    from formation_msgs_py.lockstep import STEP_FLAG_REALTIME, Step
    from formation_msgs_py.types import TriggerInfo
    from formation_sim.runtime.nodes.sim_node import FormationSimulatorNode, _on_trigger_info

    node = FormationSimulatorNode(
        scenario=load_scenario('paper_single'),
        parameter_overrides=[Parameter('clock_mode', value='realtime')],
        context=ros,
    )
    try:
        node.epoch = time.time()
        node.step = Step(index=0, time=0.0, flags=STEP_FLAG_REALTIME, epoch=node.epoch)
        stamps = [
            decode_sensed_state(node.world.sensing.on_sense(2)).stamp for _ in range(3)
        ]  # 2 foreign, then its own
        info = TriggerInfo(sender=2, receiver=1, stamp=stamps[1], control=(0.0, 0.0), rel_position=(1.0, 1.0))
        _on_trigger_info(node.world, encode_trigger_info(info), 2)
        assert node.agents[2].trigger_times == [stamps[1]] and node.world.sensing.sensing_calls == 1
        assert node.world.sensing.calls.extra() == {
            'foreign_sensing_calls': {'2': 2}
        }  # one before it, one never followed
    finally:
        node.destroy_node()
