"""Check a scenario against the hypotheses of Theorems 1 and 2 and report every number involved.

Rules (the `rule` of each finding):

connected     the graph is connected (Theorems 1, 2)                                   error
feasible      Φ is non-empty: least-squares residual of τ_i - τ_j = d_ij ~ 0 (Assumption 1)  error
edge_length   ||d_ij|| < Δ on every edge (Assumption 1)                                error
initial       ||x_i(0) - x_j(0) - d_ij|| < Δ - ||d_ij|| (initial)                      error;
              warning when the slack is below 5 % of Δ - ||d_ij||
precision     double precision resolves the initial slack: one ulp of x_i - x_j - d_ij    error
              moves the triggering error by at most PRECISION_LIMIT of the threshold
              (`_check_precision` derives it)
alpha         α > 0 (Theorem 1)                                                         error
beta          0 < β < β0 = ρ2(DD^T)/Δ0 (Theorem 1)                                       error;
              warning above 0.95 β0
rounding      β, β1, k3 or β_d above its computed bound (β0, 4/(k2+sqrt(k1²+k2²)), the    warning
              rates) by at most gains.ROUNDING_ULPS ulps of it: the bound's rounding, so the
              gain is taken as equal to it and accepted (`gains.against_bound`)
remark        β (or β1) above 4/(n(n-1)Δ) (Remark 3.2): agents cannot certify it alone  warning
alpha_d       α_d > 0 (Theorem 2)                                                       error
beta1         0 < β1 <= β0 (riccatti)                                                   error
k1_k2         k1, k2 > 0 (riccatti)                                                     error
riccati       P > 0 and ½(PC+C^T P) - β1 PBB^T P + 2I <= 0 (riccatti)                    error
k3            0 < k3 < 4/(k2 + sqrt(k1²+k2²)), i.e. k4 < 2 (Theorem 2)                   error;
              warning above 0.95 of the bound
beta_d        0 < β_d < (2-k4) ρ2(P) as printed in Theorem 2                            error;
              warning above 0.95 of the bound
beta_d_corrected  β_d < (2-k4)/λmax(P), what the proof supports (docs/THEOREM2.md)     warning
scale         Δ <= LENGTH_MAX, and every capacity Δ - ||d_ij|| and positive initial slack    error
              >= LENGTH_MIN: the certified search divides by fourth powers of the distance
              to Δ, which must stay normal doubles (`_check_scale`); the other rules are
              not evaluated then (their numbers would be overflow or underflow)
speed_scale   κ != 1: the paper's run in s = κt; the rates and times it implies, in seconds  note
threshold_floor  c0 > 0 (docs/SPEED_SCALE.md): ETA-1 c0 < β0 min(Δ-||d_ij||) sqrt(2/n)    error;
              ETA-2 the ultimate ball 2 sqrt(n c0²/(8 β1 γ λmin(P))) within min(Δ-||d_ij||)  error,
              and 2 sqrt(sup V_d/λmin(P)) below it, without which connectivity is only      warning
              checked on runs (formation_sim.model.threshold_floor)
trigger_rule  another rule than the exponential one (formation_agent.core.trigger): the   warning
              run is certified against it, but Theorems 1 and 2 are proven for c0 + α e^{-βt}
              only, so none of their guarantees (and none of the checks above) covers it
parameters    Δ, the horizon, the agents' gains and every d_ij are 0 or normal doubles     error
              (|x| >= 2.2e-308): agents receive them as ROS parameters, and rcl's parameter
              file parser reads a subnormal number as text (the agent then cannot start)

Notes (informational findings) carry the graph quantities, the feasibility residual, the slack of
every edge and the Riccati solution.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from formation_agent.core.crossing import DEFAULT_TOLERANCE, MAX_STEPS
from formation_agent.core.eta import ALGORITHM_GAINS, SCALE_GAINS
from formation_agent.core.trigger import DEFAULT_RULE, ExponentialRule, rule_factory
from formation_msgs_py.errors import FormationError
from formation_sim.model import theory
from formation_sim.model.errors import TheoryError
from formation_sim.model.gains import (
    OUTSIDE,
    ROUNDING,
    ROUNDING_ULPS,
    against_bound,
    k3_upper_bound,
    k4_value,
    riccati_holds,
    riccati_lhs,
    ulps_above,
)
from formation_sim.model.scenario import Scenario
from formation_sim.model.threshold_floor import floor_bounds

NEAR_EDGE_FRACTION = 0.95  # warn when a gain is above this fraction of its bound
SLACK_WARNING_FRACTION = 0.05  # warn when (initial) holds with less than this relative slack
SLACK_LINES = 20  # per-edge slack lines printed by `format` (all are in to_dict)
# The largest step of the rounded triggering error, relative to the threshold, that the certified
# search gets through (see `_check_precision`): its tolerance times its steps, with a factor 2 to spare.
PRECISION_LIMIT = DEFAULT_TOLERANCE * MAX_STEPS / 4.0
# The range of lengths the engine computes in: its certified bounds take fourth powers of the
# distance to Δ (formation_agent.core.eta, `_fast_bounds`: g_ij/gap³, the curvature /gap⁴), and
# 2^±250 keeps a fourth power within normal doubles (2^±1022) with 2^±20 to spare for a run whose
# edges come closer to Δ than at t = 0.
LENGTH_MIN = 2.0**-250
LENGTH_MAX = 2.0**250


class ValidationError(FormationError, ValueError):
    """A scenario that breaks a hypothesis of the paper; `report` holds all findings."""

    def __init__(self, report: ValidationReport) -> None:
        self.report = report
        first = report.errors[0]
        more = f' (and {len(report.errors) - 1} more errors)' if len(report.errors) > 1 else ''
        super().__init__(
            f'scenario {report.scenario!r} is invalid: [{first.rule}] {first.subject}: {first.message}{more}'
        )


@dataclass(frozen=True, kw_only=True)
class Finding:
    rule: str
    subject: str  # 'graph', 'formation', 'edge (i, j)', 'gains', ...
    message: str  # human text with the numbers
    values: dict[str, Any] = field(default_factory=dict)  # the numbers, JSON-friendly

    def to_dict(self) -> dict[str, Any]:
        return {
            'rule': self.rule,
            'subject': self.subject,
            'message': self.message,
            'values': _json_safe(self.values),
        }

    def format(self) -> str:
        return f'[{self.rule}] {self.subject}: {self.message}'


@dataclass(kw_only=True)
class ValidationReport:
    scenario: str
    dynamics: str
    errors: list[Finding] = field(default_factory=list)
    warnings: list[Finding] = field(default_factory=list)
    notes: list[Finding] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.errors

    def to_dict(self) -> dict[str, Any]:
        return {
            'scenario': self.scenario,
            'dynamics': self.dynamics,
            'ok': self.ok,
            'errors': [f.to_dict() for f in self.errors],
            'warnings': [f.to_dict() for f in self.warnings],
            'notes': [f.to_dict() for f in self.notes],
        }

    def format(self) -> str:
        verdict = 'VALID' if self.ok else 'INVALID'
        lines = [
            f'scenario {self.scenario!r} ({self.dynamics} integrators): {verdict}, '
            f'{len(self.errors)} error(s), {len(self.warnings)} warning(s)'
        ]
        for note in self.notes:
            lines.append(f'  {note.subject}: {note.message}')
            if note.rule == 'initial' and 'edges' in note.values:
                lines.extend(_slack_lines(note.values['edges']))
        for title, findings in (('errors', self.errors), ('warnings', self.warnings)):
            if findings:
                lines.append(f'{title}:')
                lines.extend(f'  {finding.format()}' for finding in findings)
        return '\n'.join(lines)


def _json_safe(value: Any) -> Any:
    """Plain JSON types; non-finite floats (e.g. the relative slack of a zero capacity) become None."""
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def _slack_lines(edges: list[dict[str, Any]]) -> list[str]:
    shown = sorted(edges, key=lambda e: e['relative_slack'])[:SLACK_LINES]
    lines = [
        f'    edge ({e["i"]}, {e["j"]}): ||d_ij|| = {_g(e["d_norm"])}, Δ-||d_ij|| = {_g(e["capacity"])}, '
        f'||x_i(0)-x_j(0)-d_ij|| = {_g(e["error"])}, slack {_g(e["slack"])} '
        f'({100.0 * e["relative_slack"]:.1f} %)'
        for e in shown
    ]
    if len(edges) > len(shown):
        lines.append(f'    ... {len(edges) - len(shown)} more edges with larger slack (see --json)')
    return lines


def _g(value: float) -> str:
    return f'{value:.6g}'


def _apart(a: float, b: float) -> tuple[str, str]:
    """a and b to 6 significant digits, or to as many more as it takes to print different numbers
    differently (a strict inequality broken by 3.0000001 >= 3 must not read "3 is not below 3")."""
    for digits in range(6, 18):
        left, right = f'{a:.{digits}g}', f'{b:.{digits}g}'
        if left != right or a == b:
            return left, right
    return repr(a), repr(b)  # pragma: no cover - 17 digits tell any two doubles apart


def _rounding(out: _Collector, name: str, value: float, bound_name: str, bound: float) -> None:
    """The warning for a gain accepted because it exceeds its computed bound by rounding only."""
    out.warning(
        'rounding',
        'gains',
        f'{name} = {value!r} is {ulps_above(value, bound)} ulp(s) above {bound_name} = {bound!r}, within '
        f'the rounding margin of {ROUNDING_ULPS} ulps of a computed bound: taken as equal to it',
        value=value,
        bound=bound,
        margin_ulps=ROUNDING_ULPS,
    )


def _edge(edge) -> str:
    return f'edge ({edge.i}, {edge.j})'


class _Collector:
    def __init__(self, report: ValidationReport) -> None:
        self.report = report

    def error(self, rule: str, subject: str, message: str, **values: Any) -> None:
        self.report.errors.append(Finding(rule=rule, subject=subject, message=message, values=values))

    def warning(self, rule: str, subject: str, message: str, **values: Any) -> None:
        self.report.warnings.append(Finding(rule=rule, subject=subject, message=message, values=values))

    def note(self, rule: str, subject: str, message: str, **values: Any) -> None:
        self.report.notes.append(Finding(rule=rule, subject=subject, message=message, values=values))


def validate_scenario(scenario: Scenario) -> ValidationReport:
    """Every hypothesis of the theorem for `scenario.dynamics`, with the numbers."""
    report = ValidationReport(scenario=scenario.name, dynamics=scenario.dynamics)
    out = _Collector(report)
    connected = _check_graph(scenario, out)

    with np.errstate(over='ignore', invalid='ignore'):  # out-of-range lengths: `_check_scale` says so
        capacities = theory.edge_capacities(scenario)
        errors0 = theory.edge_errors(scenario, scenario.positions)
    if not _check_scale(scenario, out, capacities, capacities - errors0):
        return report  # every number below would be computed outside double precision's range

    _check_feasible(scenario, out)
    _check_initial(scenario, out, capacities, errors0)
    _check_precision(scenario, out, capacities, errors0)
    beta0 = _beta0(scenario, out, connected=connected, capacities=capacities)
    if scenario.dynamics == 'single':
        _check_single(scenario, out, beta0)
    else:
        _check_double(scenario, out, beta0)
    _check_speed_scale(scenario, out, beta0)
    if report.ok:
        _check_threshold_floor(scenario, out)
    _check_trigger_rule(scenario, out)
    _check_parameters(scenario, out)
    return report


def _check_trigger_rule(scenario: Scenario, out: _Collector) -> None:
    """A warning for a rule the theorems do not cover (formation_agent.core.trigger)."""
    if rule_factory(scenario.trigger_rule) is not ExponentialRule:  # the scenario checked the name
        out.warning(
            'trigger_rule',
            'gains',
            f'trigger_rule {scenario.trigger_rule!r}: Theorems 1 and 2 are proven for the threshold '
            f'c0 + alpha e^(-beta t) ({DEFAULT_RULE!r}) only; the run is certified against this rule, '
            'but no guarantee of the theorems, nor any check above, covers it',
            trigger_rule=scenario.trigger_rule,
        )


def _check_graph(scenario: Scenario, out: _Collector) -> bool:
    """The graph's size and whether it is connected (an error when not); whether it is."""
    n, m = scenario.n, len(scenario.edges)
    components = theory.graph_components(scenario)
    connected = len(components) == 1
    out.note(
        'connected',
        'graph',
        f'{n} agents, {m} edges, p = {scenario.dimension}, Δ = {_g(scenario.delta)}, '
        + ('connected' if connected else f'{len(components)} components'),
        n=n,
        m=m,
        components=len(components),
    )
    if not connected:
        sizes = [len(c) for c in components]
        stray = components[1]
        out.error(
            'connected',
            'graph',
            f'the graph has {len(components)} connected components (sizes {sizes[:10]}); '
            f'e.g. agent {stray[0]} has no path to agent {components[0][0]}',
            component_sizes=sizes,
            components=[list(c) for c in components[:10]],
        )
    return connected


