"""An agent's neighbourhood without an agent: its edges checked (Assumption 1), and every check of
what an agent is handed, each refusal naming the agent, the rule and the value."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_agent.core.errors import AgentError
from formation_agent.core.errors import AgentError as EtaAgentError
from formation_agent.core.neighbourhood import Neighbourhood, positive
from formation_msgs_py.types import TriggerInfo


def _hood(**overrides) -> Neighbourhood:
    kwargs = {'agent_id': 1, 'neighbours': {3: (0.0, -2.0), 2: (-2.0, 0.0)}, 'delta': 4.0, **overrides}
    return Neighbourhood(**kwargs)


def _info(*, sender: int = 2, receiver: int = 1) -> TriggerInfo:
    return TriggerInfo(
        sender=sender, receiver=receiver, stamp=0.5, control=(0.0, 0.0), rel_position=(1.0, 1.0)
    )


def test_the_edges_keep_the_given_neighbour_order_and_their_capacities():
    hood = _hood()
    assert hood.ids == (3, 2) and hood.slot == {3: 0, 2: 1} and hood.dimension == 2
    assert np.array_equal(hood.offsets, [[0.0, -2.0], [-2.0, 0.0]])
    assert hood.capacity.tolist() == [2.0, 2.0]  # Δ - ||d_ij||
    assert hood.agent_id == 1 and hood.delta == 4.0


@pytest.mark.parametrize('dimension', [1, 2, 3, 4])
def test_offsets_and_capacities_are_the_floats_of_asarray_per_row_and_linalg_norm(dimension):
    # The constructor builds the rows in one numpy call and ||d_ij|| with norm's own formula: the
    # reference here is the former construction, np.asarray per row and np.linalg.norm.
    rng = np.random.default_rng(dimension)
    for trial in range(200):
        m = int(rng.integers(1, 9))
        scale = 10.0 ** rng.integers(-12, 12, size=(m, 1))
        rows = rng.normal(size=(m, dimension)) * scale
        delta = float(np.linalg.norm(rows, axis=-1).max()) * (1.0 + rng.random()) + 1e-300
        kinds = (tuple, list, np.asarray, lambda r: [int(v) if v.is_integer() else v for v in r.tolist()])
        neighbours = {j + 2: kinds[(trial + j) % 4](row) for j, row in enumerate(rows)}
        if np.any(delta - np.linalg.norm(rows, axis=-1) <= 0.0):
            continue
        hood = Neighbourhood(agent_id=1, neighbours=neighbours, delta=delta)
        expected = np.array([np.asarray(neighbours[j], dtype=float) for j in neighbours])
        assert hood.offsets.dtype == expected.dtype and hood.offsets.shape == expected.shape
        assert hood.offsets.tobytes() == expected.tobytes()
        capacity = delta - np.linalg.norm(expected, axis=-1)
        assert hood.capacity.tobytes() == capacity.tobytes()
        assert hood._capacity == capacity.tolist()


def _same_hood(team: Neighbourhood, alone: Neighbourhood) -> None:
    """Everything a Neighbourhood holds, byte for byte (floats by their bits, -0.0 and 0.0 apart)."""
    assert (team.agent_id, team.delta, team.ids, team.dimension) == (
        alone.agent_id,
        alone.delta,
        alone.ids,
        alone.dimension,
    )
    assert type(team.agent_id) is type(alone.agent_id) is int and type(team.delta) is float
    for mine, theirs in ((team.offsets, alone.offsets), (team.capacity, alone.capacity)):
        assert mine.dtype == theirs.dtype and mine.shape == theirs.shape and mine.flags.c_contiguous
        assert mine.tobytes() == theirs.tobytes()
    for mine, theirs in (
        (team._capacity, alone._capacity),
        (team.offset_rows, alone.offset_rows),
        (team.offset_rows3, alone.offset_rows3),
    ):
        assert np.array(mine).tobytes() == np.array(theirs).tobytes() and list(map(type, mine)) == list(
            map(type, theirs)
        )
    assert team.slot == alone.slot and team._ids == alone._ids


@pytest.mark.parametrize('dimension', [1, 2, 3, 4])
def test_a_teams_neighbourhoods_at_once_are_each_agents_own(dimension):
    # Neighbourhood.team: all d_ij in one np.array and all capacities in one call, sliced per agent; the
    # reference is the constructor per agent (itself checked against asarray and linalg.norm above).
    rng = np.random.default_rng(10 + dimension)
    for trial in range(60):
        n = int(rng.integers(1, 40))
        kinds = (tuple, list, np.asarray, lambda r: [int(v) if v.is_integer() else v for v in r.tolist()])
        team, scale = {}, 10.0 ** float(rng.integers(-12, 12))
        for i in range(n):
            others = [j for j in range(n + 5) if j != i]
            chosen = rng.choice(others, size=int(rng.integers(1, min(9, len(others) + 1))), replace=False)
            rows = (
                rng.normal(size=(len(chosen), dimension))
                * scale
                * 10.0 ** rng.integers(-3, 1, size=(len(chosen), 1))
            )
            rows[rng.random(size=rows.shape) < 0.05] = -0.0
            team[i] = {int(j): kinds[(trial + k) % 4](row) for k, (j, row) in enumerate(zip(chosen, rows))}
        delta = scale * 20.0 * (1.0 + rng.random())
        hoods = Neighbourhood.team(neighbours=team, delta=delta)
        assert hoods is not None and list(hoods) == list(team)
        for i, table in team.items():
            _same_hood(hoods[i], Neighbourhood(agent_id=i, neighbours=table, delta=delta))


@pytest.mark.parametrize(
    'bad',
    [
        {'neighbours': {}},
        {'neighbours': {1: (0.0, 1.0)}},
        {'delta': 0.0},
        {'delta': math.nan},
        {'neighbours': {2: (0.0, 1.0), 3: (1.0,)}},
        {'neighbours': {2: ()}},
        {'neighbours': {2: ('east', 1.0)}},
        {'neighbours': {2: (0.0, math.inf)}},
        {'neighbours': {2: (0.0, 1.0), 5: (0.0, -4.0)}},
        {'neighbours': {np.int64(2): (0.0, 1.0)}},
    ],
)
def test_a_team_with_a_neighbourhood_the_constructor_refuses_or_changes_is_left_to_it(bad):
    # None: the engine then builds each agent alone, and the constructor raises its error naming the rule
    # (or, for an id that is not an int, makes an int of it).
    team = {0: {1: (1.0, 0.0)}, 1: bad.get('neighbours', {0: (-1.0, 0.0)})}
    assert Neighbourhood.team(neighbours=team, delta=bad.get('delta', 4.0)) is None


def test_the_error_is_the_agents_error():
    assert AgentError is EtaAgentError and issubclass(AgentError, ValueError)


@pytest.mark.parametrize(
    ('overrides', 'message'),
    [
        ({'neighbours': {}}, r'^agent 1 has no neighbours: the graph must be connected$'),
        ({'neighbours': {1: (0.0, 1.0)}}, r'^agent 1 lists itself as a neighbour \(self-loop\)$'),
        ({'delta': 0.0}, r'^delta \(communication radius Δ\) must be a finite number > 0, got 0.0$'),
        ({'delta': math.nan}, r'must be a finite number > 0, got nan$'),
        ({'neighbours': {2: (0.0, 1.0), 3: (1.0,)}}, r'^agent 1: desired displacements must be vectors'),
        ({'neighbours': {2: ()}}, r'vectors of one dimension p >= 1$'),
        ({'neighbours': {2: ('east', 1.0)}}, r'vectors of one dimension p >= 1$'),
        ({'neighbours': {2: (0.0, math.inf)}}, r'^agent 1: desired displacements are not finite$'),
        ({'neighbours': {2: np.zeros(2), 3: np.zeros(3)}}, r'vectors of one dimension p >= 1$'),
        ({'neighbours': {2: np.zeros((1, 2))}}, r'vectors of one dimension p >= 1$'),
        ({'neighbours': {2: 1.0}}, r'vectors of one dimension p >= 1$'),
        ({'neighbours': {2: np.array([0.0, np.nan])}}, r'^agent 1: desired displacements are not finite$'),
        (
            {'neighbours': {2: (0.0, 1.0), 5: (0.0, -4.0)}},
            r'^edge \(1,5\): \|\|d_ij\|\| = 4.0 is not below Δ = 4.0 \(Assumption 1\)$',
        ),
    ],
)
def test_bad_edges_are_named_with_their_rule(overrides, message):
    with pytest.raises(AgentError, match=message):
        _hood(**overrides)


def test_positive_numbers_only():
    assert positive('tolerance', 1) == 1.0 and isinstance(positive('tolerance', 1), float)
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(AgentError, match=rf'^tolerance must be a finite number > 0, got {bad!r}$'):
            positive('tolerance', bad)


def test_vectors_are_p_finite_floats_and_the_template_is_filled_only_on_error():
    hood = _hood()
    assert hood.floats([1, 2.5], 'control from agent {}', 2) == (1.0, 2.5)
    assert hood.floats(np.array([0.25, -0.0]), 'unused {}', object()) == (0.25, -0.0)
    with pytest.raises(
        AgentError, match=r'^agent 1: control from agent 2 has shape \(3,\), expected \(2,\)$'
    ):
        hood.floats((1.0, 2.0, 3.0), 'control from agent {}', 2)
    with pytest.raises(AgentError, match=r'^agent 1: rel_position from agent 3 is not finite: \[nan, 0.0\]$'):
        hood.floats((math.nan, 0.0), 'rel_position from agent {}', 3)
    with pytest.raises(AgentError, match=r'has shape \(\), expected \(2,\)$'):
        hood.floats(1.0, 'a scalar')  # not iterable: numpy names its shape


def test_times_must_be_finite():
    hood = _hood()
    assert hood.time(1, 'trigger') == 1.0
    with pytest.raises(AgentError, match=r'^agent 1: information from agent 2 has a non-finite time inf$'):
        hood.time(math.inf, 'information from agent {}', 2)


def test_per_neighbour_values_cover_exactly_the_neighbours_in_their_order():
    hood = _hood()
    assert hood.rows({2: (1.0, 0.0), 3: (0.0, 1.0)}, 'sensed rel_positions') == [(0.0, 1.0), (1.0, 0.0)]
    for values, got in (
        ({2: (1.0, 0.0)}, r'\[2\]'),
        (None, 'None'),
        ({2: (0, 0), 3: (0, 0), 4: (0, 0)}, r'\[2, 3, 4\]'),
    ):
        with pytest.raises(
            AgentError,
            match=rf'^agent 1: sensed rel_positions must cover exactly its neighbours \[2, 3\], got {got}$',
        ):
            hood.rows(values, 'sensed rel_positions')
    with pytest.raises(AgentError, match=r'^agent 1: sensed rel_velocities\[3\] is not finite'):
        hood.rows({2: (1.0, 0.0), 3: (math.nan, 1.0)}, 'sensed rel_velocities')


def test_information_must_come_from_a_neighbour_to_this_agent():
    hood = _hood()
    assert hood.sender_slot(_info(sender=2)) == 1 and hood.sender_slot(_info(sender=3)) == 0
    with pytest.raises(AgentError, match=r'^agent 1 got information addressed to agent 3$'):
        hood.sender_slot(_info(receiver=3))
    with pytest.raises(
        AgentError, match=r'^agent 1 got information from agent 4, which is not a neighbour \[2, 3\]$'
    ):
        hood.sender_slot(_info(sender=4))


def test_edges_out_of_their_range_are_named():
    hood = _hood()
    hood.check_sensed_range([0.0, math.nextafter(2.0, 0.0)])  # just inside Δ - ||d_ij|| = 2
    with pytest.raises(
        AgentError,
        match=r'^agent 1: edge to agent 2 is out of its range: '
        r'\|\|x_i-x_j-d_ij\|\| = 2.0 >= Δ-\|\|d_ij\|\| = 2.0$',
    ):
        hood.check_sensed_range([0.0, 2.0])
    error = hood.out_of_range(0, 2.5, 2.0)
    assert isinstance(error, AgentError) and str(error) == (
        'agent 1: predicted edge to agent 3 left its range (||y_ij|| = 2.5 >= Δ-||d_ij|| = 2.0)'
    )
