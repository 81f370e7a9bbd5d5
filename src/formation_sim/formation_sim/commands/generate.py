"""`formation generate --agents N --out FILE`: a random team meeting every hypothesis of Theorem 1
or 2, as a scenario file.

The team is `formation_sim.model.generate.random_scenario`; the file is JSON if its name ends in
.json (the format for large teams: the json module reads 10 000 agents in half a second, PyYAML
refuses files above ~9 000), else YAML. The text is read back before it is written, so a file
`formation generate` writes is one `load_scenario` reads, to the bit.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from formation_msgs_py.exit_codes import ExitCode
from formation_sim.commands.common import NON_NEGATIVE_INT, POSITIVE, POSITIVE_INT, UNIT_FRACTION, refuse


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'generate',
        help='write a random valid team as a scenario file (JSON for large teams)',
        description='Write a random team that meets every hypothesis of Theorem 1 (single) or 2 (double) '
        'by construction (formation_sim.model.generate.random_scenario): a geometric graph of the given '
        'mean degree, the initial condition (initial) held with the given slack on every edge, β = β0/2. '
        'The file is JSON if --out ends in .json (for large teams), else YAML.',
        epilog='Exit status: 0 written; 2 bad input (nothing was written).',
    )
    parser.add_argument(
        '--agents',
        type=POSITIVE_INT,
        required=True,
        metavar='N',
        help='number of agents (ids 1..N), at least 2',
    )
    parser.add_argument('--seed', type=NON_NEGATIVE_INT, default=0, help='random seed (default 0)')
    parser.add_argument(
        '--dynamics',
        choices=('single', 'double'),
        default='single',
        help='single (ETA-1) or double (ETA-2) integrators',
    )
    parser.add_argument(
        '--dimension',
        type=POSITIVE_INT,
        default=2,
        metavar='P',
        help='dimension p of the positions (default 2)',
    )
    parser.add_argument('--degree', type=POSITIVE, default=6.0, help='mean degree of the graph (default 6)')
    parser.add_argument(
        '--slack',
        type=UNIT_FRACTION,
        default=0.5,
        help='least relative slack of (initial) over the edges (default 0.5)',
    )
    parser.add_argument(
        '--horizon', type=POSITIVE, default=10.0, help='horizon of the scenario [s] (default 10)'
    )
    parser.add_argument('--name', default=None, help='scenario name (default random_<dynamics>_n<N>_seed<S>)')
    parser.add_argument(
        '--out', type=Path, required=True, help='the scenario file to write: NAME.json or NAME.yaml'
    )
    parser.add_argument('--force', action='store_true', help='replace an existing file')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from formation_sim.model.errors import GenerateError, ScenarioError
    from formation_sim.model.generate import random_scenario
    from formation_sim.model.scenario import dump_scenario_as, file_kind, scenario_from_text
    from formation_sim.sim.files import write_atomically

    out: Path = args.out
    if out.suffix.lower() not in ('.json', '.yaml', '.yml'):
        return refuse('generate', f'argument --out: a scenario file ends in .json or .yaml, got {out}')
    if out.is_dir():
        return refuse('generate', f'argument --out: {out} is a folder')
    if out.exists() and not args.force:
        return refuse(
            'generate',
            f'{out} exists; nothing was changed: choose another --out or add --force to replace it',
        )
    if not out.parent.is_dir():
        return refuse('generate', f'argument --out: no folder {out.parent} to write {out.name} into')
    if args.agents < 2:
        return refuse(
            'generate', f'argument --agents: a formation needs at least 2 agents, got {args.agents}'
        )
    try:
        scenario = random_scenario(
            n=args.agents,
            seed=args.seed,
            dynamics=args.dynamics,
            dimension=args.dimension,
            slack=args.slack,
            degree=args.degree,
            horizon=args.horizon,
            name=args.name,
        )
    except (GenerateError, ScenarioError) as error:
        return refuse('generate', error)
    kind = file_kind(out)
    text = dump_scenario_as(scenario, kind)
    try:
        if (
            scenario_from_text(text, kind=kind, source=str(out), name=out.stem) != scenario
        ):  # pragma: no cover - dump is exact
            return refuse('generate', f'{out}: the {kind} text does not read back as the team generated')
    except ScenarioError as error:
        return refuse(
            'generate', f'{error}; nothing was written' + ('; write .json instead' if kind == 'YAML' else '')
        )
    try:
        write_atomically(out, text)
    except OSError as error:
        return refuse('generate', f'cannot write {out}: {error.strerror or error}')
    print(
        f'{out}: {scenario.name}, {scenario.n} agents, {len(scenario.edges)} edges, {scenario.dynamics} '
        f'integrators in {scenario.dimension}-D ({kind})'
    )
    return ExitCode.OK
