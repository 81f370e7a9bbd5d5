#!/usr/bin/env python3
"""Write docs/EXIT_CODES.md and docs/TOPICS.md from the code; `--check` only says whether they are
up to date (a test runs it, as for docs/PARAMETERS.md).

- EXIT_CODES.md: every member of `formation_msgs_py.exit_codes.ExitCode` with what it means and the
  modules that return it (every `ExitCode.<NAME>` under src), one row per status.
- TOPICS.md: the processes of a run and the topics between them, from the topic lists the
  recorder is given (`sim_node.formation_topics`, `coordinator.robot_run_topics`) and the names of
  `formation_msgs_py.topics`.

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
def _roles() -> dict[str, tuple[str, str]]:
    from formation_msgs_py import topics as t

    return {
        t.STEP_TOPIC: ('time keeper', 'agents, recorder (its clock)'),
        t.STATUS_TOPIC: ('agents', 'time keeper'),
        t.REPORT_TOPIC: ('agents', 'time keeper, recorder'),
        t.STATE_TOPIC: ('simulator', 'recorder, tools'),
        t.GROUND_TRUTH_TOPIC: ('simulator', 'recorder, tools'),
        t.SENSING_LOG_TOPIC: ('simulator', 'recorder, tools'),
        t.CLOCK_TOPIC: ('simulator', 'recorder, tools'),
        t.SCENARIO_TOPIC: ('time keeper', 'recorder, tools'),
        t.MARKERS_TOPIC: ('simulator', 'recorder, Foxglove'),
        t.ROBOTS_TOPIC: ('coordinator', 'recorder, tools'),
        'trigger_info': ('agent i', 'agent j, recorder'),
        'cmd': ('agent i', 'simulator (its plant), recorder'),
        'robot/pose': (
            'robot i (motion capture, simulated robot)',
            'agent i and its neighbours, coordinator, recorder',
        ),
        'robot/odom': ('robot i', 'agent i and its neighbours, coordinator, recorder'),
        'robot/true_odom': ('simulated robot i', 'coordinator, recorder'),
        'robot/cmd_vel': ('agent i (coordinator: the zero command)', 'robot i, recorder'),
    }


def _role_key(topic: str) -> str:
    roles = _roles()
    if topic in roles:
        return topic
    for key in ('trigger_info', 'robot/true_odom', 'robot/pose', 'robot/odom', 'robot/cmd_vel'):
        if f'/{key}' in topic:
            return key
    if topic.endswith(('/cmd_vel', '/cmd_accel')):
        return 'cmd'
    raise SystemExit(f'topic {topic} has no writer and readers in scripts/reference_docs.py: add them')


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
        writer, readers = _roles()[_role_key(topic)]
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
        writer, readers = _roles()[_role_key(topic)]
        writer = keeper if writer == 'time keeper' else writer
        by_writer.setdefault(writer, []).append(f'  ──{name}──▶ {readers.replace("time keeper", keeper)}')
    out = ['```text']
    for writer, lines in by_writer.items():
        out += [f'[{writer}]', *lines, '']
    return [*out[:-1], '```']


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
            'formation_topics`, `formation_sim.runtime.coordinator.robot_run_topics`), spelled in',
            '`formation_msgs_py.topics`; every agent `i` lives in the namespace `/agent_<i>`. Each',
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
