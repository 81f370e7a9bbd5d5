"""Scenario model: the paper's examples, the YAML schema, error messages, exact round trips."""

from __future__ import annotations

import copy
import math
from decimal import Decimal, getcontext

import numpy as np
import pytest
from scipy.linalg import solve_continuous_are

from formation_sim.model.errors import ScenarioError
from formation_sim.model.scenario import (
    DoubleGains,
    Edge,
    Scenario,
    SingleGains,
    builtin_scenarios,
    dump_scenario,
    load_scenario,
    scenario_from_dict,
    scenario_to_dict,
)
from formation_sim.model.validate import require_valid

# --------------------------------------------------------------------------- the paper's examples


def test_every_builtin_loads_under_its_name_and_is_valid():
    names = builtin_scenarios()
    assert {'paper_single', 'paper_double'} <= set(names)
    for name in names:
        scenario = load_scenario(name)
        assert scenario.name == name
        assert require_valid(scenario).ok  # a shipped scenario meets every hypothesis of its theorem


@pytest.mark.parametrize('name', ['paper_single', 'paper_double'])
def test_builtin_matches_section_5(name):
    s = load_scenario(name)
    assert s.name == name
    assert s.n == 3 and s.dimension == 2 and s.agent_ids == (1, 2, 3)
    assert s.delta == 4.0 and s.horizon == 10.0
    np.testing.assert_array_equal(s.positions, [[2.0, 4.0], [3.5, 7.0], [4.5, 5.5]])
    assert {e.pair: tuple(e.d) for e in s.edges} == {
        (1, 2): (0.0, -2.0),
        (1, 3): (-2.0, 0.0),
        (2, 3): (-2.0, 2.0),
    }


def test_paper_single_gains():
    s = load_scenario('paper_single')
    assert s.dynamics == 'single' and s.velocities is None
    assert s.gains == SingleGains(alpha=10.0, beta=1.0)


def test_paper_double_gains_match_the_printed_numbers():
    s = load_scenario('paper_double')
    g = s.gains
    np.testing.assert_array_equal(s.velocities, [[1.0, 2.0], [-1.0, -2.0], [-1.0, -1.0]])
    assert (g.alpha_d, g.beta_d, g.beta1) == (10.0, 1.0, 1.5)
    # Section 5 prints P = [[5.0237, 1.1547], [1.1547, 1.4502]], k3 = 0.6053.
    np.testing.assert_allclose(g.P, [[5.0237, 1.1547], [1.1547, 1.4502]], atol=5e-5)
    assert (g.k1, g.k2) == (g.P[0, 1], g.P[1, 1])
    assert round(g.k3, 4) == 0.6053
    # The same P from scipy's Riccati solver: (riccatti) times 2 is C^T P + P C - 2β1 P B B^T P + 4I = 0.
    C = np.array([[0.0, 1.0], [0.0, 0.0]])
    B = np.array([[0.0], [1.0]])
    P_scipy = solve_continuous_are(C, B, 4.0 * np.eye(2), np.array([[1.0 / (2.0 * 1.5)]]))
    np.testing.assert_allclose(g.P, P_scipy, rtol=1e-12)
    # k3 = 2 / (k2 + sqrt(k1² + k2²)) to full precision, from a 50-digit evaluation of the closed form.
    getcontext().prec = 50
    k1 = (Decimal(2) / Decimal('1.5')).sqrt()
    k2 = ((k1 + 2) / Decimal('1.5')).sqrt()
    k3 = Decimal(2) / (k2 + (k1 * k1 + k2 * k2).sqrt())
    assert g.k3 == pytest.approx(float(k3), rel=4e-16)


def test_neighbours_carry_the_sign_for_the_asking_agent():
    s = load_scenario('paper_single')
    np.testing.assert_array_equal(s.neighbours(1)[2], [0.0, -2.0])  # d_12
    np.testing.assert_array_equal(s.neighbours(2)[1], [0.0, 2.0])  # d_21 = -d_12
    np.testing.assert_array_equal(s.neighbours(3)[2], [2.0, -2.0])  # d_32 = -d_23
    assert sorted(s.neighbours(3)) == [1, 2]
    with pytest.raises(ScenarioError, match='unknown agent 7'):
        s.neighbours(7)