def _check_feasible(scenario: Scenario, out: _Collector) -> None:
    """Assumption 1: some τ has τ_i - τ_j = d_ij on every edge (least squares, with its residual)."""
    m = len(scenario.edges)
    feasibility = theory.formation_feasibility(scenario)
    worst = int(np.argmax(feasibility.edge_residuals)) if m else None
    if feasibility.feasible:
        out.note(
            'feasible',
            'formation',
            f'feasible: least-squares residual max ||τ_i-τ_j-d_ij|| = {_g(feasibility.residual)} '
            f'(tolerance {_g(feasibility.tolerance)})',
            residual=feasibility.residual,
            tolerance=feasibility.tolerance,
        )
    else:
        edge = scenario.edges[worst]
        out.error(
            'feasible',
            'formation',
            f'no τ with τ_i - τ_j = d_ij on every edge (Assumption 1): least-squares residual '
            f'{_g(feasibility.residual)} on {_edge(edge)} exceeds {_g(feasibility.tolerance)}; '
            f'the d_ij around some cycle do not sum to 0',
            residual=feasibility.residual,
            tolerance=feasibility.tolerance,
            worst_edge=[edge.i, edge.j],
        )


def _check_initial(scenario: Scenario, out: _Collector, capacities: np.ndarray, errors0: np.ndarray) -> None:
    """Per edge: ||d_ij|| < Δ (Assumption 1) and (initial), with each edge's slack."""
    slack_rows = []
    for k, edge in enumerate(scenario.edges):
        d_norm = float(np.linalg.norm(edge.d))
        capacity, error = float(capacities[k]), float(errors0[k])
        slack = capacity - error
        relative = slack / capacity if capacity > 0.0 else -math.inf
        slack_rows.append(
            dict(
                i=edge.i,
                j=edge.j,
                d_norm=d_norm,
                capacity=capacity,
                error=error,
                slack=slack,
                relative_slack=relative,
            )
        )
        if not capacity > 0.0:
            shown_norm, shown_delta = _apart(d_norm, scenario.delta)
            out.error(
                'edge_length',
                _edge(edge),
                f'||d_ij|| = {shown_norm} is not below Δ = {shown_delta} (Assumption 1)',
                d_norm=d_norm,
                delta=scenario.delta,
            )
        if not error < capacity:
            shown_error, shown_capacity = _apart(error, capacity)
            out.error(
                'initial',
                _edge(edge),
                f'||x_i(0)-x_j(0)-d_ij|| = {shown_error} is not below Δ-||d_ij|| = {shown_capacity} '
                f'(initial)',
                error=error,
                capacity=capacity,
            )
        elif relative < SLACK_WARNING_FRACTION:
            out.warning(
                'initial',
                _edge(edge),
                f'(initial) holds with slack Δ-||d_ij||-||x_i(0)-x_j(0)-d_ij|| = {_g(slack)}, only '
                f'{100.0 * relative:.1f} % of Δ-||d_ij|| = {_g(capacity)} (below '
                f'{100.0 * SLACK_WARNING_FRACTION:.0f} %)',
                slack=slack,
                capacity=capacity,
                relative_slack=relative,
            )
    if slack_rows:
        least = min(slack_rows, key=lambda row: row['relative_slack'])
        out.note(
            'initial',
            'initial condition',
            f'(initial) slack per edge, least {_g(least["slack"])} '
            f'({100.0 * least["relative_slack"]:.1f} %) on edge ({least["i"]}, {least["j"]})',
            edges=slack_rows,
        )


