# The compiled core's interface (_fastcore.c, docs/COMPILED_CORE.md), for the type checker: the C
# extension has no Python source. formation_agent.core.compiled is its only user.
from collections.abc import Callable, Iterable, Sequence
from typing import Any

from formation_agent.core.crossing import CrossingSearch
from formation_agent.core.eta import TriggerOutput
from formation_msgs_py.types import SensedState, TriggerInfo

def configure(
    *,
    growth: float,
    max_steps: int,
    rtol: float,
    gap_fraction: float,
    series_limit: float,
    series: tuple[float, ...],
    raiser: Callable[[Any, tuple[Any, ...]], None],
    array: Callable[..., Any],
    trigger_output: type,
    trigger_info: type,
    direct_output: bool,
    direct_info: bool,
) -> None: ...
def configure_world(
    *, expm1: Callable[[Any], Any], series: tuple[float, ...], series_limit: float
) -> None: ...
def advance(x: Any, q: Any, u: Any, x_out: Any, q_out: Any, k3: float, tau: float, /) -> bool: ...
def abs_max(array: Any, /) -> float | None: ...
def team_edges(
    agents: tuple[Any, ...], ids: tuple[int, ...], /
) -> tuple[tuple[tuple[int, ...], ...], tuple[tuple[int, ...], ...]] | None: ...
def watch_edges(
    x: Any, rows: list[int], start: Any, incident: Any, heads: Any, tails: Any, squared: Any, /
) -> bool: ...
def receive(agent: Any, info: TriggerInfo, /) -> bool: ...
def trigger(agent: Any, t: float, sensed: SensedState, /) -> TriggerOutput | None: ...

# CrossingSearch's twin: the same constructor, attributes and methods (not a subclass at run time)
class Search(CrossingSearch): ...

class Agenda:
    horizon: float
    failed: object | None
    from_team: int
    def __init__(
        self,
        *,
        agent_ids: Iterable[int],
        horizon: float,
        first_span: float = ...,
        plain: tuple[type, ...] = ...,
        rule: type = ...,
    ) -> None: ...
    def plan(self, agents: Any, changed: Sequence[int], /) -> None: ...
    def plan_union(self, agents: Any, due: list[int], receivers: list[int], /) -> None: ...
    def link(self, team: Team, /) -> None: ...
    def next_time(self) -> float: ...
    def pop_due(self, t: float, /) -> list[int]: ...

class Team:
    def __init__(
        self,
        *,
        agents: tuple[Any, ...],
        ids: tuple[int, ...],
        neighbours: tuple[tuple[int, ...], ...],
        back: tuple[tuple[int, ...], ...],
        dimension: int,
        set_control: Callable[[int, Any], None],
        plain: tuple[type, ...],
        rule: type,
    ) -> None: ...
    loads: int
    stores: int
    def trigger(self, due: list[int], start: int, t: float, x: Any, q: Any, u: Any, /) -> int: ...
    def deliver(self) -> list[int]: ...
    def release(self, *ids: int) -> None: ...
