#!/usr/bin/env python3
"""Write docs/EXIT_CODES.md and docs/TOPICS.md from the code; `--check` only says whether they are
up to date (a test runs it, as for docs/PARAMETERS.md).

- EXIT_CODES.md: every `EXIT_<NAME> = <status>` of the modules that define exit statuses, with the
  comment or docstring the code gives it, one row per status.
- TOPICS.md: the processes of a run and the topics between them, from the topic lists the
  recorder is given (`sim_node.formation_topics`, `coordinator.robot_run_topics`) and the topic
  table they are drawn from (`formation_msgs_py.topic_table`).

    python scripts/reference_docs.py            # rewrite both
    python scripts/reference_docs.py --check    # exit 1 if either differs from the code
"""

import argparse
import ast
import importlib
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / 'docs'

# Where exit statuses are defined, in the order the table names them.
EXIT_MODULES = (
    'formation_sim.commands.common',
    'formation_agent.ros.process',
    'formation_sim.runtime.results',
    'formation_sim.runtime.coordinator',
    'formation_sim.commands.analyze',
    'formation_sim.commands.validate',
    'formation_sim.commands.study',
)
# What a status means where no definition says it in a comment (0 and 130 are conventions).
PLAIN = {
    0: 'done: the command did what was asked and every check holds',
    130: 'interrupted (Ctrl-C, SIGINT or SIGTERM)',
}


def _source_comment(lines: list[str], node: ast.Assign, body: list, index: int) -> str:
    """The definition's trailing `# comment`, else the string right after it, else ''."""
    line = lines[node.lineno - 1]
    if '#' in line.split('=', 1)[1]:
        return line.split('#', 1)[1].strip()
    following = body[index + 1] if index + 1 < len(body) else None
    if isinstance(following, ast.Expr) and isinstance(following.value, ast.Constant):
        return ' '.join(str(following.value.value).split())
    return ''


def exit_statuses() -> dict[int, list[tuple[str, str]]]:
    """status -> [(module.NAME, what the code says of it)]."""
    found: dict[int, list[tuple[str, str]]] = {}
    for name in EXIT_MODULES:
        module = importlib.import_module(name)
        path = Path(module.__file__)
        lines = path.read_text().splitlines()
        body = ast.parse(path.read_text()).body
        for index, node in enumerate(body):
            if not (isinstance(node, ast.Assign) and len(node.targets) == 1):
                continue
            target = getattr(node.targets[0], 'id', '')
            value = getattr(module, target, None)
            if not target.startswith('EXIT_') or type(value) is not int:
                continue
            found.setdefault(value, []).append(
                (f'{name}.{target}', _source_comment(lines, node, body, index))
            )
    return dict(sorted(found.items()))


def _plain(comment: str) -> str:
    """A comment as a table cell: 'Exit status of a node that ... .' -> 'a node that ...'; a bare
    number (`# 3`, the value spelled out) says nothing."""
    text = comment.removeprefix('Exit status of ').rstrip('.').strip()
    return '' if text.isdigit() else text


def render_exit_codes() -> str:
    rows = []
    for status, names in exit_statuses().items():
        said = list(dict.fromkeys(_plain(comment) for _, comment in names if _plain(comment)))
        if not said and status not in PLAIN:
            raise SystemExit(f'exit status {status} ({names[0][0]}) has no comment in the code: add one')
        meaning = '; '.join(said) if said else PLAIN[status]
        if status in PLAIN and said:
            meaning = f'{PLAIN[status]}; {meaning}'
        defined = ', '.join(f'`{name}`' for name, _ in names)
        rows.append(f'| {status} | {meaning} | {defined} |')
    return '\n'.join(
        [
            '# Exit codes',
            '',
            'Generated from the code by `python scripts/reference_docs.py` (a test checks that it is up',
            'to date): every exit status a command or a node process can end with, what the code says of',
            'it, and where it is defined. The statuses mean the same in every command: 0 done, 1 the',
            'command ran and the answer is no, 2 bad input refused before anything started or changed;',
            '`formation run` and the node processes add 3 (a process, an agent, a robot or the recorder',
            "was lost), 4 (the robots' measured start breaks the initial condition: nothing was sent),",
            '5 (an operator stopped the run: [Emergency stop](EMERGENCY_STOP.md)) and 130 (interrupted).',
            'What each fault of a run looks like: [Reliability](RELIABILITY.md).',
            '',
            '| status | meaning | defined as |',
            '|---|---|---|',
            *rows,
            '',
        ]
    )


# Who writes and who reads each topic of a run (the names come from formation_msgs_py.topics; a
# topic of the lists without a row here fails the generator, so the page cannot fall behind).
def _row(topic: str):
    """The topic table's row of a topic (`formation_msgs_py.topic_table`)."""
    from formation_msgs_py.topic_table import match_topic

    if (found := match_topic(topic)) is None:
        raise SystemExit(f'topic {topic} is not in formation_msgs_py.topic_table: add its row')
    return found[0]


def _roles_of(topic: str) -> tuple[str, str]:
    row = _row(topic)
    return row.writer, row.readers


def _generic(topic: str) -> str:
    """/agent_1/trigger_info/to_2 -> /agent_<i>/trigger_info/to_<j>."""
    parts = ['agent_<i>' if re.fullmatch(r'agent_\d+', p) else p for p in topic.split('/')]
    return '/'.join('to_<j>' if re.fullmatch(r'to_\d+', p) else p for p in parts)