def _beta0(scenario: Scenario, out: _Collector, *, connected: bool, capacities: np.ndarray) -> float | None:
    """β0 = ρ2(DD^T)/Δ0 with its note (None when the graph is not connected or has no capacity)."""
    beta0 = None
    if connected and capacities.size and capacities.max() > 0.0:
        lam2 = theory.algebraic_connectivity(scenario)
        delta0 = float(capacities.max())
        beta0 = lam2 / delta0
        remark = theory.remark_beta_bound(scenario)
        out.note(
            'beta',
            'graph',
            f'ρ2(DD^T) = {_g(lam2)}, Δ0 = max(Δ-||d_ij||) = {_g(delta0)}, β0 = ρ2/Δ0 = {_g(beta0)}; '
            f'Remark 3.2 bound 4/(n(n-1)Δ) = {_g(remark)}',
            rho2=lam2,
            delta0=delta0,
            beta0=beta0,
            remark_bound=remark,
        )
    return beta0


def _check_speed_scale(scenario: Scenario, out: _Collector, beta0: float | None) -> None:
    """κ changes none of the hypotheses (they are the paper's, in s = κt): a note with the real-time
    numbers."""
    kappa = scenario.speed_scale
    if kappa == 1.0:
        return
    gains = scenario.gains
    name, rate = ('β', gains.beta) if scenario.dynamics == 'single' else ('β_d', gains.beta_d)
    line = (
        f"speed scale κ = {_g(kappa)}: the paper's run in s = κt, every triggering time (and ξ_i) "
        'divided by κ, '
        f'commands × κ'
        + (
            ''
            if scenario.dynamics == 'single'
            else ' (accelerations × κ², gains κ²k1, κk2, κk3, q(0) → κ q(0))'
        )
        + f'; the threshold decays at κ{name} = {_g(kappa * rate)} per second'
        + ('' if beta0 is None else f', β0 in real time κβ0 = {_g(kappa * beta0)}')
    )
    out.note(
        'speed_scale',
        'gains',
        line,
        speed_scale=kappa,
        rate=kappa * rate,
        beta0=None if beta0 is None else kappa * beta0,
    )


