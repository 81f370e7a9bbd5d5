"""Which implementation runs the certified search of a plain-float agent: compiled or pure Python.

The compiled core (`formation_agent.core._fastcore`, C through the CPython API, built by setup.py
where a C compiler is present) runs `CrossingSearch.advance` for an ETA-1/ETA-2 agent of dimension
<= 3: the step loop, e_i and its bounds, the last step and the polish, with ETA-2's closed forms.
It computes the very floats of the pure-Python path (the same operations in the same order, the
same libm; docs/COMPILED_CORE.md), so the engine, an agent node and a robot agree bit for bit
whichever of them has it. The pure-Python path is used when the extension is missing (it was not
built) and when the environment variable FORMATION_PURE_PYTHON is 1 when this module is first
imported; `use_compiled` switches at run time (for tests and benchmarks: it applies to searches
made after the call).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

from formation_agent.core import crossing
from formation_agent.core.closed_form import _C as _SERIES
from formation_agent.core.closed_form import SERIES_LIMIT

ENVIRONMENT = 'FORMATION_PURE_PYTHON'
"""Set to 1 to force the pure-Python path."""

try:
    from formation_agent.core import _fastcore
except ImportError:  # not built (no compiler at install, or a plain copy of the sources)
    _fastcore = None  # type: ignore[assignment]  # the module or None: AVAILABLE says which

AVAILABLE = _fastcore is not None
"""True when the compiled core was built and imports."""


def _forced_pure() -> bool:
    value = os.environ.get(ENVIRONMENT, '')
    if value not in ('', '0', '1'):
        raise ValueError(f'{ENVIRONMENT} must be 0 or 1 (1: the pure-Python core), got {value!r}')
    return value == '1'


_active = AVAILABLE and not _forced_pure()


def configure(*, gap_fraction: float) -> None:
    """Hand the compiled core the search's constants from their one source: crossing.py, closed_form.py
    and eta.py's gap fraction (eta.py calls this once, at its import)."""
    if _fastcore is not None:
        _fastcore.configure(
            growth=crossing._GROWTH,
            max_steps=crossing.MAX_STEPS,
            rtol=crossing._RTOL,
            gap_fraction=gap_fraction,
            series_limit=SERIES_LIMIT,
            series=_SERIES,
            raiser=_raise,
        )


def active() -> bool:
    """True when new searches run compiled."""
    return _active


def use_compiled(on: bool) -> bool:
    """Run new searches compiled (True) or in pure Python (False); returns the previous choice.

    Asking for the compiled core where it was not built is an error that says so.
    """
    global _active
    if on and not AVAILABLE:
        raise RuntimeError(
            'the compiled core formation_agent.core._fastcore is not built (reinstall formation_agent '
            'with a C compiler and the Python headers: `make venv` or `colcon build`)'
        )
    previous, _active = _active, bool(on)
    return previous


def implementation() -> str:
    """'compiled' or 'python': what new searches run."""
    return 'compiled' if _active else 'python'


def kernel() -> Callable[[crossing.CrossingSearch, float], float | None] | None:
    """The compiled advance(search, until) for a plain-float agent, or None for the pure-Python path."""
    return _fastcore.advance if _active else None


def _raise(model: Any, problem: tuple[Any, ...]) -> None:  # model: the agent's error model
    """The error the pure-Python path raises at this point, in its words (the compiled core calls it)."""
    what = problem[0]
    if what == 'range':
        _, k, r, c = problem
        raise model._hood.out_of_range(k, r, c)
    if what == 'steps':
        raise crossing.steps_error(problem[1])
    raise crossing.finite_error(*problem[1:])
