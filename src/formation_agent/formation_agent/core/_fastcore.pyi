# The compiled core's interface (_fastcore.c, docs/COMPILED_CORE.md), for the type checker: the C
# extension has no Python source. formation_agent.core.compiled is its only user.
from collections.abc import Callable

from formation_agent.core.crossing import CrossingSearch

def configure(
    *,
    growth: float,
    max_steps: int,
    rtol: float,
    gap_fraction: float,
    series_limit: float,
    series: tuple[float, ...],
    raiser: Callable[[object, tuple[object, ...]], None],
) -> None: ...
def advance(search: CrossingSearch, until: float, /) -> float | None: ...