def test_arrays_are_read_only_and_replace_checks_again():
    s = load_scenario('paper_single')
    with pytest.raises(ValueError):
        s.positions[0, 0] = 1.0
    with pytest.raises(ValueError):
        s.edges[0].d[0] = 1.0
    moved = s.replace(positions=s.positions + 1.0)
    assert moved != s and moved.edges == s.edges
    with pytest.raises(ScenarioError, match='horizon'):
        s.replace(horizon=-1.0)


def test_scenario_from_dict_equals_the_builtin(paper_scenario_dict):
    s = scenario_from_dict(paper_scenario_dict('single'))
    assert s == load_scenario('paper_single').replace(name='typed_in')


def test_json_style_string_agent_ids_are_read_as_integers(paper_scenario_dict):
    data = paper_scenario_dict('single')
    data['agents'] = {str(k): v for k, v in data['agents'].items()}
    assert scenario_from_dict(data) == scenario_from_dict(paper_scenario_dict('single'))
    data['agents']['1'] = {'position': [0.0, 0.0]}
    data['agents'][1] = {'position': [0.0, 0.0]}
    with pytest.raises(ScenarioError, match='agent 1 is listed twice'):
        scenario_from_dict(data)


def test_name_falls_back_to_the_keyword(paper_scenario_dict):
    data = paper_scenario_dict('single')
    del data['name']
    assert scenario_from_dict(data, name='fallback').name == 'fallback'


# --------------------------------------------------------------------------- round trips


def awkward_scenario() -> Scenario:
    """Floats that a decimal round trip would lose: 0.1, 1/3, subnormal, next-after, -0.0."""
    x = np.array([[0.1, 1.0 / 3.0, -0.0], [np.nextafter(2.0, 3.0), 5e-324, 1e300], [7.0, -1e-7, 2.5]])
    return Scenario(
        name='awkward',
        dynamics='double',
        delta=math.pi,
        agent_ids=(3, 10, 42),
        positions=x,
        velocities=x[::-1] * 0.3,
        edges=(
            Edge(i=10, j=3, d=np.array([0.1 + 0.2, -1.0 / 7.0, 1e-310])),
            Edge(i=3, j=42, d=np.array([1.0, 2.0, 3.0])),
        ),
        gains=DoubleGains(
            alpha_d=0.7,
            beta_d=1e-3,
            beta1=2.0 / 3.0,
            k3=0.123456789012345678,
            k1=1.1,
            k2=2.2,
            P=np.array([[9.75, 1.1], [1.1, 2.2]]),
        ),
        horizon=12.5,
    )


@pytest.mark.parametrize(
    'make', [lambda: load_scenario('paper_single'), lambda: load_scenario('paper_double'), awkward_scenario]
)
@pytest.mark.parametrize('suffix', ['.yaml', '.json', '.JSON'])
def test_dict_and_file_round_trips_are_exact(make, tmp_path, suffix):
    s = make()
    assert scenario_from_dict(scenario_to_dict(s)) == s
    path = tmp_path / f'scenario{suffix}'
    dump_scenario(s, path)
    json_file = suffix.lower() == '.json'
    assert path.read_text().startswith('{') == json_file  # the format follows the name
    loaded = load_scenario(path)
    assert loaded == s
    np.testing.assert_array_equal(loaded.positions.view(np.int64), s.positions.view(np.int64))  # bit for bit
    if s.velocities is not None:
        np.testing.assert_array_equal(loaded.velocities.view(np.int64), s.velocities.view(np.int64))


def test_dict_round_trip_keeps_explicit_riccati_gains(paper_scenario_dict):
    data = paper_scenario_dict('double')
    data['gains'].update(k1=1.2, k2=1.5)
    s = scenario_from_dict(data)
    assert (s.gains.k1, s.gains.k2) == (1.2, 1.5)
    assert s.gains.k0 == 2.0 * 1.5 * 1.2 * 1.5  # default k0 = 2 β1 k1 k2
    out = scenario_to_dict(s)
    assert out['gains']['k1'] == 1.2 and out['gains']['k0'] == s.gains.k0
    assert scenario_from_dict(out) == s


def test_riccati_gains_are_not_dumped_when_they_follow_from_beta1():
    out = scenario_to_dict(load_scenario('paper_double'))
    assert set(out['gains']) == {'alpha_d', 'beta_d', 'beta1', 'k3'}


