#!/usr/bin/env python3
"""Write docs/EXIT_CODES.md and docs/TOPICS.md from the code; `--check` only says whether they are
up to date (a test runs it, as for docs/PARAMETERS.md).

- EXIT_CODES.md: every member of `formation_msgs_py.exit_codes.ExitCode` with what it means and the
  modules that return it (every `ExitCode.<NAME>` under src), one row per status.
- TOPICS.md: the processes of a run and the topics between them, from the topic lists the
  recorder is given (`contract.formation_topics`, `contract.robot_run_topics`) and the topic
  table they are drawn from (`formation_msgs_py.topic_table`).

    python scripts/reference_docs.py            # rewrite both
    python scripts/reference_docs.py --check    # exit 1 if either differs from the code
"""

import argparse
import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / 'docs'

SRC = ROOT / 'src'
PACKAGES = ('formation_msgs_py', 'formation_agent', 'formation_sim')


def exit_code_users() -> dict[int, list[str]]:
    """status -> the modules under src that name its `ExitCode` member (`ExitCode.LOST`), sorted."""
    from formation_msgs_py.exit_codes import ExitCode

    users: dict[int, set[str]] = {code: set() for code in ExitCode}
    for package in PACKAGES:
        root = SRC / package
        for path in sorted((root / package).rglob('*.py')):
            module = '.'.join(path.relative_to(root).with_suffix('').parts).removesuffix('.__init__')
            if module == 'formation_msgs_py.exit_codes':
                continue
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if (
                    isinstance(node, ast.Attribute)
                    and isinstance(node.value, ast.Name)
                    and node.value.id == 'ExitCode'
                ):
                    users[ExitCode[node.attr]].add(module)
    return {code: sorted(found) for code, found in users.items()}


def render_exit_codes() -> str:
    from formation_msgs_py.exit_codes import SENTENCE, ExitCode

    users = exit_code_users()
    rows = [
        f'| {code} | `{code.name}` | {code.meaning} | {", ".join(f"`{m}`" for m in users[code]) or "—"} |'
        for code in ExitCode
    ]
    return '\n'.join(
        [
            '# Exit codes',
            '',
            'Generated from the code by `python scripts/reference_docs.py` (a test checks that it is up',
            'to date): every exit status a command or a node process can end with is a member of one',
            'enum, `formation_msgs_py.exit_codes.ExitCode`, which also writes the `formation --help`',
            'epilog. The statuses mean the same in every command, in one sentence:',
            '',
            SENTENCE,
            '',
            "What each fault of a run looks like: [Reliability](RELIABILITY.md); an operator's stop:",
            '[Emergency stop](EMERGENCY_STOP.md).',
            '',
            '| status | `ExitCode` | meaning | returned in |',
            '|---|---|---|---|',
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
    from formation_sim.runtime.contract import formation_topics, robot_run_topics

    exact = formation_topics(load_scenario('paper_single'))
    robots = robot_run_topics(
        load_scenario('robots_square'), model='holonomic', simulated=True, pose_type='pose'
    )
    return '\n'.join(
        [
            '# Processes and topics',
            '',
            'Generated from the code by `python scripts/reference_docs.py` (a test checks that it is up',
            'to date): the topics are the lists a run gives its recorder (`formation_sim.runtime.contract.',
            'formation_topics`, `formation_sim.runtime.contract.robot_run_topics`), both drawn from',
            '[the topic table](#the-topic-table); every agent `i` lives in the namespace `/agent_<i>`. Each',
            'process is its own OS process (agents may share one: `--agents-per-process`), all in one',
            'private ROS domain. Message layouts and QoS: [MESSAGES.md](MESSAGES.md); the protocol:',
            '[the distributed runtime](RUNTIME.md).',
            '',
            '## On the exact backend (`formation run SCENARIO`)',
            '',
            "The simulator is the time keeper and the world: it answers each agent's sensing service",
            "`/agent_<i>/sense` (`rcl_interfaces/srv/SetParameters`, its request tagged) at the agent's",
            'triggers, and moves the world with the commands.',
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
