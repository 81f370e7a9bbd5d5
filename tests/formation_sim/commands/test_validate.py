"""`formation validate`: output, JSON, exit codes 0 / 1 / 2, and a catalogue of broken scenario files."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from importlib import resources

import pytest

from formation_sim.cli import main

GOOD = """\
name: good
dynamics: single
communication_radius: 4.0
horizon: 10.0
agents:
  1: {position: [0.0, 0.0]}
  2: {position: [0.0, 2.5]}
edges:
  - {i: 1, j: 2, d: [0.0, -2.0]}
gains: {alpha: 1.0, beta: 0.1}
"""


def write(tmp_path, text):
    path = tmp_path / 'case.yaml'
    path.write_text(text, encoding='utf-8')
    return str(path)


def test_valid_builtin_prints_the_report(capsys):
    assert main(['validate', 'paper_single']) == 0
    out = capsys.readouterr().out
    assert 'VALID' in out and 'β0 = ρ2/Δ0 = 1.5' in out and '[remark]' in out


def test_valid_file_without_warnings(tmp_path, capsys):
    # One edge: ρ2 = 2, Δ0 = 2, β0 = 1; 0.1 < 4/(2·1·4) = 0.5; slack 0.5 of 2.
    assert main(['validate', write(tmp_path, GOOD)]) == 0
    out = capsys.readouterr().out
    assert '0 error(s), 0 warning(s)' in out


def test_json_output(capsys):
    assert main(['validate', 'paper_double', '--json']) == 0
    data = json.loads(capsys.readouterr().out)
    assert data['ok'] is True and data['scenario'] == 'paper_double'
    assert 'beta_d_corrected' in {w['rule'] for w in data['warnings']}


def test_invalid_scenario_exits_1(tmp_path, capsys):
    path = write(tmp_path, GOOD.replace('beta: 0.1', 'beta: 1.1'))  # β > β0 = 1
    assert main(['validate', path]) == 1
    out = capsys.readouterr().out
    assert 'INVALID' in out and '[beta] gains' in out and 'β0 = 1' in out
    assert main(['validate', path, '--json']) == 1
    assert json.loads(capsys.readouterr().out)['errors'][0]['rule'] == 'beta'


@pytest.mark.parametrize(
    'text, fragment',
    [
        (GOOD.replace('[0.0, 2.5]}', '[0.0, 2.5]'), 'malformed YAML at line 8'),
        (GOOD.replace('horizon: 10.0', 'horizon: 0'), 'horizon'),
        (GOOD.replace('j: 2', 'j: 9'), 'j=9 is not an agent'),
    ],
)
def test_unreadable_scenario_exits_2_without_traceback(tmp_path, capsys, text, fragment):
    assert main(['validate', write(tmp_path, text)]) == 2
    captured = capsys.readouterr()
    assert fragment in captured.err and 'Traceback' not in captured.err
    if 'malformed' in fragment:
        assert 'started at line 7' in captured.err  # where the unclosed mapping begins
    assert captured.out == ''


def test_missing_file_exits_2(capsys):
    assert main(['validate', 'no_such_scenario.yaml']) == 2
    assert 'no such scenario file' in capsys.readouterr().err


def test_no_subcommand_exits_2(capsys):
    assert main([]) == 2
    assert 'validate' in capsys.readouterr().err


def test_module_entry_point(tmp_path):
    path = write(tmp_path, GOOD.replace('horizon: 10.0', 'horizon: -1'))
    result = subprocess.run(
        [sys.executable, '-m', 'formation_sim.cli', 'validate', path],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 2
    assert 'horizon' in result.stderr and 'Traceback' not in result.stderr


def test_a_folder_is_not_reported_as_missing(tmp_path, capsys):
    assert main(['validate', str(tmp_path)]) == 2
    assert f"'{tmp_path}': is a folder, not a scenario file" in capsys.readouterr().err


# -- a catalogue of broken scenario files -----------------------------------------------------------
#
# Each is answered at once by `formation validate` (exit 2: unreadable, 1: a hypothesis broken),
# without a traceback, naming the key, agent or edge and the value, in a message of bounded size.

# The built-in paper_single, its comment lines dropped (so line numbers below count from `name`).
PAPER = ''.join(
    line
    for line in (resources.files('formation_sim.model.scenarios') / 'paper_single.yaml')
    .read_text()
    .splitlines(True)
    if not line.startswith('#')
).replace('name: paper_single', 'name: case')


def edit(old, new, count=1):
    assert PAPER.count(old) >= count, old
    return PAPER.replace(old, new, count)


def rename_agent_3(new):
    return PAPER.replace('  3: {', f'  {new}: {{').replace('j: 3', f'j: {new}')


BOMB = ''.join(
    f'{name}: &{name} [{", ".join([f"*{prev}"] * 9) if prev else ", ".join(["lol"] * 9)}]\n'
    for prev, name in zip([None, *'abcdefgh'], 'abcdefghi')
)

CATALOGUE = [
    # (id, file content (str, or bytes as written), exit code, fragments of the message)
    # -- numbers at the edges of a double
    (
        'integer beyond a double',
        edit('beta: 1.0', 'beta: 1' + '0' * 400),
        2,
        ['gains.beta: 100000000000... (an integer of 401 digits) is too large for a double'],
    ),
    (
        'huge integer in a position',
        edit('[2.0, 4.0]', '[' + '9' * 400 + ', 4.0]'),
        2,
        ['agents.1.position[0]', 'too large for a double'],
    ),
    (
        'huge integer in d',
        edit('d: [0.0, -2.0]', 'd: [0.0, -1' + '0' * 400 + ']'),
        2,
        ['edges[0] (1, 2).d[1]', 'an integer of 401 digits'],
    ),
    (
        'huge integer as Δ',
        edit('communication_radius: 4.0', 'communication_radius: 1' + '0' * 400),
        2,
        ['communication_radius', 'too large for a double'],
    ),
    (
        'integer past int() digits',
        edit('horizon: 10.0', 'horizon: 1' + '0' * 6000),
        2,
        ['line 4, column 10', 'an integer of 6001 characters is too large for a double'],
    ),
    ('1e999', edit('horizon: 10.0', 'horizon: 1e999'), 2, ['horizon: must be finite, got inf']),
    ('.nan', edit('alpha: 10.0', 'alpha: .nan'), 2, ['gains.alpha: must be finite, got nan']),
    ('-.inf', edit('[2.0, 4.0]', '[-.inf, 4.0]'), 2, ['agents.1.position[0]: must be finite, got -inf']),
    (
        'nan spelled as text',
        edit('alpha: 10.0', 'alpha: nan'),
        2,
        ["gains.alpha: expected a number, got 'nan'"],
    ),
    ('yes for a number', edit('alpha: 10.0', 'alpha: yes'), 2, ['gains.alpha: expected a number, got True']),
    (
        'subnormal α',
        edit('alpha: 10.0', 'alpha: 5e-324'),
        1,
        ['[parameters] gains: gains.alpha = 5e-324 is a subnormal double', 'ROS parameter'],
    ),
    (
        'subnormal β',
        edit('beta: 1.0', 'beta: 1e-310'),
        1,
        ['[parameters] gains: gains.beta = 1e-310 is a subnormal double'],
    ),
    (
        'subnormal horizon',
        edit('horizon: 10.0', 'horizon: 5e-324'),
        1,
        ['[parameters] scenario: horizon = 5e-324 is a subnormal double'],
    ),
    (
        'subnormal d',
        edit('d: [0.0, -2.0]', 'd: [1e-320, -2.0]'),
        1,
        ['[parameters] edge (1, 2): d[0] = 1e-320 is a subnormal double'],
    ),
    ('position 1e308', edit('[2.0, 4.0]', '[1e308, 4.0]'), 1, ['[initial] edge (1, 2)', '(initial)']),
    (
        'Δ 1e308',
        edit('communication_radius: 4.0', 'communication_radius: 1e308'),
        1,
        ['[scale] scenario: Δ = 1e+308 is above 1.80925e+75 (2^250)'],
    ),
    (
        'Δ 1e-300',
        edit('communication_radius: 4.0', 'communication_radius: 4e-300'),
        1,
        ['[edge_length] edge (1, 2)'],
    ),
    (
        '-0.0 breaking (initial)',
        edit('[2.0, 4.0]', '[-0.0, 4.0]'),
        1,
        ['[initial] edge (1, 2): ||x_i(0)-x_j(0)-d_ij|| = 3.64005 is not below Δ-||d_ij|| = 2'],
    ),
    (
        'β a hair above β0',
        edit('beta: 1.0', 'beta: 1.500000000000001'),
        1,
        ['0 < β < β0 = 1.5 required, got β = 1.500000000000001'],
    ),
    # -- YAML features
    (
        'alias bomb',
        BOMB + PAPER.replace('horizon: 10.0', 'horizon: *i').replace('name: case\n', ''),
        2,
        ['more than 300000 nodes with its aliases expanded', 'an alias bomb?'],
    ),
    (
        'recursive alias',
        edit('[2.0, 4.0]', '&r [*r]'),
        2,
        ['agents.1.position[0]: expected a number, got [[[[...]]]]'],
    ),
    (
        'python object tag',
        edit('horizon: 10.0', "horizon: !!python/object/apply:os.system ['echo hi']"),
        2,
        [
            'line 4, column 10',
            "could not determine a constructor for the tag 'tag:yaml.org,2002:python/object/apply:os.system'",
        ],
    ),
    (
        'binary tag',
        edit('horizon: 10.0', 'horizon: !!binary aGVsbG8='),
        2,
        ["horizon: expected a number, got b'hello'"],
    ),
    (
        'a date',
        edit('horizon: 10.0', 'horizon: 2001-12-14'),
        2,
        ['horizon: expected a number, got datetime.date(2001, 12, 14)'],
    ),
    (
        'duplicate key',
        edit('  3: {position', '  2: {position'),
        2,
        ['line 8, column 3', 'found duplicate key 2'],
    ),
    (
        'duplicate id spelled as text',
        edit('  3: {position', '  "1": {position'),
        2,
        ['agents.1: agent 1 is listed twice'],
    ),
    (
        'merge key with an unknown key',
        edit('gains: {alpha: 10.0, beta: 1.0}', 'base: &g {alpha: 10.0}\ngains: {<<: *g, beta: 1.0}'),
        2,
        ["scenario: unknown key 'base'"],
    ),
    (
        'unhashable key',
        edit('  1: {position: [2.0, 4.0]}', '  ? [1, 2]\n  : {position: [2.0, 4.0]}'),
        2,
        ['line 6, column 5', 'found unhashable key'],
    ),
    ('two documents', PAPER + '---\n' + PAPER, 2, ['line 14, column 1', 'expected a single document']),
    ('empty file', '', 2, ['scenario: expected a mapping, got None']),
    ('a list', '- 1\n- 2\n', 2, ['scenario: expected a mapping, got [1, 2]']),
    (
        'tab indentation',
        edit('  1: {', '\t1: {'),
        2,
        ['line 6, column 1', "found character '\\t' that cannot start any token"],
    ),
    ('NUL byte', edit('horizon: 10.0', 'horizon: 1\x000'), 2, ['unacceptable character #x0000']),
    (
        'nested too deeply',
        edit('horizon: 10.0', 'horizon: ' + '[' * 5000 + ']' * 5000),
        2,
        ['nested too deeply'],
    ),
    (
        'non-UTF-8 bytes',
        PAPER.encode().replace(b'name: case', b'name: ca\xffse'),
        2,
        ['not UTF-8 text: byte 0xff at line 1 (offset 8)'],
    ),
    ('10 MB file', '# ' + 'x' * 10_000_000 + '\n', 2, ['10.0 MB; a scenario file holds at most 4.2 MB']),
    (
        '100 kB string',
        edit('horizon: 10.0', 'horizon: ' + 'x' * 100_000),
        2,
        ["horizon: expected a number, got 'xxxxxxxxxxxx", "xxx'"],
    ),
    (
        '10 kB key',
        edit('horizon: 10.0', 'horizon: 10.0\n' + 'k' * 10_000 + ': 1'),
        2,
        ['line 5', "could not find expected ':'"],
    ),
    # -- ids
    (
        'id 2^31',
        rename_agent_3(2**31),
        2,
        ['agents.2147483648: agent ids are integers in [0, 2147483647]', 'got 2147483648'],
    ),
    (
        'id 1e30',
        rename_agent_3('1e30'),
        2,
        ['agents.1e+30: agent ids are integers in [0, 2147483647]', 'got 1e+30'],
    ),
    (
        'id 10^30',
        rename_agent_3(10**30),
        2,
        ['agent ids are integers in [0, 2147483647]', 'an integer of 31 digits'],
    ),
    (
        'id negative',
        rename_agent_3(-3),
        2,
        ['agents.-3: agent ids are integers in [0, 2147483647]', 'got -3'],
    ),
    ('id float', rename_agent_3(3.5), 2, ['agents.3.5: agent ids are integers', 'got 3.5']),
    ('id text', rename_agent_3('three'), 2, ['agents.three: agent ids are integers', "got 'three'"]),
    (
        'id bool',
        PAPER.replace('  1: {', '  true: {').replace('i: 1,', 'i: true,'),
        2,
        ['agents.True: agent ids are integers', 'got True'],
    ),
    (
        'edge id as text',
        edit('i: 2, j: 3', 'i: "2", j: 3'),
        2,
        ['edges[2].i: agent ids are integers', "got '2'"],
    ),
    (
        'edge to nobody',
        edit('j: 3, d: [-2.0, 2.0]', 'j: 9, d: [-2.0, 2.0]'),
        2,
        ['edges[2] (2, 9): j=9 is not an agent (agents: 1, 2, 3)'],
    ),
    # -- names
    ('empty name', edit('name: case', "name: ''"), 2, ["name: expected a non-empty string, got ''"]),
    ('name a number', edit('name: case', 'name: 42'), 2, ['name: expected a non-empty string, got 42']),
    (
        'name of 300 characters',
        edit('name: case', 'name: ' + 'n' * 300),
        2,
        ['name: at most 200 printable characters', '(300 characters)'],
    ),
    (
        'name with a line break',
        edit('name: case', 'name: "a\\nb"'),
        2,
        ["name: at most 200 printable characters (no line breaks or control characters), got 'a\\nb'"],
    ),
    # -- sizes
    (
        'no agents',
        PAPER.split('agents:')[0] + 'agents: {}\nedges: []\ngains: {alpha: 1.0, beta: 0.1}\n',
        2,
        ['agents: the formation problem needs at least 2 agents, got 0'],
    ),
    (
        'one agent',
        PAPER.split('agents:')[0]
        + 'agents: {1: {position: [0.0]}}\nedges: []\ngains: {alpha: 1.0, beta: 0.1}\n',
        2,
        ['at least 2 agents, got 1'],
    ),
    (
        'agents null',
        PAPER.split('agents:')[0] + 'agents:\nedges: []\ngains: {alpha: 1.0, beta: 0.1}\n',
        2,
        ['agents: expected a mapping, got None'],
    ),
    (
        'no edges',
        PAPER.split('edges:')[0] + 'edges: []\ngains: {alpha: 10.0, beta: 1.0}\n',
        1,
        ['[connected] graph: the graph has 3 connected components'],
    ),
    (
        'p = 0',
        edit('[2.0, 4.0]', '[]'),
        2,
        ['agents.1.position: expected a non-empty list of numbers, got []'],
    ),
    (
        'mismatched dimensions',
        edit('[2.0, 4.0]', '[2.0, 4.0, 1.0]'),
        2,
        ['agents.2.position: has 2 components, expected 3'],
    ),
    (
        'd of another dimension',
        edit('d: [0.0, -2.0]', 'd: [0.0]'),
        2,
        ['edges[0] (1, 2).d: has 1 components, expected 2'],
    ),
    (
        'gains as a list',
        edit('gains: {alpha: 10.0, beta: 1.0}', 'gains: [10.0, 1.0]'),
        2,
        ['gains: expected a mapping, got [10.0, 1.0]'],
    ),
    (
        'an edge as a list',
        edit('{i: 1, j: 2, d: [0.0, -2.0]}', '[1, 2, [0.0, -2.0]]'),
        2,
        ['edges[0]: expected a mapping, got [1, 2, [0.0, -2.0]]'],
    ),
]

# The same problem as a JSON file (the format for large teams), one agent and one edge a line.
PAPER_JSON = """\
{
"name": "case",
"dynamics": "single",
"communication_radius": 4.0,
"horizon": 10.0,
"agents": {
  "1": {"position": [2.0, 4.0]},
  "2": {"position": [3.5, 7.0]},
  "3": {"position": [4.5, 5.5]}
},
"edges": [
  {"i": 1, "j": 2, "d": [0.0, -2.0]},
  {"i": 1, "j": 3, "d": [-2.0, 0.0]},
  {"i": 2, "j": 3, "d": [-2.0, 2.0]}
],
"gains": {"alpha": 10.0, "beta": 1.0}
}
"""


def edit_json(old, new):
    assert old in PAPER_JSON, old
    return PAPER_JSON.replace(old, new, 1)


JSON_CATALOGUE = [
    # -- syntax, with line and column
    (
        'missing comma',
        edit_json('"horizon": 10.0,', '"horizon": 10.0'),
        2,
        ["malformed JSON at line 6, column 1: Expecting ',' delimiter"],
    ),
    (
        'trailing comma',
        edit_json('"beta": 1.0}', '"beta": 1.0,}'),
        2,
        ['malformed JSON at line 16, column 38: Expecting property name enclosed in double quotes'],
    ),
    (
        'single quotes',
        edit_json('"dynamics": "single"', "'dynamics': 'single'"),
        2,
        ['malformed JSON at line 3, column 1'],
    ),
    ('two documents', PAPER_JSON + PAPER_JSON, 2, ['malformed JSON at line 18, column 1: Extra data']),
    ('empty file', '', 2, ['malformed JSON at line 1, column 1: Expecting value']),
    (
        'NUL byte in a string',
        edit_json('"name": "case"', '"name": "ca\x00se"'),
        2,
        ['malformed JSON at line 2, column 12: Invalid control character'],
    ),
    (
        'nested too deeply',
        edit_json('"horizon": 10.0', '"horizon": ' + '[' * 100_000 + ']' * 100_000),
        2,
        ['malformed JSON: nested too deeply'],
    ),
    (
        'non-UTF-8 bytes',
        PAPER_JSON.encode().replace(b'"case"', b'"ca\xffse"'),
        2,
        ['not UTF-8 text: byte 0xff at line 2 (offset 13)', 'UTF-8 JSON'],
    ),
    (
        '40 MB file',
        lambda: ' ' * 40_000_000 + PAPER_JSON,
        2,
        ['40.0 MB; a JSON scenario file holds at most 33.6 MB: refused'],
    ),
    # -- what json.loads would accept silently or differently
    (
        'duplicate key',
        edit_json('"horizon": 10.0,', '"horizon": 10.0,\n"horizon": 20.0,'),
        2,
        ["malformed JSON: duplicate key 'horizon'", "'communication_radius', 'horizon', 'horizon'"],
    ),
    (
        'duplicate agent',
        edit_json('"3": {"position": [4.5, 5.5]}', '"2": {"position": [4.5, 5.5]}'),
        2,
        ["duplicate key '2' in the object with keys ['1', '2', '2']"],
    ),
    ('NaN', edit_json('"alpha": 10.0', '"alpha": NaN'), 2, ['gains.alpha: must be finite, got nan']),
    (
        '-Infinity',
        edit_json('[2.0, 4.0]', '[-Infinity, 4.0]'),
        2,
        ['agents.1.position[0]: must be finite, got -inf'],
    ),
    ('1e999', edit_json('"horizon": 10.0', '"horizon": 1e999'), 2, ['horizon: must be finite, got inf']),
    (
        'integer beyond a double',
        edit_json('"beta": 1.0', '"beta": 1' + '0' * 400),
        2,
        ['gains.beta: 100000000000... (an integer of 401 digits) is too large for a double'],
    ),
    (
        'integer past int() digits',
        edit_json('"horizon": 10.0', '"horizon": 1' + '0' * 6000),
        2,
        ['an integer of 6001 digits is too large for a double'],
    ),
    (
        'nan spelled as text',
        edit_json('"alpha": 10.0', '"alpha": "nan"'),
        2,
        ["gains.alpha: expected a number, got 'nan'"],
    ),
    (
        'true for a number',
        edit_json('"alpha": 10.0', '"alpha": true'),
        2,
        ['gains.alpha: expected a number, got True'],
    ),
    (
        'subnormal α',
        edit_json('"alpha": 10.0', '"alpha": 5e-324'),
        1,
        ['[parameters] gains: gains.alpha = 5e-324 is a subnormal double'],
    ),
    (
        'β a hair above β0',
        edit_json('"beta": 1.0', '"beta": 1.500000000000001'),
        1,
        ['0 < β < β0 = 1.5 required, got β = 1.500000000000001'],
    ),
    # -- the schema, as for YAML
    ('a list', '[1, 2]', 2, ['scenario: expected a mapping, got [1, 2]']),
    (
        'unknown key',
        edit_json('"horizon": 10.0,', '"horizon": 10.0,\n"extra": 1,'),
        2,
        ["scenario: unknown key 'extra'"],
    ),
    (
        'agents null',
        PAPER_JSON.split('"agents"', maxsplit=1)[0]
        + '"agents": null,\n"edges": [],\n"gains": {"alpha": 1.0, "beta": 0.1}\n}',
        2,
        ['agents: expected a mapping, got None'],
    ),
    (
        'id 2^31',
        edit_json('"3": {', '"2147483648": {').replace('"j": 3', '"j": 2147483648'),
        2,
        ['agents.2147483648: agent ids are integers in [0, 2147483647]'],
    ),
    (
        'id text',
        edit_json('"3": {', '"three": {'),
        2,
        ['agents.three: agent ids are integers', "got 'three'"],
    ),
    (
        'edge id as text',
        edit_json('"i": 2, "j": 3', '"i": "2", "j": 3'),
        2,
        ['edges[2].i: agent ids are integers', "got '2'"],
    ),
    (
        'edge to nobody',
        edit_json('"i": 2, "j": 3', '"i": 2, "j": 9'),
        2,
        ['edges[2] (2, 9): j=9 is not an agent (agents: 1, 2, 3)'],
    ),
    (
        'name of 300 characters',
        edit_json('"name": "case"', '"name": "' + 'n' * 300 + '"'),
        2,
        ['name: at most 200 printable characters', '(300 characters)'],
    ),
    (
        'mismatched dimensions',
        edit_json('[2.0, 4.0]', '[2.0, 4.0, 1.0]'),
        2,
        ['agents.2.position: has 2 components, expected 3'],
    ),
    (
        'an edge as a list',
        edit_json('{"i": 1, "j": 2, "d": [0.0, -2.0]}', '[1, 2, [0.0, -2.0]]'),
        2,
        ['edges[0]: expected a mapping, got [1, 2, [0.0, -2.0]]'],
    ),
    (
        'no edges',
        PAPER_JSON.split('"edges"', maxsplit=1)[0] + '"edges": [],\n"gains": {"alpha": 10.0, "beta": 1.0}\n}',
        1,
        ['[connected] graph: the graph has 3 connected components'],
    ),
]

MESSAGE_LIMIT = 2000  # characters: an error quotes values cut short, never their whole expansion


@pytest.mark.timeout(60)
@pytest.mark.parametrize(
    ('label', 'content', 'code', 'fragments'), CATALOGUE, ids=[case[0] for case in CATALOGUE]
)
def test_every_broken_file_gets_a_clear_answer(tmp_path, capsys, label, content, code, fragments):
    _check_clear_answer(tmp_path / 'case.yaml', capsys, label, content, code, fragments)


@pytest.mark.timeout(60)
@pytest.mark.parametrize(
    ('label', 'content', 'code', 'fragments'), JSON_CATALOGUE, ids=[case[0] for case in JSON_CATALOGUE]
)
def test_every_broken_json_file_gets_a_clear_answer(tmp_path, capsys, label, content, code, fragments):
    _check_clear_answer(tmp_path / 'case.json', capsys, label, content, code, fragments)


def test_the_json_paper_file_is_the_builtin_scenario(tmp_path, capsys):
    from formation_sim.model.scenario import load_scenario

    path = tmp_path / 'case.json'
    path.write_text(PAPER_JSON)
    assert load_scenario(path) == load_scenario('paper_single').replace(name='case')
    path.write_text('\ufeff' + PAPER_JSON, encoding='utf-8')  # a byte order mark is dropped, as for YAML
    assert main(['validate', str(path), '--json']) == 0
    assert json.loads(capsys.readouterr().out)['scenario'] == 'case'


def test_a_deeply_nested_json_file_is_refused_in_its_own_process(tmp_path):
    """A million nested brackets: json's C scanner counts its recursion (RecursionError), no crash."""
    path = tmp_path / 'deep.json'
    path.write_text('{"horizon": ' + '[' * 1_000_000 + ']' * 1_000_000 + '}')
    done = subprocess.run(
        [
            sys.executable,
            '-c',
            'import sys; from formation_sim.cli import main; sys.exit(main(sys.argv[1:]))',
            'validate',
            str(path),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2, done.stderr[-2000:]
    assert 'malformed JSON: nested too deeply' in done.stderr and len(done.stderr) < MESSAGE_LIMIT


def _check_clear_answer(path, capsys, label, content, code, fragments):
    content = content() if callable(content) else content
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding='utf-8', newline='')
    tmp_path = path.parent
    assert main(['validate', str(path)]) == code, label
    captured = capsys.readouterr()
    text = captured.err if code == 2 else captured.out
    for fragment in fragments:
        assert fragment in text, (label, text[:MESSAGE_LIMIT])
    assert 'Traceback' not in captured.err
    if code == 2:
        assert str(path) in captured.err and len(captured.err) < MESSAGE_LIMIT
        assert captured.out == ''
    else:  # broken hypotheses: the commands that run scenarios refuse them before anything starts
        assert main(['simulate', str(path), '--out', str(tmp_path / 'run')]) == 2
        assert not (tmp_path / 'run').exists()


@pytest.mark.parametrize('prefix', ['\ufeff', ''], ids=['BOM', 'no BOM'])
def test_a_byte_order_mark_is_read_as_utf8(tmp_path, capsys, prefix):
    path = tmp_path / 'case.yaml'
    path.write_text(prefix + PAPER, encoding='utf-8')
    assert main(['validate', str(path), '--json']) == 0
    assert json.loads(capsys.readouterr().out)['scenario'] == 'case'


def test_merge_keys_and_aliases_in_allowed_places_are_read(tmp_path, capsys):
    path = tmp_path / 'case.yaml'
    path.write_text(
        edit('gains: {alpha: 10.0, beta: 1.0}', 'gains: {<<: {alpha: 10.0, beta: 0.5}, beta: 1.0}').replace(
            'd: [0.0, -2.0]', 'd: &down [0.0, -2.0]'
        )
    )
    assert main(['validate', str(path), '--json']) == 0
    report = json.loads(capsys.readouterr().out)
    assert report['ok'] and 'β0 = ρ2/Δ0 = 1.5' in json.dumps(report, ensure_ascii=False)


def test_the_largest_agent_id_is_accepted(tmp_path):
    path = tmp_path / 'case.yaml'
    path.write_text(rename_agent_3(2**31 - 1))
    assert main(['validate', str(path)]) == 0


def test_an_alias_bomb_costs_neither_time_nor_memory(tmp_path):
    """In its own process with 1 GiB of address space: before the fix this took 1.5 GB and 358 MB of
    stderr."""
    path = tmp_path / 'bomb.yaml'
    path.write_text(
        BOMB
        + 'j: &j ['
        + ', '.join(['*i'] * 9)
        + ']\n'
        + PAPER.replace('horizon: 10.0', 'horizon: *j').replace('name: case\n', '')
    )
    assert path.stat().st_size < 1000
    limit = 'import resource; resource.setrlimit(resource.RLIMIT_AS, (2**30, 2**30)); '
    done = subprocess.run(
        [
            sys.executable,
            '-c',
            limit + 'import sys; from formation_sim.cli import main; sys.exit(main(sys.argv[1:]))',
            'validate',
            str(path),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2, done.stderr[-2000:]
    assert 'with its aliases expanded' in done.stderr and len(done.stderr) < MESSAGE_LIMIT


# -- --max-speed: the largest command a robot is asked for -------------------------------------


def test_robots_square_stays_within_a_turtlebot3s_limits_by_the_theorys_bound(capsys):
    assert main(['validate', 'robots_square', '--max-speed', '0.22', '--max-angular-speed', '2.84']) == 0
    out = capsys.readouterr().out
    assert 'largest speed: 0.1945 m/s <= 0.22 m/s (a bound from the theory)' in out
    assert 'largest turn rate (unicycle, l = 0.1 m: |ω| <= ||u|| / l): 1.945 rad/s <= 2.84 rad/s' in out
    assert '(dotyi) as printed bounds it by 0.2095 m/s' in out


def test_a_scenario_whose_bound_is_too_loose_is_decided_by_an_exact_run_and_says_so(capsys):
    # paper_single: the proofs allow 58 000 m/s, which settles nothing against 0.22; its exact
    # run asks for 536 m/s (issue 9).
    assert main(['validate', 'paper_single', '--max-speed', '0.22']) == 1
    out = capsys.readouterr().out
    assert 'the theory bounds the speed by 5.842e+04 m/s' in out
    assert (
        'largest speed: 535.7 m/s EXCEEDS 0.22 m/s (the largest in an exact in-process run, not a guarantee)'
        in out
    )


def test_command_limits_in_json_and_bad_limits_refused(capsys):
    assert main(['validate', 'paper_double', '--max-speed', '5', '--max-acceleration', '10', '--json']) == 1
    data = json.loads(capsys.readouterr().out)
    largest = data['commands']['largest']
    assert largest['source'] == 'exact run' and math.isclose(
        largest['max_acceleration'], 1208.19, rel_tol=1e-5
    )
    assert data['commands']['within'] is False
    assert main(['validate', 'robots_square', '--max-speed', '-1']) == 2
    assert 'argument --max-speed: must be a finite number > 0, got -1.0' in capsys.readouterr().err


def test_validate_reports_both_speed_scales_and_their_settling_times(capsys):
    from formation_sim.model.scenario import load_scenario
    from formation_sim.sim.largest_command import measured_command

    # robots_lab is set down 21-30 cm off its corners: at κ = 1 it asks for more than a TurtleBot can do
    assert (
        main(['validate', 'robots_lab', '--max-speed', '0.22', '--max-angular-speed', '2.84', '--json']) == 1
    )
    data = json.loads(capsys.readouterr().out)['commands']['speed_scale']
    asked = measured_command(load_scenario('robots_lab')).max_speed
    assert data['source'] == 'observed' and math.isclose(data['value'] * asked * 1.25, 0.22, rel_tol=1e-12)
    assert data['guaranteed']['value'] < data['observed']['value']
    assert data['settling']['definition'].startswith('first time after which the formation error')
    assert math.isclose(
        data['observed']['settle_time'], data['settling']['time_at_1'] / data['value'], rel_tol=1e-12
    )
    assert main(['validate', 'robots_lab', '--max-speed', '0.22']) == 1
    out = capsys.readouterr().out
    assert f'--speed-scale auto runs κ = {data["value"]:.4g} (observed)' in out
    assert 'guaranteed: κ = ' in out and 'bound by the speed 0.22 m/s' in out


def test_an_acceleration_limit_on_eta1_is_refused_with_the_reason(capsys):
    assert main(['validate', 'robots_lab', '--max-speed', '0.22', '--max-acceleration', '1']) == 2
    assert 'ETA-1 commands velocities (uxsingle) that jump at every event' in capsys.readouterr().err


def test_validate_suggests_the_threshold_floor_for_a_pose_noise(capsys):
    assert main(['validate', 'robots_lab', '--pose-noise', '0.005', '--json']) == 0
    floor = json.loads(capsys.readouterr().out)['threshold_floor']
    assert math.isclose(
        floor['suggested'], 3 * math.sqrt(10) * 0.005, rel_tol=1e-12
    )  # ω_ij = 2/(3 - 1) = 1, two neighbours
    assert main(['validate', 'robots_lab', '--pose-noise', '0.005']) == 0
    out = capsys.readouterr().out
    assert f'suggested c0 = {floor["suggested"]:.3g}' in out and 'sqrt(3 Σ_j ω_ij² + (Σ_j ω_ij)²)' in out
    assert main(['validate', 'robots_lab', '--pose-noise', '0']) == 2
    assert 'argument --pose-noise: must be a finite number > 0, got 0.0' in capsys.readouterr().err


def test_validate_reports_the_time_to_five_percent_with_the_warp_and_the_constant_kappa(capsys):
    import numpy as np

    from formation_agent.core.time_warp import TimeWarp
    from formation_sim.model.scenario import load_scenario
    from formation_sim.sim.engine import simulate

    limits = ['--max-speed', '0.22', '--max-angular-speed', '2.84']
    assert main(['validate', 'robots_lab', *limits, '--json']) == 1
    data = json.loads(capsys.readouterr().out)['commands']
    warp_data = data['time_warp']
    warp = TimeWarp(
        paper_starts=tuple(warp_data['observed']['paper_starts']), rates=tuple(warp_data['observed']['rates'])
    )
    settle = warp_data['observed']['settle_time']
    constant = warp_data['constant_settle_time']
    assert math.isclose(constant, data['speed_scale']['observed']['settle_time'], rel_tol=1e-12)
    assert settle < constant / 2.5  # robots_lab: 2.1 s against 6.4 s
    # the warped run itself crosses 5 % of its initial formation error for good at that real time
    scenario = load_scenario('robots_lab')
    record = simulate(scenario, horizon=20.0, sample_dt=None, time_warp=warp)
    heads, tails, d = scenario.edge_indices()
    x = np.asarray(record.sample_positions)
    error = np.linalg.norm(x[:, heads] - x[:, tails] - d, axis=2).max(axis=1)
    above = np.flatnonzero(error > 0.05 * error[0])
    times = np.asarray(record.sample_times)
    assert times[above[-1]] <= settle <= times[above[-1] + 1]
    assert warp_data['guaranteed']['settle_time'] > settle
    assert main(['validate', 'robots_lab', *limits]) == 1
    out = capsys.readouterr().out
    assert (
        f'observed: {warp.pieces} pieces, κ from {warp.rates[0]:.4g} to 1; 5 % of the formation error after'
        in out
    )
    assert f'the constant observed κ = {data["speed_scale"]["value"]:.4g}: 5 % after {constant:.4g} s' in out
    # ETA-2: no warp, and why
    main(['validate', 'paper_double', '--max-speed', '0.22'])
    assert 'time warp: none: time_warp: ETA-1 only' in capsys.readouterr().out


def test_validate_robot_takes_the_origins_and_the_footprints_default(tmp_path, capsys):
    """Issue 27 leftover 2: `--robot KIND` validates what `formation run --backend KIND` runs: D between
    origins (control points D + 2l), by default the footprints 2r + 5 cm apart; a start inside the
    margin is said and accepted, overlapping robots refused."""
    from formation_sim.model.scenario import dump_scenario
    from formation_sim.sim import safety_cases

    path = tmp_path / 'random_100.yaml'  # issue 27's draw: agents 1 and 3 0.30508 m apart
    dump_scenario(safety_cases.random_square(100, safety=None, side=2.2), path)
    assert main(['validate', str(path), '--robot', 'unicycle', '--json']) == 0
    captured = capsys.readouterr()
    # Burgers: r = 0.105 m, l = 0.1 m: origins 2 · 0.105 + 0.05 = 0.26 m, control points 0.46 m
    assert json.loads(captured.out)['safety']['min_separation'] == pytest.approx(0.46)
    assert "keeps the robots' origins 0.26 m apart (unicycle footprints (r = 0.105 m))" in captured.err
    assert 'agents 1 and 3 start 0.30508 m apart, inside the separation 0.46 m' in captured.err
    assert main(['validate', str(path), '--robot', 'unicycle', '--min-separation', '0.25', '--json']) == 0
    assert json.loads(capsys.readouterr().out)['safety']['min_separation'] == pytest.approx(0.45)
    assert main(['validate', str(path), '--robot', 'holonomic', '--min-separation', '0.25', '--json']) == 0
    assert json.loads(capsys.readouterr().out)['safety']['min_separation'] == pytest.approx(0.25)
    assert main(['validate', str(path), '--json']) == 0  # no robots: no layer by default
    assert 'safety' not in json.loads(capsys.readouterr().out)
    code = main(['validate', str(path), '--robot', 'unicycle', '--footprint-radius', '0.16'])
    assert code == 2
    assert (
        'robots overlap: agents 1 and 3 are set down with their origins 0.30508 m apart'
        in capsys.readouterr().err
    )
