"""Figures of a run in the style of the paper's Fig. 1 and Fig. 2.

(a) trajectories, circles at the initial positions and the final formation drawn over its edges;
(b) the triggering times of each agent as an event raster. A continuous-controller run has no
triggering times, so its figure is panel (a) alone.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

FIGURE_FILE = 'formation.png'


def _pyplot():
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    return plt


def run_figure(record, *, title: str | None = None) -> Figure:
    """The figure of `record`: trajectories and, unless the run is continuous, its event raster."""
    plt = _pyplot()
    scenario = record.scenario
    ids = list(scenario.agent_ids)
    index = {agent: k for k, agent in enumerate(ids)}
    x = record.sample_positions
    events = record.mode != 'continuous'  # the continuous controller never triggers
    if events:
        fig, (ax_traj, ax_events) = plt.subplots(2, 1, figsize=(7.0, 9.0), gridspec_kw={'height_ratios': [3, 2]})
    else:
        # An empty raster would only say "no events" in a whole panel: the title says it instead.
        fig, ax_traj = plt.subplots(1, 1, figsize=(7.0, 5.6))
    colours = plt.rcParams['axes.prop_cycle'].by_key()['color']
    planar = x.shape[2] >= 2
    for agent in ids:
        k = index[agent]
        colour = colours[k % len(colours)]
        if planar:
            ax_traj.plot(x[:, k, 0], x[:, k, 1], color=colour, lw=1.2, label=f'agent {agent}')
            ax_traj.plot(x[0, k, 0], x[0, k, 1], 'o', mfc='none', mec=colour, ms=9)
        else:
            ax_traj.plot(record.sample_times, x[:, k, 0], color=colour, lw=1.2, label=f'agent {agent}')
    if planar:
        for edge in scenario.edges:
            a, b = index[edge.i], index[edge.j]
            ax_traj.plot(x[-1, [a, b], 0], x[-1, [a, b], 1], 'k-', lw=0.8)
        ax_traj.set_xlabel('x_1')
        ax_traj.set_ylabel('x_2')
        ax_traj.set_aspect('equal', adjustable='datalim')
        panel = 'trajectories; o initial positions; final formation in black'
    else:
        ax_traj.set_xlabel('t [s]')
        ax_traj.set_ylabel('x')
        panel = 'positions over time'
    ax_traj.set_title(f'(a) {panel}' if events else panel)
    if len(ids) <= 12:
        ax_traj.legend(loc='best', fontsize=8)
    heading = title or f'{scenario.name}: {record.mode}'
    if events:
        _draw_raster(ax_events, record, colours)
    else:
        heading += '\na continuous controller has no triggering events, hence no event raster'
    fig.suptitle(heading)
    fig.tight_layout()
    return fig


def _draw_raster(ax: Axes, record, colours: list[str]) -> None:
    """Panel (b): one row per agent, a tick at each of its triggering times."""
    ids = list(record.scenario.agent_ids)
    for k, agent in enumerate(ids):
        ax.vlines(np.asarray(record.trigger_times[agent]), k + 0.6, k + 1.4, color=colours[k % len(colours)], lw=0.6)
    ax.set_yticks(range(1, len(ids) + 1) if len(ids) <= 30 else [])
    if len(ids) <= 30:
        ax.set_yticklabels([str(a) for a in ids])
    ax.set_xlim(0.0, record.horizon)
    ax.set_xlabel('t [s]')
    ax.set_ylabel('agent')
    ax.set_title(f'(b) triggering times ({record.total_events} events)')


def plot_run(record, out_dir, *, title: str | None = None) -> Path:
    """Write the figure of `record` (see `run_figure`) into `out_dir`; return its path."""
    plt = _pyplot()
    fig = run_figure(record, title=title)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / FIGURE_FILE
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