def _topic_table(listed: list[tuple[str, str]]) -> list[str]:
    rows, seen = [], set()
    for topic, msgtype in listed:
        name = _generic(topic)
        if name in seen:
            continue
        seen.add(name)
        writer, readers = _roles_of(topic)
        rows.append(f'| `{name}` | `{msgtype}` | {writer} | {readers} |')
    return ['| topic | type | written by | read by |', '|---|---|---|---|', *rows]


def _diagram(listed: list[tuple[str, str]], keeper: str) -> list[str]:
    """One line per writer: the topics it writes and who reads them."""
    by_writer: dict[str, list[str]] = {}
    seen = set()
    for topic, _ in listed:
        name = _generic(topic)
        if name in seen:
            continue
        seen.add(name)
        writer, readers = _roles_of(topic)
        writer = keeper if writer == 'time keeper' else writer
        by_writer.setdefault(writer, []).append(f'  ──{name}──▶ {readers.replace("time keeper", keeper)}')
    out = ['```text']
    for writer, lines in by_writer.items():
        out += [f'[{writer}]', *lines, '']
    return [*out[:-1], '```']


def _whole_table() -> list[str]:
    """Every row of the topic table (`formation_msgs_py.topic_table.TOPICS`)."""
    from formation_msgs_py.topic_table import KIND_COMMAND, TOPICS

    def yes(flag: bool) -> str:
        return 'yes' if flag else 'no'

    lines = ['| topic | type | writer QoS | recorded on | counted | tagged |', '|---|---|---|---|---|---|']
    for row in TOPICS:
        msgtype = "the robot kind's command type" if row.msgtype == KIND_COMMAND else f'`{row.msgtype}`'
        recorded = ', '.join(sorted(row.recorded)) or 'never'
        if row.when is not None:
            recorded += f' ({row.when})'
        flags = f'{yes(row.counted)} | {yes(row.tagged)}'
        lines.append(f'| `{row.pattern}` | {msgtype} | `{row.qos}` | {recorded} | {flags} |')
    return lines


def render_topics() -> str:
    from formation_sim.model.scenario import load_scenario
    from formation_sim.runtime.coordinator import robot_run_topics
    from formation_sim.runtime.sim_node import formation_topics

    exact = formation_topics(load_scenario('paper_single'))
    robots = robot_run_topics(
        load_scenario('robots_square'), model='holonomic', simulated=True, pose_type='pose'
    )
    return '\n'.join(
        [
            '# Processes and topics',
            '',
            'Generated from the code by `python scripts/reference_docs.py` (a test checks that it is up',
            'to date): the topics are the lists a run gives its recorder (`formation_sim.runtime.sim_node.',
            'formation_topics`, `formation_sim.runtime.coordinator.robot_run_topics`), both drawn from',
            '[the topic table](#the-topic-table); every agent `i` lives in the namespace `/agent_<i>`. Each',
            'process is its own OS process (agents may share one: `--agents-per-process`), all in one',
            'private ROS domain. Message layouts and QoS: [MESSAGES.md](MESSAGES.md); the protocol:',
            '[the distributed runtime](RUNTIME.md).',
            '',
            '## On the exact backend (`formation run SCENARIO`)',
            '',
            "The simulator is the time keeper and the world: it answers each agent's sensing service",
            "`/agent_<i>/sense` (`std_srvs/srv/Trigger`) at the agent's triggers, and moves the world",
            'with the commands.',
            '',
            *_diagram(exact, 'simulator'),
            '',
            *_topic_table(exact),
            '',
            '## On robots (`formation run SCENARIO --backend holonomic | unicycle | car | external`)',
            '',
            'The coordinator is the time keeper; the robots (simulated, or your own) are the world:',
            'agents read poses and command velocities themselves (shown for simulated holonomic robots',
            'reporting poses; odometry instead with `--pose-type odom`).',
            '',
            *_diagram(robots, 'coordinator'),
            '',
            *_topic_table(robots),
            '',
            '## The topic table',
            '',
            "Every topic of a run, one row of `formation_msgs_py.topic_table.TOPICS`: the recorders' lists,",
            "the launch plan's counting and the analysis' dispatch are derived from it. *writer QoS*: the",
            'profile of `formation_msgs_py.qos` its writer offers (robot poses: the profile agents read',
            'them with); *recorded on*: the backends whose recorder records it (`exact`; `robots`: every',
            'robot backend), and under which condition (the dynamics, the pose topics a robot run uses);',
            "*counted*: the run's nodes count what they publish on it (summary.json `extra.published`,",
            "checked against the bag); *tagged*: its messages carry the run's tag (HOSTILE_TRAFFIC.md,",
            '"Tags").',
            '',
            *_whole_table(),
            '',
        ]
    )


PAGES = {'EXIT_CODES.md': render_exit_codes, 'TOPICS.md': render_topics}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--check', action='store_true', help='exit 1 if a page differs from the code')
    args = parser.parse_args(argv)
    stale = []
    for name, render in PAGES.items():
        path, text = DOCS / name, render()
        if args.check:
            if not path.is_file() or path.read_text() != text:
                stale.append(name)
        else:
            path.write_text(text)
            print(f'wrote {path}')
    if stale:
        print(f'out of date: {", ".join(stale)}; run python scripts/reference_docs.py', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
