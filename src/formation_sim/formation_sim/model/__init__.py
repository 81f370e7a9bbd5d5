"""The problem, ROS-free: a scenario and the hypotheses and constants of Theorems 1 and 2.

- `scenario`: `Scenario` (agents, graph, desired displacements d_ij, Δ, gains, horizon), YAML in
  and out, the built-ins `paper_single` and `paper_double` (Section 5).
- `gains`: P from (riccatti), the range of k3, k4 and β_d (Theorem 2).
- `theory`: graph quantities (D, L, ρ2, β0), feasibility (Φ), ν, V, and the proofs' constants
  (k_ν, k_ij, k_V, c_i, ξ_i and their ETA-2 counterparts); `threshold_floor`: what a floor c0 > 0
  under the threshold still guarantees (docs/SPEED_SCALE.md).
- `validate`: every hypothesis of the theorems, with the numbers; `generate`: random valid teams.
"""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(
    globals(),
    {
        'scenario': (
            'DoubleGains',
            'Edge',
            'Scenario',
            'SingleGains',
            'builtin_scenarios',
            'dump_scenario',
            'dump_scenario_text',
            'load_scenario',
            'scenario_from_dict',
            'scenario_to_dict',
        ),
        'gains': ('paper_k3', 'riccati_solution'),
        'theory': ('TheoremConstants', 'beta0', 'formation_feasibility', 'theorem_constants'),
        'threshold_floor': ('FloorBounds', 'floor_bounds'),
        'validate': ('Finding', 'ValidationError', 'ValidationReport', 'require_valid', 'validate_scenario'),
        'generate': ('random_scenario',),
        'errors': ('GainsError', 'GenerateError', 'ScenarioError', 'TheoryError'),
    },
)