def _check_threshold_floor(scenario: Scenario, out: _Collector) -> None:
    """The floor's connectivity condition (formation_sim.model.threshold_floor, docs/SPEED_SCALE.md)."""
    c0 = scenario.gains.threshold_floor
    if c0 == 0.0:
        return
    try:
        floor = floor_bounds(scenario)
    except TheoryError:
        return  # a hypothesis the rules above report
    if floor.theorem == 1 and not floor.proven:
        out.error(
            'threshold_floor',
            'gains',
            f'threshold floor c0 = {_g(c0)} breaks {floor.condition}: connectivity is not guaranteed',
            threshold_floor=c0,
            limit=floor.limit,
        )
        return
    c_min = floor.limit if floor.theorem == 2 else None
    if floor.theorem == 2 and not floor.ball < c_min:
        out.error(
            'threshold_floor',
            'gains',
            f'threshold floor c0 = {_g(c0)}: the ultimate ball 2 sqrt(n c0²/(8 β1 γ λmin(P))) = '
            f'{_g(floor.ball)} is not within min(Δ-||d_ij||) = {_g(c_min)}: even ultimately nothing '
            'keeps the edges in range',
            threshold_floor=c0,
            ball=floor.ball,
            limit=c_min,
        )
        return
    if not floor.proven:
        out.warning(
            'threshold_floor',
            'gains',
            f'threshold floor c0 = {_g(c0)}: connectivity is proven only if '
            f'{floor.condition.replace(" < ", " were below ")}; it is not, so connectivity is checked '
            'on runs only (docs/SPEED_SCALE.md)',
            threshold_floor=c0,
            value=floor.value,
            limit=floor.limit,
        )
    kappa = scenario.speed_scale
    xi = '' if floor.xi is None else f', inter-event times >= {_g(min(floor.xi.values()) / kappa)} s'
    out.note(
        'threshold_floor',
        'gains',
        f'threshold floor c0 = {_g(c0)}: V ultimately <= {_g(floor.ultimate)}, formation error ultimately <= '
        f'{_g(floor.ball)}{xi}' + (f' ({floor.condition})' if floor.proven else ''),
        **floor.to_dict(),
    )


