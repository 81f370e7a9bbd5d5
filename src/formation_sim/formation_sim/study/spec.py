"""A study's SPEC: cases given as grids and random draws over teams, gains, algorithm and horizon.

YAML (or a dict with the same shape; docs/STUDY.md has the reference):

    name: smoke
    seed: 1                   # the random draws' seed
    defaults: {horizon: 2}    # fixed values for every block (a block's own value wins)
    cases:                    # blocks
      - n: [3, 5]             # a list is a grid axis
        graph: [star, path]
        algorithm: eta1       # a scalar is fixed
      - draws: 100            # random draws of the block's distributions
        n: {integers: [2, 100]}
        slack: {log_uniform: [0.001, 0.9]}
        graph: {choice: [geometric, star, path, cycle, complete]}
        # also uniform: [a, b], integers: [i, j], log_integers: [i, j] (log-uniform, rounded)

A block is the product of its grid axes times `draws` (default 1) draws of its distributions; draw
d of block b uses numpy's default_rng([seed, b, d]) and draws the parameters in name order, so a
case depends on the SPEC alone; a team's seed is d unless given, so the grid points of one draw
share their team (an ETA run and its periodic baseline). Every value is checked against
PARAMETERS (the parameter, the rule and the value are named); cases identical after normalisation
(a `period` is kept only with `sampling: periodic`, a graph's `degree` only for `geometric`, ETA-2's
gains only for ETA-2) are run once. A case's key is a hash of its parameters: the rows of a study
are keyed by it.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from formation_sim.model.generate import GRAPH_FAMILIES
from formation_sim.model.scenario import short_repr
from formation_sim.study.errors import StudyError

ALGORITHMS = ('eta1', 'eta2')  # ETA-1: single integrators (Theorem 1); ETA-2: double (Theorem 2)
SAMPLINGS = ('event', 'periodic', 'continuous')
BETA_D_BOUNDS = ('printed', 'corrected')  # what β_d is a fraction of (docs/THEOREM2.md)


def _is_int(v: Any) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool)


def _is_num(v: Any) -> bool:
    return (
        isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) and math.isfinite(v)
    )


def _scale_ok(name: str, value: Any) -> bool:
    """κ or c0 within formation_agent.core.speed_scale's rules (the scenario's own check)."""
    from formation_agent.core.errors import ScaleError
    from formation_agent.core.speed_scale import check_speed_scale, check_threshold_floor

    if not _is_num(value):
        return False
    try:
        (check_speed_scale if name == 'speed_scale' else check_threshold_floor)(value)
    except ScaleError:
        return False
    return True


@dataclass(frozen=True)
class Parameter:
    """One case parameter: its default (None: unset), its rule as text and the test of a value."""

    default: Any
    rule: str
    holds: Any  # callable(value) -> bool


PARAMETERS: dict[str, Parameter] = {
    'algorithm': Parameter('eta1', f'one of {", ".join(ALGORITHMS)}', lambda v: v in ALGORITHMS),
    'sampling': Parameter('event', f'one of {", ".join(SAMPLINGS)}', lambda v: v in SAMPLINGS),
    'period': Parameter(
        None, "a number > 0 (the periodic baseline's period [s])", lambda v: _is_num(v) and v > 0
    ),
    'n': Parameter(None, 'an integer >= 2 (agents)', lambda v: _is_int(v) and v >= 2),
    'p': Parameter(2, 'an integer in [1, 10] (dimension)', lambda v: _is_int(v) and 1 <= v <= 10),
    'graph': Parameter('geometric', f'one of {", ".join(GRAPH_FAMILIES)}', lambda v: v in GRAPH_FAMILIES),
    'degree': Parameter(
        6.0, 'a number > 0 (mean degree of a geometric graph)', lambda v: _is_num(v) and v > 0
    ),
    'slack': Parameter(
        0.5, 'a number in (0, 1] (least relative slack of (initial))', lambda v: _is_num(v) and 0 < v <= 1
    ),
    'seed': Parameter(
        None,
        "an integer >= 0 (the team's seed; default: the number of the draw in its block, from 0)",
        lambda v: _is_int(v) and v >= 0,
    ),
    'delta': Parameter(4.0, 'a number > 0 (Δ)', lambda v: _is_num(v) and v > 0),
    'alpha': Parameter(1.0, 'a number > 0 (α, or α_d for ETA-2)', lambda v: _is_num(v) and v > 0),
    'beta': Parameter(
        0.5, 'a number in (0, 1): β as a fraction of β0 (ETA-1)', lambda v: _is_num(v) and 0 < v < 1
    ),
    'beta1': Parameter(
        1.0, 'a number in (0, 1]: β1 as a fraction of β0 (ETA-2)', lambda v: _is_num(v) and 0 < v <= 1
    ),
    'k3': Parameter(
        None,
        "a number in (0, 1): k3 as a fraction of 4/(k2+sqrt(k1²+k2²)) (ETA-2; default the paper's, 1/2)",
        lambda v: _is_num(v) and 0 < v < 1,
    ),
    'beta_d': Parameter(
        None,
        'a number in (0, 1): β_d as a fraction of the bound named by beta_d_bound (ETA-2; default half '
        'the smaller bound)',
        lambda v: _is_num(v) and 0 < v < 1,
    ),
    'beta_d_bound': Parameter(
        'printed',
        f'one of {", ".join(BETA_D_BOUNDS)}: the bound β_d is a fraction of, the printed (2-k4)ρ2(P) or '
        'the corrected (2-k4)/λmax(P) of docs/THEOREM2.md (ETA-2)',
        lambda v: v in BETA_D_BOUNDS,
    ),
    'max_speed': Parameter(1.0, 'a number >= 0 (bound on |q_i(0)|, ETA-2)', lambda v: _is_num(v) and v >= 0),
    'horizon': Parameter(5.0, 'a number > 0 [s]', lambda v: _is_num(v) and v > 0),
    'until_error': Parameter(
        None,
        'a number in (0, 1): end an event run at its first event whose formation error is below this '
        'fraction of the initial one, or on the rounding floor (the horizon stays the upper bound)',
        lambda v: _is_num(v) and 0 < v < 1,
    ),
    'speed_scale': Parameter(
        1.0,
        "a number > 0 (the speed scale κ; docs/SPEED_SCALE.md; 1 is the paper's)",
        lambda v: _scale_ok('speed_scale', v),
    ),
    'threshold_floor': Parameter(
        0.0,
        "a number >= 0 (the threshold floor c0; docs/SPEED_SCALE.md; 0 is the paper's)",
        lambda v: _scale_ok('threshold_floor', v),
    ),
}
# Parameters added after studies were run: at their default (or None, where they do not apply) they
# stay out of a case's key, so the cases (and study folders) of earlier SPECs keep their keys.
LATE_PARAMETERS = ('speed_scale', 'threshold_floor', 'until_error', 'beta_d_bound')
INTEGERS = ('n', 'p', 'seed')
ETA2_ONLY = ('beta1', 'k3', 'beta_d', 'beta_d_bound', 'max_speed')
DISTRIBUTIONS = ('uniform', 'log_uniform', 'integers', 'log_integers', 'choice')
TOP_KEYS = ('name', 'seed', 'defaults', 'cases')


@dataclass(frozen=True, kw_only=True)
class Case:
    """One run of a study: its parameters (every key of PARAMETERS, None where it does not apply)."""

    index: int  # position in the study, from 0
    key: str  # hash of the parameters: what the rows are keyed by
    block: int
    params: dict[str, Any]

    def describe(self) -> str:
        p = self.params
        return (
            f'case {self.index} (cases[{self.block}]: {p["algorithm"]} {p["sampling"]} n={p["n"]} '
            f'p={p["p"]} {p["graph"]} seed={p["seed"]})'
        )


@dataclass(frozen=True, kw_only=True)
class Study:
    name: str
    cases: tuple[Case, ...]
    digest: str  # hash of every case's key, in order: the identity of the study
    text: str  # the SPEC as given (JSON of the dict, or the YAML text)


def _normalise(params: dict[str, Any], where: str) -> dict[str, Any]:
    """Check every value and drop what does not apply (period, degree, ETA-2's gains)."""
    out = {}
    for name, spec in PARAMETERS.items():
        value = params.get(name, spec.default)
        if isinstance(value, np.generic):
            value = value.item()
        if value is not None and not spec.holds(value):
            raise StudyError(f'{where}.{name}: must be {spec.rule}, got {short_repr(value)}')
        out[name] = float(value) if name not in INTEGERS and _is_num(value) else value
    if out['n'] is None:
        raise StudyError(f'{where}.n: must be given ({PARAMETERS["n"].rule})')
    if out['sampling'] == 'periodic':
        if out['period'] is None:
            raise StudyError(
                f'{where}.period: sampling: periodic needs a period ({PARAMETERS["period"].rule})'
            )
    else:
        out['period'] = None
    if out['graph'] != 'geometric':
        out['degree'] = None
    if out['graph'] == 'cycle' and out['n'] < 3:
        raise StudyError(f'{where}: a cycle needs n >= 3 agents, got n = {out["n"]}')
    if out['algorithm'] == 'eta1':
        for name in ETA2_ONLY:
            out[name] = None
    else:
        out['beta'] = None
    return out


def _distribution(value: Any, where: str) -> tuple[str, Any] | None:
    """(kind, arguments) if value is a distribution {kind: args}, else None."""
    if not isinstance(value, dict):
        return None
    if len(value) != 1 or next(iter(value)) not in DISTRIBUTIONS:
        raise StudyError(
            f'{where}: a distribution is one of {{{", ".join(f"{d}: ..." for d in DISTRIBUTIONS)}}}, '
            f'got {short_repr(value)}'
        )
    kind, args = next(iter(value.items()))
    if kind == 'choice':
        if not isinstance(args, list) or not args:
            raise StudyError(f'{where}.choice: must be a non-empty list, got {short_repr(args)}')
        return kind, args
    if not (
        isinstance(args, list) and len(args) == 2 and all(_is_num(a) for a in args) and args[0] <= args[1]
    ):
        raise StudyError(f'{where}.{kind}: must be [low, high] with low <= high, got {short_repr(args)}')
    if kind in ('log_uniform', 'log_integers') and not args[0] > 0:
        raise StudyError(f'{where}.{kind}: low must be > 0, got {short_repr(args[0])}')
    if kind in ('integers', 'log_integers') and not all(_is_int(a) for a in args):
        raise StudyError(f'{where}.{kind}: must be two integers, got {short_repr(args)}')
    return kind, args


def _draw(rng: np.random.Generator, kind: str, args: Any) -> Any:
    if kind == 'uniform':
        return float(rng.uniform(args[0], args[1]))
    if kind == 'log_uniform':
        return float(math.exp(rng.uniform(math.log(args[0]), math.log(args[1]))))
    if kind == 'integers':
        return int(rng.integers(args[0], args[1], endpoint=True))
    if kind == 'log_integers':  # log-uniform on [low - 1/2, high + 1/2], rounded: every integer can come
        return int(
            min(
                args[1],
                max(args[0], round(math.exp(rng.uniform(math.log(args[0] - 0.5), math.log(args[1] + 0.5))))),
            )
        )
    return args[int(rng.integers(len(args)))]


def _block_cases(
    block: dict[str, Any], defaults: dict[str, Any], seed: int, number: int
) -> list[dict[str, Any]]:
    """The normalised parameters of block `number` (grid axes x draws), in order."""
    where = f'cases[{number}]'
    if not isinstance(block, dict):
        raise StudyError(f'{where}: a block is a mapping of parameters, got {short_repr(block)}')
    unknown = sorted(set(block) - set(PARAMETERS) - {'draws'})
    if unknown:
        raise StudyError(
            f'{where}: unknown key {unknown[0]!r} (parameters: {", ".join(PARAMETERS)}; and draws)'
        )
    draws = block.get('draws', 1)
    if not (_is_int(draws) and draws >= 1):
        raise StudyError(f'{where}.draws: must be an integer >= 1, got {short_repr(draws)}')
    merged = {**defaults, **{k: v for k, v in block.items() if k != 'draws'}}
    axes, randoms, fixed = {}, {}, {}
    for name in sorted(merged):
        value = merged[name]
        if isinstance(value, list):
            if not value:
                raise StudyError(f'{where}.{name}: a grid axis needs at least one value')
            axes[name] = value
        elif (dist := _distribution(value, f'{where}.{name}')) is not None:
            randoms[name] = dist
        else:
            fixed[name] = value
    if randoms and 'draws' not in block:
        raise StudyError(f'{where}: draws: K is needed with distributions ({", ".join(randoms)})')
    result = []
    names = list(axes)
    for d in range(draws):
        rng = np.random.default_rng([seed, number, d])
        drawn = {name: _draw(rng, *randoms[name]) for name in sorted(randoms)}
        for values in itertools.product(*(axes[name] for name in names)):
            params = {**fixed, **drawn, **dict(zip(names, values))}
            params.setdefault('seed', d)
            result.append(_normalise(params, where))
    return result


def case_key(params: dict[str, Any]) -> str:
    """16 hex digits of the SHA-256 of the parameters' canonical JSON (LATE_PARAMETERS at their
    default left out)."""
    keyed = {
        k: v
        for k, v in params.items()
        if not (k in LATE_PARAMETERS and (v is None or v == PARAMETERS[k].default))
    }
    text = json.dumps(keyed, sort_keys=True, allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def build_study(spec: dict[str, Any], *, text: str | None = None) -> Study:
    """Expand a SPEC dictionary into its cases; StudyError names the first broken rule."""
    if not isinstance(spec, dict):
        raise StudyError(f'a SPEC is a mapping with keys {", ".join(TOP_KEYS)}, got {short_repr(spec)}')
    unknown = sorted(set(spec) - set(TOP_KEYS))
    if unknown:
        raise StudyError(f'unknown key {unknown[0]!r} (a SPEC has {", ".join(TOP_KEYS)})')
    name = spec.get('name', 'study')
    if not isinstance(name, str) or not name:
        raise StudyError(f'name: must be a non-empty string, got {short_repr(name)}')
    seed = spec.get('seed', 0)
    if not (_is_int(seed) and seed >= 0):
        raise StudyError(f'seed: must be an integer >= 0, got {short_repr(seed)}')
    defaults = spec.get('defaults', {})
    if not isinstance(defaults, dict):
        raise StudyError(f'defaults: must be a mapping of parameters, got {short_repr(defaults)}')
    bad = sorted(set(defaults) - set(PARAMETERS))
    if bad:
        raise StudyError(f'defaults: unknown key {bad[0]!r} (parameters: {", ".join(PARAMETERS)})')
    blocks = spec.get('cases')
    if not isinstance(blocks, list) or not blocks:
        raise StudyError(f'cases: must be a non-empty list of blocks, got {short_repr(blocks)}')
    cases, seen = [], set()
    for number, block in enumerate(blocks):
        for params in _block_cases(block, defaults, seed, number):
            key = case_key(params)
            if key not in seen:  # the same case twice (a grid over period with event sampling): once
                seen.add(key)
                cases.append(Case(index=len(cases), key=key, block=number, params=params))
    digest = hashlib.sha256(''.join(c.key for c in cases).encode()).hexdigest()[:16]
    return Study(
        name=name,
        cases=tuple(cases),
        digest=digest,
        text=text if text is not None else json.dumps(spec, sort_keys=True),
    )


def load_study(path: str | Path) -> Study:
    """Read and expand a SPEC file (YAML)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as error:
        raise StudyError(f'cannot read the SPEC {path}: {error.strerror or error}') from None
    try:
        spec = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise StudyError(f'{path}: not YAML: {error}') from None
    try:
        return build_study(spec, text=text)
    except StudyError as error:
        raise StudyError(f'{path}: {error}') from None
