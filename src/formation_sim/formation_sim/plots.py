"""Figures of a run in the style of the paper's Fig. 1 and Fig. 2.

(a) trajectories, circles at the initial positions and the final formation drawn over its edges;
(b) the triggering times of each agent as an event raster.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

FIGURE_FILE = 'formation.png'


def _pyplot():
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    return plt


def plot_run(record, out_dir, *, title: str | None = None) -> Path:
    """Write the two-panel figure of `record` into `out_dir`; return its path."""
    plt = _pyplot()
    scenario = record.scenario
    ids = list(scenario.agent_ids)
    index = {agent: k for k, agent in enumerate(ids)}
    x = record.sample_positions
    fig, (ax_traj, ax_events) = plt.subplots(2, 1, figsize=(7.0, 9.0), gridspec_kw={'height_ratios': [3, 2]})
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
        ax_traj.set_title('(a) trajectories; o initial positions; final formation in black')
    else:
        ax_traj.set_xlabel('t [s]')
        ax_traj.set_ylabel('x')
        ax_traj.set_title('(a) positions over time')
    if len(ids) <= 12:
        ax_traj.legend(loc='best', fontsize=8)
    for agent in ids:
        times = np.asarray(record.trigger_times[agent])
        k = index[agent]
        ax_events.vlines(times, k + 0.6, k + 1.4, color=colours[k % len(colours)], lw=0.6)
    ax_events.set_yticks(range(1, len(ids) + 1) if len(ids) <= 30 else [])
    if len(ids) <= 30:
        ax_events.set_yticklabels([str(a) for a in ids])
    ax_events.set_xlim(0.0, record.horizon)
    ax_events.set_xlabel('t [s]')
    ax_events.set_ylabel('agent')
    ax_events.set_title(f'(b) triggering times ({record.total_events} events)')
    fig.suptitle(title or f'{scenario.name}: {record.mode}')
    fig.tight_layout()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / FIGURE_FILE
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
