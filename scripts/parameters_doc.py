#!/usr/bin/env python3
"""Write docs/PARAMETERS.md, one table per node, from the nodes' own ParameterSpecs (the tables
`--help` prints and `ros2 param describe` shows); `--check` only says whether it is up to date.

    python scripts/parameters_doc.py            # rewrite docs/PARAMETERS.md
    python scripts/parameters_doc.py --check    # exit 1 if it differs from the specs
"""

import argparse
import sys
from pathlib import Path

DOC = Path(__file__).resolve().parents[1] / 'docs' / 'PARAMETERS.md'

INTRO = """\
# Node parameters

Generated from the nodes' declarations by `python scripts/parameters_doc.py` (a test checks that it
is up to date). Every node declares its parameters from one table of
`formation_agent.ros.parameters.ParameterSpec`s: each with a description, a type, and its range or
choices as a `ParameterDescriptor` (read-only: a node reads them once, at start), so on a ROS 2
Jazzy install `ros2 param describe /formation_recorder output` explains it; the node's `--help`
prints the same table. Missing parameters, values of the wrong type, out of range or not among
the choices are all named in one error, and the node exits with status 2 before it starts
anything. `formation run` writes every node's parameter file into its run folder, and `formation
params SCENARIO --out DIR` writes the same files without starting anything ([Agents on separate
machines](SEPARATE_MACHINES.md)).
"""


def sections() -> list[tuple[str, str, object]]:
    """(heading, what it is, specs) per node command."""
    from formation_agent.ros.config import AGENT_PARAMETERS, GAIN_PARAMETERS
    from formation_sim.runtime.nodes.coordinator import COORDINATOR_PARAMETERS
    from formation_sim.runtime.nodes.recorder import RECORDER_PARAMETERS
    from formation_sim.runtime.nodes.robot_node import SPECS as ROBOT_PARAMETERS
    from formation_sim.runtime.nodes.sim_node import SIMULATOR_PARAMETERS

    return [
        (
            '`formation_agent`: node `/agent_<i>/formation_agent`',
            'An agent (`formation_agent.ros.config`), in `agents.params.yaml` keyed by node name. '
            'The gains are '
            'those of its algorithm: `alpha`, `beta` for eta1; `alpha_d`, `beta_d`, `k1`, `k2`, '
            '`k3` for eta2.',
            (*AGENT_PARAMETERS, *GAIN_PARAMETERS['eta1'], *GAIN_PARAMETERS['eta2']),
        ),
        (
            '`formation_sim`: node `/formation_simulator`',
            'The simulator of the exact backend (`formation_sim.runtime.nodes.sim_node`), in '
            '`simulator.params.yaml`.',
            SIMULATOR_PARAMETERS,
        ),
        (
            '`formation_coordinator`: node `/formation_coordinator`',
            'The time keeper of robot runs (`formation_sim.runtime.nodes.coordinator`), in '
            '`coordinator.params.yaml`.',
            COORDINATOR_PARAMETERS,
        ),
        (
            '`formation_recorder`: node `/formation_recorder`',
            'The recorder (`formation_sim.runtime.nodes.recorder`), in `recorder.params.yaml`.',
            RECORDER_PARAMETERS,
        ),
        (
            '`formation_robot`: node `/agent_<i>/simulated_robot`',
            'A simulated robot (`formation_sim.runtime.nodes.robot_node`), in `robots.params.yaml` keyed '
            'by node name.',
            ROBOT_PARAMETERS,
        ),
    ]


def render() -> str:
    from formation_agent.ros.parameters import parameter_table

    parts = [INTRO]
    for heading, what, specs in sections():
        parts.append(f'## {heading}\n\n{what}\n\n{parameter_table(specs)}\n')
    return '\n'.join(parts)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        '--check', action='store_true', help='exit 1 if docs/PARAMETERS.md is not what the specs say'
    )
    args = parser.parse_args()
    text = render()
    if args.check:
        if DOC.read_text(encoding='utf-8') != text:
            print(f'{DOC} is out of date: run python scripts/parameters_doc.py', file=sys.stderr)
            return 1
        return 0
    DOC.write_text(text, encoding='utf-8')
    print(DOC)
    return 0


if __name__ == '__main__':
    sys.exit(main())