def test_equality_sees_every_field():
    s = load_scenario('paper_double')
    assert s == load_scenario('paper_double')
    assert s != s.replace(velocities=s.velocities * 2.0)
    assert s != s.replace(edges=s.edges[:2])
    assert s != s.replace(gains=DoubleGains.from_riccati(alpha_d=10.0, beta_d=1.0, beta1=1.4, k3='paper'))


# --------------------------------------------------------------------------- errors


def _set(path, value):
    def mutate(data):
        target = data
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value

    return mutate


def _delete(path):
    def mutate(data):
        target = data
        for key in path[:-1]:
            target = target[key]
        del target[path[-1]]

    return mutate


def _append_edge(edge):
    return lambda data: data['edges'].append(edge)


BROKEN_SINGLE = [
    ('unknown top key', _set(('colour',), 'red'), ["unknown key 'colour'"]),
    ('missing key', _delete(('communication_radius',)), ["missing key 'communication_radius'"]),
    ('dynamics', _set(('dynamics',), 'triple'), ['dynamics', "'triple'"]),
    ('delta zero', _set(('communication_radius',), 0.0), ['communication_radius', 'Δ must be > 0', '0.0']),
    ('delta negative', _set(('communication_radius',), -4), ['communication_radius', '-4']),
    ('horizon zero', _set(('horizon',), 0), ['horizon', 'must be > 0', '0']),
    ('horizon text', _set(('horizon',), 'long'), ['horizon', "expected a number, got 'long'"]),
    ('delta nan', _set(('communication_radius',), float('nan')), ['communication_radius', 'finite']),
    (
        'position inf',
        _set(('agents', 2, 'position'), [1.0, float('inf')]),
        ['agents.2.position[1]', 'finite'],
    ),
    ('position text', _set(('agents', 3, 'position'), [1.0, 'x']), ['agents.3.position[1]', "'x'"]),
    ('position bool', _set(('agents', 3, 'position'), [1.0, True]), ['agents.3.position[1]', 'True']),
    (
        'position size',
        _set(('agents', 2, 'position'), [1.0, 2.0, 3.0]),
        ['agents.2.position', '3 components', 'expected 2'],
    ),
    (
        'position scalar',
        _set(('agents', 2, 'position'), 5.0),
        ['agents.2.position', 'list of numbers', '5.0'],
    ),
    ('velocity for single', _set(('agents', 1, 'velocity'), [0.0, 0.0]), ['agents.1.velocity', "'single'"]),
    ('unknown agent key', _set(('agents', 1, 'colour'), 'red'), ['agents.1', "unknown key 'colour'"]),
    (
        'agent id text',
        _set(('agents', 'four'), {'position': [0.0, 0.0]}),
        ['agents.four', 'integers in [0, 2147483647]', "'four'"],
    ),
    (
        'agent id negative',
        _set(('agents', -1), {'position': [0.0, 0.0]}),
        ['agents.-1', 'integers in [0, 2147483647]'],
    ),
    ('one agent', _set(('agents',), {1: {'position': [0.0, 0.0]}}), ['at least 2 agents']),
    (
        'edge to nobody',
        _append_edge({'i': 1, 'j': 7, 'd': [0.0, 0.0]}),
        ['edges[3] (1, 7)', 'j=7 is not an agent'],
    ),
    ('self loop', _append_edge({'i': 2, 'j': 2, 'd': [0.0, 0.0]}), ['edges[3] (2, 2)', 'self-loop']),
    (
        'duplicate edge',
        _append_edge({'i': 1, 'j': 2, 'd': [0.0, -2.0]}),
        ['edges[3] (1, 2)', 'duplicates edges[0] (1, 2)'],
    ),
    (
        'reversed duplicate',
        _append_edge({'i': 2, 'j': 1, 'd': [0.0, 2.0]}),
        ['edges[3] (2, 1)', 'duplicates edges[0] (1, 2), they agree', 'd_ji = -d_ij'],
    ),
    ('edge d size', _set(('edges', 1, 'd'), [1.0]), ['edges[1] (1, 3).d', '1 components', 'expected 2']),
    ('edge d nan', _set(('edges', 2, 'd'), [float('nan'), 0.0]), ['edges[2] (2, 3).d[0]', 'finite']),
    ('edge missing d', _delete(('edges', 0, 'd')), ['edges[0]', "missing key 'd'"]),
    ('edge unknown key', _set(('edges', 0, 'weight'), 2.0), ['edges[0]', "unknown key 'weight'"]),
    ('edges not a list', _set(('edges',), {'i': 1}), ['edges', 'expected a list']),
    ('gains unknown', _set(('gains', 'alpha_d'), 1.0), ["unknown key 'alpha_d'", "'single'"]),
    ('gains missing', _delete(('gains', 'beta')), ['gains', "missing key 'beta'"]),
    ('gain text', _set(('gains', 'alpha'), 'ten'), ['gains.alpha', "'ten'"]),
    ('gain nan', _set(('gains', 'beta'), float('nan')), ['gains.beta', 'finite', 'nan']),
    ('horizon negative', _set(('horizon',), -1.0), ['horizon', 'must be > 0', '-1.0']),
    ('horizon infinite', _set(('horizon',), float('inf')), ['horizon', 'finite', 'inf']),
    (
        'd_ji disagreeing with d_ij',
        _append_edge({'i': 2, 'j': 1, 'd': [1.0, 2.0]}),
        [
            'edges[3] (2, 1)',
            'duplicates edges[0] (1, 2)',
            'they disagree: d = [0.0, -2.0] there, [-1.0, -2.0] here',
            'd_ji = -d_ij',
        ],
    ),
]

