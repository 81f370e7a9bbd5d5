"""The benchmark cases: scenarios by name, so that a separate process can rebuild them exactly."""

from __future__ import annotations


def build_scenario(case: dict):
    """`case` = {'kind': 'builtin', 'name': ...} or {'kind': 'random', 'n', 'seed', 'dynamics'}
    (`formation_sim.model.generate.random_scenario` defaults otherwise), optionally 'beta' to replace
    a single-integrator scenario's β (the long runs)."""
    from formation_sim.model.generate import random_scenario
    from formation_sim.model.scenario import SingleGains, load_scenario

    if case['kind'] == 'builtin':
        scenario = load_scenario(case['name'])
    else:
        scenario = random_scenario(n=case['n'], seed=case['seed'], dynamics=case['dynamics'])
    if 'beta' in case:
        scenario = scenario.replace(
            gains=SingleGains(alpha=scenario.gains.alpha, beta=case['beta']),
            name=f'{scenario.name}_beta{case["beta"]:g}',
        )
    return scenario


def label(case: dict) -> str:
    if case['kind'] == 'builtin':
        base = case['name']
    else:
        base = f'random {"ETA-1" if case["dynamics"] == "single" else "ETA-2"} n={case["n"]}'
    return base + (f' (β={case["beta"]:g})' if 'beta' in case else '')


def builtin(name: str, **extra) -> dict:
    return {'kind': 'builtin', 'name': name, **extra}


def random(n: int, dynamics: str = 'single', seed: int = 1, **extra) -> dict:
    return {'kind': 'random', 'n': n, 'seed': seed, 'dynamics': dynamics, **extra}