def _check_scale(scenario: Scenario, out: _Collector, capacities: np.ndarray, slacks: np.ndarray) -> bool:
    """Refuse lengths the engine cannot compute with (rule `scale`); True when they are in range."""
    units = (
        'state the scenario in other length units (ETA-1 runs the same with lengths × s, β / s and '
        'time × s: ω_ij scales as 1/s, the commands not at all)'
    )
    found = False
    if scenario.delta > LENGTH_MAX:
        out.error(
            'scale',
            'scenario',
            f'Δ = {_g(scenario.delta)} is above {_g(LENGTH_MAX)} (2^250): squared lengths and the fourth '
            f"powers in the certified search's bounds overflow double precision; {units}",
            delta=scenario.delta,
            limit=LENGTH_MAX,
        )
        return False
    for k, edge in enumerate(scenario.edges):
        for name, value in (
            ('Δ-||d_ij||', capacities[k]),
            ('the initial slack Δ-||d_ij||-||x_i(0)-x_j(0)-d_ij||', slacks[k]),
        ):
            if 0.0 < value < LENGTH_MIN:
                out.error(
                    'scale',
                    _edge(edge),
                    f'{name} = {_g(float(value))} is below {_g(LENGTH_MIN)} (2^-250): the certified search '
                    f'divides by the fourth power of the distance to Δ, which underflows double precision '
                    f'there; {units}',
                    key=name,
                    value=float(value),
                    limit=LENGTH_MIN,
                )
                found = True
                break
    return not found


def _check_parameters(scenario: Scenario, out: _Collector) -> None:
    """Every number the agents receive as a ROS parameter (sim_node.agent_parameters) is 0 or normal."""
    smallest = sys.float_info.min  # rcl's parser (strtod) flags a subnormal result as out of range
    algorithm = 'eta1' if scenario.dynamics == 'single' else 'eta2'
    carried = [
        ('scenario', 'communication_radius', scenario.delta),
        ('scenario', 'horizon', scenario.horizon),
    ]
    carried += [
        ('gains', f'gains.{name}', getattr(scenario.gains, name))
        for name in (*ALGORITHM_GAINS[algorithm], *SCALE_GAINS)
    ]
    carried += [
        (_edge(edge), f'd[{k}]', float(value)) for edge in scenario.edges for k, value in enumerate(edge.d)
    ]
    for subject, key, value in carried:
        if value != 0.0 and abs(value) < smallest:
            out.error(
                'parameters',
                subject,
                f'{key} = {value!r} is a subnormal double (0 < |x| < {smallest!r}): agents receive it '
                'as a ROS '
                "parameter, and rcl's parameter file parser reads it as text, so the agent cannot "
                'start; use 0 '
                f'or a magnitude of at least {smallest!r}',
                key=key,
                value=value,
            )