BROKEN_DOUBLE = [
    ('velocity missing', _delete(('agents', 2, 'velocity')), ['agents.2', 'velocity missing', "'double'"]),
    ('velocity size', _set(('agents', 3, 'velocity'), [1.0]), ['agents.3.velocity', 'expected 2']),
    (
        'single gains for double',
        _set(('gains',), {'alpha': 1.0, 'beta': 1.0}),
        ["unknown key 'alpha'", "'double'"],
    ),
    ('k1 without k2', _set(('gains', 'k1'), 1.0), ['gains.k1', 'without its partner']),
    ('k0 alone', _set(('gains', 'k0'), 1.0), ['gains.k0', 'without k1 and k2']),
    ('beta1 zero', _set(('gains', 'beta1'), 0.0), ['gains.beta1', '> 0', 'riccatti']),
    ('k3 word', _set(('gains', 'k3'), 'large'), ['gains.k3', "'large'"]),
]

BROKEN = [('single', *case) for case in BROKEN_SINGLE] + [('double', *case) for case in BROKEN_DOUBLE]


@pytest.mark.parametrize(
    'dynamics, label, mutate, fragments', BROKEN, ids=[f'{b[0]}: {b[1]}' for b in BROKEN]
)
def test_broken_scenarios_name_key_and_value(dynamics, label, mutate, fragments, paper_scenario_dict):
    data = paper_scenario_dict(dynamics)
    mutate(data)
    with pytest.raises(ScenarioError) as caught:
        scenario_from_dict(data)
    for fragment in fragments:
        assert fragment in str(caught.value), (label, str(caught.value))


def test_k3_paper_keyword(paper_scenario_dict):
    data = paper_scenario_dict('double')
    data['gains']['k3'] = 'paper'
    g = scenario_from_dict(data).gains
    assert g.k3 == 2.0 / (g.k2 + math.sqrt(g.k1**2 + g.k2**2))


def test_top_level_must_be_a_mapping():
    with pytest.raises(ScenarioError, match='expected a mapping'):
        scenario_from_dict([1, 2, 3])


def test_programmatic_construction_is_checked():
    s = load_scenario('paper_single')
    with pytest.raises(ScenarioError, match='self-loop'):
        Edge(i=1, j=1, d=np.zeros(2))
    with pytest.raises(ScenarioError, match='SingleGains'):
        s.replace(dynamics='double', velocities=np.zeros((3, 2)))
    with pytest.raises(ScenarioError, match='sorted'):
        s.replace(agent_ids=(2, 1, 3))
    with pytest.raises(ScenarioError, match='must equal'):
        DoubleGains(alpha_d=1, beta_d=1, beta1=1, k3=1, k1=1.0, k2=2.0, P=np.array([[3.0, 1.0], [1.0, 2.5]]))


# --------------------------------------------------------------------------- YAML files


def write(tmp_path, text: str):
    path = tmp_path / 'scenario.yaml'
    path.write_text(text, encoding='utf-8')
    return path


PAPER_YAML = """\
dynamics: single
communication_radius: 4.0
horizon: 10.0
agents:
  1: {position: [2.0, 4.0]}
  2: {position: [3.5, 7.0]}
  3: {position: [4.5, 5.5]}
edges:
  - {i: 1, j: 2, d: [0.0, -2.0]}
  - {i: 1, j: 3, d: [-2.0, 0.0]}
  - {i: 2, j: 3, d: [-2.0, 2.0]}
gains: {alpha: 1e1, beta: 1.0}
"""


