"""Figures of a run in the style of the paper's Fig. 1 and Fig. 2.

(a) trajectories, circles at the initial positions and the final formation drawn over its edges;
(b) the triggering times of each agent as an event raster. A continuous-controller run has no
triggering times, so its figure is panel (a) alone.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FIGURE_FILE = 'formation.png'


def _pyplot():
    import matplotlib as mpl

    mpl.use('Agg')
    import matplotlib.pyplot as plt

    return plt


def run_figure(record, *, title: str | None = None) -> Figure:
    """The figure of `record`: trajectories and, unless the run is continuous, its event raster.

    The panels are those of `formation_sim.analysis.figures` (the paper's Fig. 1/2 layout), drawn for
    the command line's own figure size and titles.
    """
    from formation_sim.analysis.figures import plot_trajectories, plot_trigger_raster

    plt = _pyplot()
    scenario = record.scenario
    events = record.mode != 'continuous'  # the continuous controller never triggers
    if events:
        fig, (ax_traj, ax_events) = plt.subplots(
            2, 1, figsize=(7.0, 9.0), gridspec_kw={'height_ratios': [3, 2]}
        )
    else:
        # An empty raster would only say "no events" in a whole panel: the title says it instead.
        fig, ax_traj = plt.subplots(1, 1, figsize=(7.0, 5.6))
    trajectories = plot_trajectories(ax_traj, record)
    panel = (
        'trajectories; o initial positions; final formation in black'
        if trajectories.planar
        else 'positions over time'
    )
    ax_traj.set_title(f'(a) {panel}' if events else panel)
    if len(scenario.agent_ids) <= 12:
        ax_traj.legend(handles=trajectories.legend_handles(), loc='best', fontsize=8)
    heading = title or f'{scenario.name}: {record.mode}'
    if events:
        plot_trigger_raster(ax_events, record)
        ax_events.set_title(f'(b) triggering times ({record.total_events} events)')
    else:
        heading += '\na continuous controller has no triggering events, hence no event raster'
    fig.suptitle(heading)
    fig.tight_layout()
    return fig


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