def _check_precision(
    scenario: Scenario, out: _Collector, capacities: np.ndarray, errors0: np.ndarray
) -> None:
    """Refuse an initial slack below what double precision resolves (rule `precision`).

    Between events an agent predicts y_ij(t) = x_i - x_j - d_ij in closed form; rounded, the
    prediction moves in steps of one ulp of y_ij, and each such step moves the triggering error
    by ρ = g_ij ulp(y_ij) ((gij); for E_i of ETA-2 (k1 g_ij + k2 h_ij ||q_i - q_j||) ulp(y_ij) +
    k2 f_ij ulp(q_i - q_j); `theory.rounding_step`). Near the threshold the computed error then
    stands still for a while at some margin φ > tolerance, and the certified search walks such a
    plateau in steps of about φ/|φ'|: 2 ρ / (α φ) of them (threshold α or α_d), up to
    2 ρ / (α tolerance). It gives up after MAX_STEPS, so ρ <= α PRECISION_LIMIT = α tolerance
    MAX_STEPS / 4. With the slack σ = Δ - ||d_ij|| - ||y_ij(0)||, g_ij = 2c²/σ³,
    h_ij = (2c + σ)/σ³, f_ij = (c + σ)/σ² (c = Δ - ||d_ij||) grow as σ shrinks: the rule is a
    floor on the initial slack, reported with it.
    (Late in a run the threshold itself shrinks toward the rounding of the states: the engine's
    rounding floor, the same ρ with the ulp of the positions, stops the run there.)
    """
    gains = scenario.gains
    if scenario.dynamics == 'single':
        name, threshold, k1, k2 = 'α', gains.alpha, 1.0, 0.0
    else:
        name, threshold, k1, k2 = 'α_d', gains.alpha_d, gains.k1, gains.k2
    if not (threshold > 0.0 and k1 > 0.0 and k2 >= 0.0):
        return  # the gains' own rules report them
    error_step = _error_step(scenario, capacities, k1=k1, k2=k2)
    limit = PRECISION_LIMIT * threshold
    ulp_y = _ulp_y(scenario)
    for k, edge in enumerate(scenario.edges):
        capacity, slack = float(capacities[k]), float(capacities[k] - errors0[k])
        if not (capacity > 0.0 and slack > 0.0):
            continue  # edge_length or initial already refuses it
        step = error_step(k, slack)
        if step <= limit:
            continue
        floor = _least_slack(error_step, k, slack=slack, capacity=capacity, limit=limit)
        how = (
            'g_ij × ulp, (gij)'
            if k2 == 0.0
            else '(k1 g_ij + k2 h_ij ||q_i-q_j||) × ulp + k2 f_ij × ulp(q_i-q_j)'
        )
        out.error(
            'precision',
            _edge(edge),
            f'initial slack Δ-||d_ij||-||x_i(0)-x_j(0)-d_ij|| = {_g(slack)} is below {_g(floor)}, the least '
            f'double precision resolves on this edge: one ulp of x_i-x_j-d_ij ({_g(ulp_y[k])}) moves the '
            f'triggering error by {_g(step)} ({how}), {_g(step / threshold)} of the threshold {name} = '
            f'{_g(threshold)}, where the certified search resolves at most {_g(PRECISION_LIMIT)} of it '
            f'(tolerance {_g(DEFAULT_TOLERANCE)} × {MAX_STEPS} steps / 4)',
            slack=slack,
            floor=floor,
            ulp=float(ulp_y[k]),
            error_step=step,
            threshold=threshold,
            limit=PRECISION_LIMIT,
        )


def _ulp_y(scenario: Scenario) -> np.ndarray:
    """Per edge, one ulp of y_ij(0) = x_i(0) - x_j(0) - d_ij (its largest coordinate's)."""
    heads, tails, d = scenario.edge_indices()
    y = scenario.positions[heads] - scenario.positions[tails] - d
    return np.spacing(np.abs(y).max(axis=1))


def _error_step(
    scenario: Scenario, capacities: np.ndarray, *, k1: float, k2: float
) -> Callable[[int, float], float]:
    """(edge k, slack σ) -> how far one ulp of y_ij moves the triggering error at that slack
    (`theory.rounding_step`, with edge k's initial relative velocity)."""
    heads, tails, _ = scenario.edge_indices()
    ulp_y = _ulp_y(scenario)
    if scenario.velocities is None:
        speed = ulp_q = np.zeros(len(heads))
    else:  # the paper's q_p(0) and E_i: at a speed scale κ error and threshold are both × κ²
        # (docs/SPEED_SCALE.md)
        q = scenario.velocities[heads] - scenario.velocities[tails]
        speed, ulp_q = np.linalg.norm(q, axis=1), np.spacing(np.abs(q).max(axis=1))

    def error_step(k: int, sigma: float) -> float:
        return float(
            theory.rounding_step(
                float(capacities[k]),
                sigma,
                float(ulp_y[k]),
                k1=k1,
                k2=k2,
                speed=float(speed[k]),
                ulp_q=float(ulp_q[k]),
            )
        )

    return error_step