def test_yaml_file_name_defaults_to_the_stem_and_1e1_is_a_number(tmp_path):
    s = load_scenario(write(tmp_path, PAPER_YAML))
    assert s.name == 'scenario'
    assert s.gains.alpha == 10.0


def test_malformed_yaml_gives_the_line(tmp_path):
    path = write(tmp_path, PAPER_YAML.replace('  2: {position: [3.5, 7.0]}', '  2: {position: [3.5, 7.0]'))
    with pytest.raises(ScenarioError, match=r'malformed YAML at line 7'):
        load_scenario(path)


def test_duplicate_yaml_key_is_rejected_with_its_line(tmp_path):
    path = write(tmp_path, PAPER_YAML.replace('  3: {position: [4.5, 5.5]}', '  2: {position: [4.5, 5.5]}'))
    with pytest.raises(ScenarioError, match=r'line 7.*duplicate key 2'):
        load_scenario(path)


def test_errors_from_files_name_the_file(tmp_path):
    path = write(tmp_path, PAPER_YAML.replace('horizon: 10.0', 'horizon: -3'))
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    assert str(path) in str(caught.value) and 'horizon' in str(caught.value) and '-3' in str(caught.value)


def test_missing_file_and_unknown_name():
    with pytest.raises(ScenarioError, match='no such scenario file and not a built-in'):
        load_scenario('paper_triple')


def test_inputs_are_not_modified(paper_scenario_dict):
    data = paper_scenario_dict('double')
    before = copy.deepcopy(data)
    scenario_from_dict(data)
    assert data == before


# --------------------------------------------------------------------------- limits of what is read


def test_short_repr_cuts_long_values_and_says_how_long():
    from formation_sim.model.scenario import short_repr

    assert short_repr(-4.5) == '-4.5' and short_repr(5e-324) == '5e-324' and short_repr('four') == "'four'"
    assert short_repr(10**400) == '100000000000... (an integer of 401 digits)'
    assert short_repr(-(10**20000)).endswith(
        '... (an integer of about 20000 digits)'
    )  # past int -> str's limit
    assert len(short_repr('x' * 10**6)) <= 80
    nested: list = []
    nested.append(nested)
    assert short_repr(nested) == '[[[[...]]]]'
    assert short_repr(list(range(1000))) == '[0, 1, 2, 3, 4, 5, 6, 7, ...]'


@pytest.mark.parametrize(
    ('make', 'fragment'),
    [
        (
            lambda s: s.replace(positions=[[10**400, 0.0], [1.0, 1.0], [2.0, 2.0]]),
            'positions: a value is too large for a double',
        ),
        (
            lambda s: s.replace(positions=[['a', 0.0], [1.0, 1.0], [2.0, 2.0]]),
            "positions: expected numbers, got [['a', 0.0]",
        ),
        (
            lambda s: s.replace(agent_ids=(1, 2, 2**31)),
            'agent_ids: agent ids are integers in [0, 2147483647]',
        ),
        (lambda s: Edge(i=1, j=2**31, d=np.zeros(2)), 'edge j: agent ids are integers in [0, 2147483647]'),
        (lambda s: s.replace(name='x' * 201), 'name: at most 200 printable characters'),
        (
            lambda s: SingleGains(alpha=10**400, beta=1.0),
            'gains.alpha: 100000000000... (an integer of 401 digits) is too large for a double',
        ),
    ],
)
def test_programmatic_construction_refuses_what_a_file_would(make, fragment):
    with pytest.raises(ScenarioError) as caught:
        make(load_scenario('paper_single'))
    assert fragment in str(caught.value)


def test_the_largest_agent_id_travels():
    s = load_scenario('paper_single').replace(
        agent_ids=(1, 2, 2**31 - 1),
        edges=(
            Edge(i=1, j=2, d=np.array([0.0, -2.0])),
            Edge(i=1, j=2**31 - 1, d=np.array([-2.0, 0.0])),
            Edge(i=2, j=2**31 - 1, d=np.array([-2.0, 2.0])),
        ),
    )
    assert scenario_from_dict(scenario_to_dict(s)) == s


