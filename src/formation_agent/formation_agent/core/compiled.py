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

import dataclasses
import os
from collections.abc import Callable
from typing import Any

import numpy as np

from formation_agent.core import crossing
from formation_agent.core.closed_form import _C as _SERIES
from formation_agent.core.closed_form import _SERIES as _WORLD_SERIES
from formation_agent.core.closed_form import SERIES_LIMIT
from formation_agent.core.trigger import ExponentialRule
from formation_msgs_py.types import SensedState, TriggerInfo

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

if _fastcore is not None:  # the world's step computes its factors as closed_form.advance_double does
    _fastcore.configure_world(expm1=np.expm1, series=_WORLD_SERIES, series_limit=SERIES_LIMIT)


def configure(*, gap_fraction: float, trigger_output: type) -> None:
    """Hand the compiled core the search's constants from their one source: crossing.py, closed_form.py
    and eta.py's gap fraction, and the types a trigger returns (eta.py calls this once, at its import)."""
    if _fastcore is not None:
        _fastcore.configure(
            growth=crossing._GROWTH,
            max_steps=crossing.MAX_STEPS,
            rtol=crossing._RTOL,
            gap_fraction=gap_fraction,
            series_limit=SERIES_LIMIT,
            series=_SERIES,
            raiser=_raise,
            array=np.array,
            trigger_output=trigger_output,
            trigger_info=TriggerInfo,
            direct_output=plain_record(trigger_output, ('time', 'control', 'infos')),
            direct_info=plain_record(
                TriggerInfo, ('sender', 'receiver', 'stamp', 'control', 'rel_position', 'rel_velocity')
            ),
        )


def plain_record(cls: type, fields: tuple[str, ...]) -> bool:
    """True when `cls(**values)` only stores `fields` (a slots dataclass of exactly these fields and no
    __post_init__): the compiled trigger then fills a new one field by field, as its frozen __init__
    does with object.__setattr__, instead of calling it."""
    return (
        dataclasses.is_dataclass(cls)
        and getattr(cls, '__slots__', None) == fields
        and tuple(f.name for f in dataclasses.fields(cls)) == fields
        and not hasattr(cls, '__post_init__')
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


def search_type(rule: object) -> Callable[..., crossing.CrossingSearch] | None:
    """The compiled twin of `crossing.CrossingSearch` for a plain-float agent triggering on `rule`
    (`_fastcore.Search`: the same floats, its state and the agent's packed rows held in C; it takes
    the exponential rule's floor, alpha and beta in place of the rule), or None for the pure-Python
    path: where the core was not built or is switched off, and for every rule but the exponential
    one (`trigger.ExponentialRule`, the only threshold written in C)."""
    return _fastcore.Search if _active and type(rule) is ExponentialRule else None


def receiver() -> Callable[[Any, TriggerInfo], bool] | None:
    """The compiled `receive(agent, info)` of a plain-float agent (True: taken; False: nothing changed,
    the agent's Python `receive` takes the message), or None for the pure-Python path."""
    return _fastcore.receive if _active else None


def trigger() -> Callable[[Any, float, SensedState], Any] | None:  # Any: eta's TriggerOutput or None
    """The compiled `trigger(agent, t, sensed)` of a plain-float agent without the safety layer (its
    TriggerOutput; None: nothing changed, the agent's Python `trigger` takes it), or None for the
    pure-Python path."""
    return _fastcore.trigger if _active else None


def agenda() -> type[_fastcore.Agenda] | None:
    """The compiled next-event queue of the in-process engine without a period (`_fastcore.Agenda`, the
    twin of formation_sim.sim.engine._Agenda's heap: the same order and times), or None for the
    pure-Python path."""
    return _fastcore.Agenda if _active else None


def team() -> type[_fastcore.Team] | None:
    """The compiled triggers and deliveries of the in-process engine at an event time (`_fastcore.Team`:
    sensing from the world's arrays, each due agent's trigger, its command into the world, the
    triggering information delivered; the agents' updates and floats those of `trigger` and `receive`,
    formation_sim.sim.engine._trigger_and_deliver), or None for the pure-Python path."""
    return _fastcore.Team if _active else None


def team_edges() -> Callable[[tuple[Any, ...], tuple[int, ...]], tuple[Any, Any] | None] | None:
    """The compiled `(neighbours, back)` of a `team()` over agents in the order of ids
    (`_fastcore.team_edges(agents, ids)`: each agent's neighbours by their position in ids and its slot among
    each neighbour's `neighbour_ids`; None where a neighbour does not list it back), or None for the
    pure-Python path."""
    return _fastcore.team_edges if _active else None


def world_step() -> Callable[..., bool] | None:
    """The compiled step of the in-process world (`_fastcore.advance(x, q, u, x_out, q_out, k3, tau)`:
    formation_sim.sim.world.World's closed form, single or double integrators with a scalar tau, the
    same floats as numpy's `x + tau * u` and `closed_form.advance_double`, written into x_out, q_out;
    False where an array is not a C-contiguous float64 one), or None for the pure-Python path."""
    return _fastcore.advance if _active else None


def edge_watch() -> Callable[..., bool] | None:
    """The compiled `EdgeLengths.add_edges` over the edges of some agent rows (`_fastcore.watch_edges(x,
    rows, start, incident, heads, tails, squared)`, formation_sim.sim.samples: the same floats; False
    where it cannot take the arrays), or None for the pure-Python path."""
    return _fastcore.watch_edges if _active else None


def abs_max() -> Callable[[Any], float | None] | None:
    """The compiled `float(numpy.abs(array).max())` (`_fastcore.abs_max`: None where the array is not a
    non-empty C-contiguous float64 one), or None for the pure-Python path."""
    return _fastcore.abs_max if _active else None


def _raise(model: Any, problem: tuple[Any, ...]) -> None:  # model: the agent's error model
    """The error the pure-Python path raises at this point, in its words (the compiled core calls it)."""
    what = problem[0]
    if what == 'range':
        _, k, r, c = problem
        raise model._hood.out_of_range(k, r, c)
    if what == 'steps':
        raise crossing.steps_error(problem[1])
    raise crossing.finite_error(*problem[1:])