def _least_slack(
    error_step: Callable[[int, float], float], k: int, *, slack: float, capacity: float, limit: float
) -> float:
    """The least slack whose error step on edge k is within `limit`: the step falls with the slack,
    so bisect (geometrically) between `slack` (over it) and the capacity."""
    low, high = slack, capacity
    if error_step(k, high) > limit:
        return high
    for _ in range(100):
        middle = math.sqrt(low * high)
        low, high = (middle, high) if error_step(k, middle) > limit else (low, middle)
    return high


def _check_remark(scenario: Scenario, out: _Collector, name: str, value: float) -> None:
    remark = theory.remark_beta_bound(scenario)
    if value > remark:
        out.warning(
            'remark',
            'gains',
            f'{name} = {_g(value)} exceeds 4/(n(n-1)Δ) = {_g(remark)} (Remark 3.2): an agent that '
            f'knows only n and Δ cannot check {name} against β0 locally',
            value=value,
            remark_bound=remark,
        )


def _check_single(scenario: Scenario, out: _Collector, beta0: float | None) -> None:
    alpha, beta = scenario.gains.alpha, scenario.gains.beta
    if not alpha > 0.0:
        out.error('alpha', 'gains', f'α must be > 0, got α = {_g(alpha)}', alpha=alpha)
    if beta0 is None:
        return
    state = against_bound(beta, beta0, strict=True)
    if not beta > 0.0 or state == OUTSIDE:
        shown_beta, shown_beta0 = _apart(beta, beta0)
        out.error(
            'beta',
            'gains',
            f'0 < β < β0 = {shown_beta0} required, got β = {shown_beta}',
            beta=beta,
            beta0=beta0,
        )
    elif state == ROUNDING:
        _rounding(out, 'β', beta, 'β0', beta0)
    elif beta > NEAR_EDGE_FRACTION * beta0:
        out.warning(
            'beta',
            'gains',
            f'β = {_g(beta)} is {100.0 * beta / beta0:.1f} % of β0 = {_g(beta0)} '
            f'(above {100.0 * NEAR_EDGE_FRACTION:.0f} %)',
            beta=beta,
            beta0=beta0,
        )
    if beta > 0.0:
        _check_remark(scenario, out, 'β', beta)


def _check_double(scenario: Scenario, out: _Collector, beta0: float | None) -> None:
    gains = scenario.gains
    k1, k2, k3, beta1, beta_d = gains.k1, gains.k2, gains.k3, gains.beta1, gains.beta_d
    if not gains.alpha_d > 0.0:
        out.error(
            'alpha_d', 'gains', f'α_d must be > 0, got α_d = {_g(gains.alpha_d)}', alpha_d=gains.alpha_d
        )
    if beta0 is not None:
        state = against_bound(beta1, beta0, strict=False)
        if not beta1 > 0.0 or state == OUTSIDE:
            shown_beta1, shown_beta0 = _apart(beta1, beta0)
            out.error(
                'beta1',
                'gains',
                f'0 < β1 <= β0 = {shown_beta0} required, got β1 = {shown_beta1}',
                beta1=beta1,
                beta0=beta0,
            )
        elif state == ROUNDING:
            _rounding(out, 'β1', beta1, 'β0', beta0)
        if beta1 > 0.0:
            _check_remark(scenario, out, 'β1', beta1)

    rho2_p, lam_max_p = _check_riccati(out, gains, beta1)
    upper = k3_upper_bound(k1, k2) if k1 > 0.0 and k2 > 0.0 else math.nan
    k4 = k4_value(k1, k2, k3)
    state = against_bound(k3, upper, strict=True)
    if not k3 > 0.0 or state == OUTSIDE:
        shown_k3, shown_upper = _apart(k3, upper)
        out.error(
            'k3',
            'gains',
            f'0 < k3 < 4/(k2+sqrt(k1²+k2²)) = {shown_upper} required (k4 < 2), got k3 = {shown_k3}, '
            f'k4 = {_g(k4)}',
            k3=k3,
            k3_upper_bound=upper,
            k4=k4,
        )
        return
    if state == ROUNDING:
        _rounding(out, 'k3', k3, '4/(k2+sqrt(k1²+k2²))', upper)
    elif k3 > NEAR_EDGE_FRACTION * upper:
        out.warning(
            'k3',
            'gains',
            f'k3 = {_g(k3)} is {100.0 * k3 / upper:.1f} % of its bound {_g(upper)} (k4 = {_g(k4)})',
            k3=k3,
            k3_upper_bound=upper,
            k4=k4,
        )
    _check_beta_d(out, beta_d=beta_d, k4=k4, rho2_p=rho2_p, lam_max_p=lam_max_p)