def _aliased(repeats: int, size: int = 999) -> str:
    """A YAML document of 1 + (size + 1) + 1 + repeats * (size + 1) + 1 + 1 nodes once its aliases are
    expanded."""
    return f'a: &a [{", ".join(["0"] * size)}]\nb: [{", ".join(["*a"] * repeats)}]\n'


def test_the_node_limit_counts_alias_expansions_exactly(tmp_path):
    from formation_sim.model.scenario import MAX_YAML_NODES

    # Nodes: the top mapping, key a, its list (1 + size), key b, list b, and repeats times the list a.
    def nodes(repeats, size=999):
        return 1 + 1 + (1 + size) + 1 + 1 + repeats * (1 + size)

    below = (MAX_YAML_NODES - nodes(0)) // 1000
    assert nodes(below) <= MAX_YAML_NODES < nodes(below + 1)
    for repeats, refused in ((below, False), (below + 1, True)):
        path = write(tmp_path, _aliased(repeats))
        with pytest.raises(ScenarioError) as caught:
            load_scenario(path)
        assert ('more than 300000 nodes with its aliases expanded' in str(caught.value)) == refused, str(
            caught.value
        )[:300]
        if not refused:
            assert "unknown key 'a'" in str(caught.value)  # read completely, then refused by the schema


def test_files_above_the_size_limit_are_refused_before_reading(tmp_path, monkeypatch):
    import formation_sim.model.scenario as scenario_module

    path = write(tmp_path, PAPER_YAML)
    monkeypatch.setattr(scenario_module, 'MAX_FILE_BYTES', len(PAPER_YAML.encode()) - 1)
    with pytest.raises(ScenarioError, match=r'0\.0 MB; a scenario file holds at most 0\.0 MB'):
        load_scenario(path)
    monkeypatch.setattr(scenario_module, 'MAX_FILE_BYTES', len(PAPER_YAML.encode()))
    assert load_scenario(path).n == 3


def test_json_files_have_their_own_size_limit(tmp_path, monkeypatch):
    import formation_sim.model.scenario as scenario_module

    path = tmp_path / 'paper.json'
    dump_scenario(load_scenario('paper_single'), path)
    size = path.stat().st_size
    monkeypatch.setattr(scenario_module, 'MAX_FILE_BYTES', size - 1)  # the YAML limit does not apply
    assert load_scenario(path).name == 'paper_single'
    monkeypatch.setattr(scenario_module, 'MAX_JSON_BYTES', size - 1)
    with pytest.raises(
        ScenarioError, match=r'paper\.json: 0\.0 MB; a JSON scenario file holds at most 0\.0 MB: refused'
    ):
        load_scenario(path)


def test_a_large_team_in_json_reads_back_exactly(tmp_path):
    from formation_sim.model.generate import random_scenario

    team = random_scenario(n=2000, seed=3, dynamics='double', dimension=3)
    path = tmp_path / 'team.json'
    dump_scenario(team, path)
    assert load_scenario(path) == team


def test_a_folder_is_named_as_such():
    with pytest.raises(ScenarioError, match='is a folder, not a scenario file'):
        load_scenario('.')


# --------------------------------------------------------------------------- libyaml (C) and PyYAML agree

# Documents for which the loader's fast paths (libyaml's events straight to data; libyaml's composer
# with the Python constructor) must give exactly what PyYAML's pure-Python loader gives.
YAML_DOCUMENTS = [
    PAPER_YAML,
    '',
    '# only a comment\n',
    '---\n',
    'a: [1e-3, 1E+3, .5, -0.0, +1, 0x1F, 0o17, 017, 1_000, 1:30, 1.5:30, 0b101, 190:20:30]\n',
    'a: [.inf, -.Inf, .NaN, .nan, nan, inf]\n',
    'a: [yes, No, on, OFF, true, False, ~, null, Null, "", \'\', "1", \'2.0\', x y, "a\\nb"]\n',
    'a: {1: x, 1.5: y, false: z, null: w, "1": v}\n',
    'a: &x [1, 2]\nb: *x\nc: {<<: {d: 1}, e: 2}\n',  # anchors, aliases and a merge key
    'a: 2001-12-14\nb: 2001-12-14t21:59:43.10-05:00\n',  # timestamps
    'a: !!binary aGVsbG8=\nb: !!str 1\nc: !!float 1\nd: ! 12\n',  # explicit tags
    'a: !!set {x, y}\nb: !!omap [{x: 1}]\n',
    '- [[[1]]]\n- {a: {b: {c: [2]}}}\n',
    'plain text\n',
    '"quoted root"\n',
    '%YAML 1.1\n---\na: 1\n...\n',
    'a: |\n  two\n  lines\nb: >\n  folded\n  text\n',
]