def _check_riccati(out: _Collector, gains, beta1: float) -> tuple[float, float]:
    """P and k1, k2 > 0 against (riccatti) for this β1; P's eigenvalues ρ2(P), λmax(P)."""
    k1, k2 = gains.k1, gains.k2
    eigenvalues = np.linalg.eigvalsh(gains.P)
    rho2_p, lam_max_p = float(eigenvalues.min()), float(eigenvalues.max())
    lhs = riccati_lhs(gains.P, beta1)
    lhs_max = float(np.linalg.eigvalsh(lhs).max())
    out.note(
        'riccati',
        'gains',
        f'P = [[{_g(gains.k0)}, {_g(k1)}], [{_g(k1)}, {_g(k2)}]] (k1 = {_g(k1)}, k2 = {_g(k2)}), '
        f'eigenvalues ρ2(P) = {_g(rho2_p)}, λmax(P) = {_g(lam_max_p)}; largest eigenvalue of '
        f'½(PC+C^T P) - β1 PBB^T P + 2I = {_g(lhs_max)}',
        P=gains.P.tolist(),
        k1=k1,
        k2=k2,
        rho2_P=rho2_p,
        lambda_max_P=lam_max_p,
        riccati_max_eigenvalue=lhs_max,
    )
    if not (k1 > 0.0 and k2 > 0.0):
        out.error('k1_k2', 'gains', f'k1, k2 > 0 required, got k1 = {_g(k1)}, k2 = {_g(k2)}', k1=k1, k2=k2)
    if not riccati_holds(gains.P, beta1):
        out.error(
            'riccati',
            'gains',
            f'P > 0 with ½(PC+C^T P) - β1 PBB^T P + 2I <= 0 required (riccatti); eigenvalues of P '
            f'{_g(rho2_p)}, {_g(lam_max_p)}, largest eigenvalue of the left side {_g(lhs_max)} '
            f'for β1 = {_g(beta1)}',
            rho2_P=rho2_p,
            riccati_max_eigenvalue=lhs_max,
            beta1=beta1,
        )
    return rho2_p, lam_max_p


def _check_beta_d(out: _Collector, *, beta_d: float, k4: float, rho2_p: float, lam_max_p: float) -> None:
    """β_d against the printed bound (2-k4) ρ2(P) and against (2-k4)/λmax(P), which the proof supports."""
    bound_paper = (2.0 - k4) * rho2_p
    bound_corrected = (2.0 - k4) / lam_max_p
    out.note(
        'beta_d',
        'gains',
        f'k4 = {_g(k4)}; β_d bounds: (2-k4) ρ2(P) = {_g(bound_paper)} (as printed), '
        f'(2-k4)/λmax(P) = {_g(bound_corrected)} (what the proof supports)',
        k4=k4,
        beta_d_bound_paper=bound_paper,
        beta_d_bound_corrected=bound_corrected,
    )
    state = against_bound(beta_d, bound_paper, strict=True)
    if not beta_d > 0.0 or state == OUTSIDE:
        shown_beta_d, shown_bound = _apart(beta_d, bound_paper)
        out.error(
            'beta_d',
            'gains',
            f'0 < β_d < (2-k4) ρ2(P) = {shown_bound} required, got β_d = {shown_beta_d}',
            beta_d=beta_d,
            bound=bound_paper,
        )
        return
    if state == ROUNDING:
        _rounding(out, 'β_d', beta_d, '(2-k4) ρ2(P)', bound_paper)
    elif beta_d > NEAR_EDGE_FRACTION * bound_paper:
        out.warning(
            'beta_d',
            'gains',
            f'β_d = {_g(beta_d)} is {100.0 * beta_d / bound_paper:.1f} % of (2-k4) ρ2(P) = {_g(bound_paper)}',
            beta_d=beta_d,
            bound=bound_paper,
        )
    state = against_bound(beta_d, bound_corrected, strict=True)
    if state == ROUNDING:
        _rounding(out, 'β_d', beta_d, '(2-k4)/λmax(P)', bound_corrected)
    elif state == OUTSIDE:
        shown_beta_d, shown_bound = _apart(beta_d, bound_corrected)
        out.warning(
            'beta_d_corrected',
            'gains',
            f'β_d = {shown_beta_d} is not below (2-k4)/λmax(P) = {shown_bound}, the rate the '
            f'proof of Theorem 2 (ii) supports; the printed bound (2-k4) ρ2(P) = {_g(bound_paper)} '
            f'does not follow from it (docs/THEOREM2.md), so convergence at rate β_d is not '
            f'guaranteed',
            beta_d=beta_d,
            bound_corrected=bound_corrected,
            bound_paper=bound_paper,
        )


def require_valid(scenario: Scenario) -> ValidationReport:
    """The report of a valid scenario (warnings allowed); raises ValidationError otherwise."""
    report = validate_scenario(scenario)
    if not report.ok:
        raise ValidationError(report)
    return report