@pytest.mark.parametrize('text', YAML_DOCUMENTS, ids=range(len(YAML_DOCUMENTS)))
def test_the_c_loader_reads_what_the_python_loader_reads(text):
    import yaml

    from formation_sim.model import scenario as module

    expected = yaml.load(text, Loader=module._Loader)  # noqa: S506 - a SafeLoader
    assert repr(module._load_yaml(text)) == repr(expected)
    assert repr(module._CLoader(text).get_single_data()) == repr(expected)


def test_every_dumped_scenario_takes_the_one_pass_reader_and_reads_back_bit_for_bit():
    from formation_sim.model import scenario as module
    from formation_sim.model.generate import random_scenario
    from formation_sim.model.scenario import dump_scenario_text

    for scenario in (
        load_scenario('paper_double'),
        random_scenario(n=50, seed=4, dynamics='double', dimension=3),
    ):
        text = dump_scenario_text(scenario)
        data = module._read_plain(text)  # raises _NotPlain if the dump needed the full loader
        assert scenario_from_dict(data, name=scenario.name) == scenario


@pytest.mark.parametrize('anchored', [False, True], ids=['one pass', 'anchors: the composer'])
def test_the_node_limit_holds_exactly_on_both_paths(tmp_path, anchored):
    from formation_sim.model.scenario import MAX_YAML_NODES

    # Nodes: the top mapping, key a, its list and its items (the anchored variant: one more key and scalar).
    extra = 2 if anchored else 0
    for items, refused in ((MAX_YAML_NODES - 3 - extra, False), (MAX_YAML_NODES - 2 - extra, True)):
        text = ('b: &b 0\n' if anchored else '') + 'a: [' + ', '.join(['0'] * items) + ']\n'
        with pytest.raises(ScenarioError) as caught:
            load_scenario(write(tmp_path, text))
        message = str(caught.value)
        assert (f'more than {MAX_YAML_NODES} nodes (at line' in message) == refused, message[:300]
        if not refused:
            assert 'unknown key' in message


@pytest.mark.parametrize('anchored', [False, True], ids=['one pass', 'anchors: the composer'])
def test_nesting_is_bounded_on_both_paths(tmp_path, anchored):
    from formation_sim.model.scenario import _YAML_DEPTH_LIMIT

    prefix = 'b: &b 0\n' if anchored else ''
    for depth, refused in ((_YAML_DEPTH_LIMIT - 1, False), (_YAML_DEPTH_LIMIT, True)):
        # The top mapping is one level, the list under `horizon` `depth` more.
        text = prefix + 'horizon: ' + '[' * depth + ']' * depth + '\n'
        with pytest.raises(ScenarioError) as caught:
            load_scenario(write(tmp_path, text))
        assert ('nested too deeply' in str(caught.value)) == refused, str(caught.value)[:300]


@pytest.mark.parametrize('suffix', ['.yaml', '.json'])
def test_headings_are_optional_per_agent_and_round_trip_exactly(tmp_path, suffix):
    from formation_sim.model.scenario import dump_scenario, scenario_to_dict

    lab = load_scenario('robots_lab')
    assert lab.headings is not None and lab.headings.tolist() == [-1.377, 0.402, -0.155, 1.484]
    dump_scenario(lab, tmp_path / f'lab{suffix}')
    assert load_scenario(tmp_path / f'lab{suffix}') == lab
    assert load_scenario('robots_square').headings is None  # none given: the robots' --initial-heading
    data = scenario_to_dict(lab)
    data['agents'][3]['heading'] = math.pi
    assert scenario_from_dict(data) != lab  # headings are part of the scenario
    del data['agents'][2]['heading']
    with pytest.raises(
        ScenarioError,
        match=r'agents\.2: heading missing, while agents 1, 3, 4 have one: give every agent a heading '
        r'or none',
    ):
        scenario_from_dict(data)
    data['agents'][2]['heading'] = float('nan')
    with pytest.raises(ScenarioError, match=r'agents\.2\.heading: must be finite, got nan'):
        scenario_from_dict(data)
