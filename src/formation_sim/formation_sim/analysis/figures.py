"""Figures and the animation of a run (matplotlib, Agg backend).

Every plotting function draws into axes it is given and returns the artists it created, so
callers (and tests) can read back exactly what was drawn: the raster's event times, the
trajectory lines' end points, the bound curves.

- `paper_figure`: the paper's Fig. 1 / Fig. 2 layout: (a) trajectories, circles at the initial
  positions, the final formation's edges; (b) each agent's triggering times as an event raster.
- `plot_edge_lengths`: every ||x_i - x_j|| against Δ, and the room left to Δ on a log scale with
  the room the (kij) bounds guarantee, Δ - (k_ij + ||d_ij||).
- `plot_formation_error`: max_ij ||x_i - x_j - d_ij|| on a log scale, with e(0) e^{-βt} (the
  decay rate the theorem gives) and the bound 2 sqrt(k_V) e^{-βt} (lengthysV).
- `plot_inter_event_times`: the distribution of t_{k+1} - t_k per agent, with ξ_i (xi) marked.
- `plot_energy`: the tension ν (bound k_ν) and the Lyapunov function V (bound k_V e^{-2βt}).
- `animate`: a GIF of the run (PillowWriter), edges coloured as in the Foxglove markers.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from formation_sim.analysis.markers import agent_colour, edge_colour

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.collections import LineCollection, PathCollection
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    from formation_sim.analysis.checks import Series, TheoryBounds
    from formation_sim.sim.record import RunRecord


def pyplot():
    """matplotlib.pyplot on the Agg backend (files only, no display needed)."""
    import matplotlib as mpl

    mpl.use('Agg')
    import matplotlib.pyplot as plt

    return plt


def _colour(k: int) -> tuple[float, float, float, float]:
    return agent_colour(k)


# ------------------------------------------------------------------------------ (a) trajectories

FIGURE_POINTS = 400_000
"""Points of all agents' paths together that a figure draws at most. Each costs ~0.3 µs to draw
and at 110 dpi more show nothing more: a longer run of a large team is drawn through samples
evenly spaced in time (`figure_rows`), its first and last included."""


def figure_rows(times: np.ndarray, agents: int) -> np.ndarray:
    """Indices of the samples a figure draws: all, or evenly spaced in time up to FIGURE_POINTS points."""
    count = len(times)
    if count * agents <= FIGURE_POINTS:
        return np.arange(count)
    return np.unique(frame_indices(times, frames=max(2, FIGURE_POINTS // agents)))


@dataclass(frozen=True, kw_only=True)
class TrajectoryPlot:
    """What `plot_trajectories` drew: one collection per layer (one artist per agent costs ~1 ms
    each to create and draw: 3000 agents took 7 s)."""

    axes: Axes
    planar: bool  # True: x_2 against x_1; False (p = 1): x against t
    rows: np.ndarray  # the sample rows drawn (`figure_rows`)
    paths: LineCollection  # segment k: the path of the k-th agent
    starts: PathCollection  # offset k: the k-th agent's initial position (a circle)
    formation: LineCollection | None  # segment e: the e-th edge between the final positions
    labels: list[str]  # the k-th agent's name in a legend

    def legend_handles(self) -> list[Line2D]:
        """One legend entry per agent (made when asked: a legend of 1000 agents is never drawn)."""
        from matplotlib.lines import Line2D

        style, colours, width = (
            self.paths.get_linestyle(),
            self.paths.get_colors(),
            self.paths.get_linewidths(),
        )
        return [
            Line2D(
                [],
                [],
                linestyle=style[k % len(style)],
                color=colours[k],
                lw=width[k % len(width)],
                label=label,
            )
            for k, label in enumerate(self.labels)
        ]


def plot_trajectories(
    ax: Axes, record: RunRecord, *, linestyle: str = '-', label: str = '', formation: bool = True
) -> TrajectoryPlot:
    """Paths of all agents; with p >= 3 the first two coordinates (a projection)."""
    from matplotlib.collections import LineCollection

    scenario = record.scenario
    times = np.asarray(record.sample_times, dtype=float)
    rows = figure_rows(times, scenario.n)
    x = np.asarray(record.sample_positions[rows])  # only these rows are read from a trajectory on disk
    planar = x.shape[2] >= 2
    colours = [_colour(k) for k in range(scenario.n)]
    if planar:
        paths = np.moveaxis(x[:, :, :2], 1, 0)  # (n, rows, 2)
        first = x[0, :, :2]
    else:
        paths = np.stack([np.broadcast_to(times[rows], (scenario.n, len(rows))), x[:, :, 0].T], axis=-1)
        first = np.column_stack([np.full(scenario.n, times[0]), x[0, :, 0]])
    drawn = ax.add_collection(
        LineCollection(paths, colors=colours, linestyles=linestyle, linewidths=1.2), autolim=True
    )
    starts = ax.scatter(first[:, 0], first[:, 1], s=81, facecolors='none', edgecolors=colours, marker='o')
    polygon = None
    if planar and formation:
        heads, tails, _ = scenario.edge_indices()
        polygon = ax.add_collection(
            LineCollection(
                np.stack([x[-1, heads, :2], x[-1, tails, :2]], axis=1), colors='k', linewidths=0.9
            ),
            autolim=True,
        )
    ax.autoscale_view()
    if planar:
        ax.set_xlabel('$x_{i,1}$' + (' (projection)' if x.shape[2] > 2 else ''))
        ax.set_ylabel('$x_{i,2}$')
        ax.set_aspect('equal', adjustable='datalim')
    else:
        ax.set_xlabel('t [s]')
        ax.set_ylabel('$x_i$')
    labels = [f'agent {agent}{label}' for agent in scenario.agent_ids]
    return TrajectoryPlot(
        axes=ax, planar=planar, rows=rows, paths=drawn, starts=starts, formation=polygon, labels=labels
    )


# ---------------------------------------------------------------------------- (b) event raster


@dataclass(frozen=True, kw_only=True)
class RasterPlot:
    axes: Axes
    ticks: LineCollection  # one vertical tick per trigger, agent by agent
    spans: dict[int, slice]  # agent -> its ticks in `ticks`

    def drawn_times(self, agent: int) -> list[float]:
        """The triggering times drawn in `agent`'s row, read back from the ticks."""
        return [float(segment[0, 0]) for segment in self.ticks.get_segments()[self.spans[agent]]]


def plot_trigger_raster(
    ax: Axes, record: RunRecord, *, row_offset: float = 0.0, height: float = 0.8, alpha: float = 1.0
) -> RasterPlot:
    """One row per agent (row k + 1 for the k-th agent, plus `row_offset`), a tick per trigger."""
    from matplotlib.collections import LineCollection

    ids = list(record.scenario.agent_ids)
    segments, colours, spans = [], [], {}
    drawn_so_far = 0
    for k, agent in enumerate(ids):
        times = np.asarray(record.trigger_times[agent], dtype=float)
        row = k + 1 + row_offset
        ticks = np.empty((times.size, 2, 2))
        ticks[:, :, 0] = times[:, None]
        ticks[:, 0, 1], ticks[:, 1, 1] = row - height / 2.0, row + height / 2.0
        spans[agent] = slice(drawn_so_far, drawn_so_far + times.size)
        drawn_so_far += times.size
        segments.append(ticks)
        colours.extend([_colour(k)] * times.size)
    drawn = ax.add_collection(
        LineCollection(np.concatenate(segments), colors=colours, linewidths=0.7, alpha=alpha)
    )
    if len(ids) <= 30:
        ax.set_yticks(range(1, len(ids) + 1))
        ax.set_yticklabels([str(agent) for agent in ids])
    ax.set_xlim(0.0, record.horizon)
    ax.set_ylim(0.3, len(ids) + 0.7 + max(row_offset, 0.0))
    ax.set_xlabel('t [s]')
    ax.set_ylabel('agent')
    return RasterPlot(axes=ax, ticks=drawn, spans=spans)


def paper_figure(record: RunRecord, *, title: str | None = None) -> tuple[Figure, TrajectoryPlot, RasterPlot]:
    """The layout of the paper's Fig. 1 (ETA-1) and Fig. 2 (ETA-2)."""
    plt = pyplot()
    fig, (ax_a, ax_b) = plt.subplots(2, 1, figsize=(6.0, 7.5), gridspec_kw={'height_ratios': [3, 1.6]})
    trajectories = plot_trajectories(ax_a, record)
    algorithm = 'ETA-1' if record.scenario.dynamics == 'single' else 'ETA-2'
    ax_a.set_title(
        f'(a) trajectories ({algorithm}); o initial positions, final formation in black', fontsize=9
    )
    if len(record.scenario.agent_ids) <= 12:
        ax_a.legend(handles=trajectories.legend_handles(), loc='best', fontsize=8)
    raster = plot_trigger_raster(ax_b, record)
    ax_b.set_title(f'(b) triggering times of each agent ({record.total_events} events)', fontsize=9)
    fig.suptitle(title or f'{record.scenario.name}: {record.mode} run', fontsize=10)
    fig.tight_layout()
    return fig, trajectories, raster


# -------------------------------------------------------------------------- time-series panels


@dataclass(frozen=True, kw_only=True)
class SeriesPlot:
    axes: Axes
    lines: dict[str, Line2D]  # what each line shows -> the line


def plot_edge_lengths(
    ax: Axes,
    record: RunRecord,
    series: Series,
    bounds: TheoryBounds | None = None,
    *,
    margin_ax: Axes | None = None,
) -> SeriesPlot:
    """Every ||x_i - x_j|| against Δ; on `margin_ax`, the room left to Δ on a log scale.

    The bounds k_ij + ||d_ij|| of (kij) lie within a fraction of a percent of Δ on typical
    scenarios, where they cannot be told from the Δ line: `margin_ax` shows Δ - ||x_i - x_j||
    with the guaranteed room Δ - (k_ij + ||d_ij||) dotted below it, decades apart.
    """
    scenario = record.scenario
    lines = {}
    for column, edge in enumerate(scenario.edges):
        (lines[f'{edge.i}-{edge.j}'],) = ax.plot(
            series.times,
            series.edge_lengths[:, column],
            lw=1.0,
            label=f'$\\|x_{{{edge.i}}}-x_{{{edge.j}}}\\|$',
        )
    lines['delta'] = ax.axhline(scenario.delta, color='r', lw=1.2, label=f'Δ = {scenario.delta:g}')
    ax.set_ylabel('edge length')
    ax.set_title('edge lengths against the communication radius Δ', fontsize=9)
    if len(scenario.edges) <= 10:
        ax.legend(loc='best', fontsize=7)
    if margin_ax is None:
        ax.set_xlabel('t [s]')
        return SeriesPlot(axes=ax, lines=lines)
    for column, edge in enumerate(scenario.edges):
        colour = lines[f'{edge.i}-{edge.j}'].get_color()
        room = scenario.delta - series.edge_lengths[:, column]
        positive = room > 0.0
        (lines[f'room {edge.i}-{edge.j}'],) = margin_ax.semilogy(
            series.times[positive], room[positive], color=colour, lw=1.0
        )
        if bounds is not None and bounds.edge_bounds is not None and len(scenario.edges) <= 12:
            guaranteed = scenario.delta - bounds.edge_bounds[edge.pair]
            if guaranteed > 0.0:
                lines[f'bound {edge.i}-{edge.j}'] = margin_ax.axhline(
                    guaranteed, color=colour, ls=':', lw=1.0
                )
    margin_ax.set_xlabel('t [s]')
    margin_ax.set_ylabel('Δ − edge length')
    margin_ax.set_title(
        'room left to Δ (log scale); dotted: the room (kij) guarantees, Δ − ($k_{ij} + \\|d_{ij}\\|$)',
        fontsize=9,
    )
    return SeriesPlot(axes=ax, lines=lines)


def plot_formation_error(
    ax: Axes, series: Series, bounds: TheoryBounds | None, *, rate: float | None = None
) -> SeriesPlot:
    """Error on a log scale; `rate` (β or β_d) draws e(0) e^{-rate t} when no bounds are known."""
    t = series.times
    lines = {}
    positive = series.formation_error > 0.0
    (lines['error'],) = ax.semilogy(
        t[positive], series.formation_error[positive], 'k', lw=1.2, label='$\\max_{ij}\\|x_i-x_j-d_{ij}\\|$'
    )
    rate = bounds.rate if bounds is not None else rate
    if rate is not None:
        (lines['envelope'],) = ax.semilogy(
            t,
            series.formation_error[0] * np.exp(-rate * t),
            'b--',
            lw=1.0,
            label=f'$e(0)\\,e^{{-{rate:g}t}}$',
        )
    if bounds is not None and bounds.error_gain is not None:
        (lines['bound'],) = ax.semilogy(
            t,
            bounds.error_gain * np.exp(-bounds.rate * t),
            'r:',
            lw=1.2,
            label='$2\\sqrt{k_V}\\,e^{-\\beta t}$ (theorem)',
        )
    if bounds is not None and bounds.floor is not None:  # the threshold floor's bound (docs/SPEED_SCALE.md)
        floor = bounds.floor
        bound = 2.0 * np.sqrt(floor.z_gain * floor.lyapunov_bound(bounds.speed_scale * t))
        (lines['bound'],) = ax.semilogy(
            t, bound, 'r:', lw=1.2, label='$2\\sqrt{z B(\\kappa t)}$ (threshold floor)'
        )
    if bounds is not None and bounds.printed_error_gain is not None:
        (lines['printed bound'],) = ax.semilogy(
            t,
            bounds.printed_error_gain * np.exp(-bounds.rate * t),
            'm-.',
            lw=1.0,
            label='bound of the proof as printed',
        )
    ax.set_xlabel('t [s]')
    ax.set_ylabel('formation error')
    ax.set_title('formation error (log scale) against the exponential envelope', fontsize=9)
    ax.legend(loc='best', fontsize=7)
    return SeriesPlot(axes=ax, lines=lines)


@dataclass(frozen=True, kw_only=True)
class HistogramPlot:
    axes: Axes
    gaps: dict[int, np.ndarray]  # agent -> its inter-event times, as histogrammed
    xi_lines: dict[int, Any]  # agent -> vertical line at ξ_i


def plot_inter_event_times(ax: Axes, record: RunRecord, xi: dict[int, float] | None) -> HistogramPlot:
    """Log-spaced histogram of t_{k+1} - t_k per agent (step outlines), ξ_i as dashed lines."""
    ids = list(record.scenario.agent_ids)
    gaps = {agent: np.diff(np.asarray(record.trigger_times[agent], dtype=float)) for agent in ids}
    values = np.concatenate([g[g > 0.0] for g in gaps.values()] + [np.array([])])
    xi_values = [v for v in (xi or {}).values() if v and v > 0.0]
    # One axis for the measured gaps and the proof's bounds, which may be orders of magnitude lower.
    low = min([*values.tolist(), *xi_values], default=1e-3)
    high = max(float(values.max()) if values.size else 1.0, 10.0 * low)
    bins = np.logspace(np.log10(low) - 0.1, np.log10(high) + 0.1, 40)
    for k, agent in enumerate(ids):
        g = gaps[agent]
        if g.size:
            ax.hist(
                g[g > 0.0],
                bins=bins,
                histtype='step',
                color=_colour(k),
                lw=1.1,
                label=f'agent {agent} ({g.size})',
            )
    lines = {}
    for k, agent in enumerate(ids):
        if xi and xi.get(agent):
            lines[agent] = ax.axvline(xi[agent], color=_colour(k), ls='--', lw=0.9)
    ax.set_xscale('log')
    ax.set_xlabel('inter-event time $t^i_{k+1}-t^i_k$ [s] (dashed: $\\xi_i$ of (xi))')
    ax.set_ylabel('count')
    ax.set_title('distribution of inter-event times', fontsize=9)
    if len(ids) <= 12:
        ax.legend(loc='best', fontsize=7)
    return HistogramPlot(axes=ax, gaps=gaps, xi_lines=lines)


def plot_energy(
    ax_tension: Axes, ax_lyapunov: Axes, record: RunRecord, series: Series, bounds: TheoryBounds | None
) -> SeriesPlot:
    double = record.scenario.dynamics == 'double'
    t = series.times
    name_nu = '$\\nu_d$' if double else '$\\nu$'
    name_v = '$V_d$' if double else '$V$'
    lines = {}
    (lines['tension'],) = ax_tension.semilogy(t, series.tension, 'k', lw=1.2, label=name_nu)
    (lines['lyapunov'],) = ax_lyapunov.semilogy(t, series.lyapunov, 'k', lw=1.2, label=name_v)
    if bounds is not None and bounds.floor is not None:
        (lines['k_V'],) = ax_lyapunov.semilogy(
            t,
            bounds.floor.lyapunov_bound(bounds.speed_scale * t),
            'r:',
            lw=1.2,
            label='$B(\\kappa t)$ (threshold floor)',
        )
    if bounds is not None and bounds.k_nu is not None:
        lines['k_nu'] = ax_tension.axhline(
            bounds.k_nu, color='r', ls=':', lw=1.2, label='$k^d_\\nu$' if double else '$k_\\nu$ (kν)'
        )
        if bounds.k_V is not None:
            (lines['k_V'],) = ax_lyapunov.semilogy(
                t,
                bounds.k_V * np.exp(-2.0 * bounds.rate * t),
                'r:',
                lw=1.2,
                label='$k_V e^{-2\\beta t}$ (kV)',
            )
        if bounds.printed_k_V is not None:
            (lines['printed k_V'],) = ax_lyapunov.semilogy(
                t,
                bounds.printed_k_V * np.exp(-2.0 * bounds.rate * t),
                'm-.',
                lw=1.0,
                label='$k^d_V e^{-2\\beta_d t}$ as printed (kVd)',
            )
    ax_tension.set_title(f'tension energy {name_nu}', fontsize=9)
    ax_lyapunov.set_title(f'Lyapunov function {name_v}', fontsize=9)
    for ax in (ax_tension, ax_lyapunov):
        ax.set_xlabel('t [s]')
        ax.legend(loc='best', fontsize=7)
    return SeriesPlot(axes=ax_tension, lines=lines)


# -------------------------------------------------------------------------------- all figures


FIGURE_FILES = {
    'formation (paper Fig. 1/2 style)': 'formation.png',
    'edge lengths': 'edge_lengths.png',
    'formation error': 'formation_error.png',
    'inter-event times': 'inter_event_times.png',
    'tension and Lyapunov function': 'energy.png',
}


def write_figures(
    record: RunRecord, series: Series, bounds: TheoryBounds | None, out_dir: str | Path, *, dpi: int = 100
) -> dict[str, str]:
    """Every analysis figure as a PNG in `out_dir`; returns title -> file name."""
    plt = pyplot()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rate = (
        record.scenario.gains.beta if record.scenario.dynamics == 'single' else record.scenario.gains.beta_d
    )
    figures = {}
    fig, _, _ = paper_figure(record)
    figures['formation (paper Fig. 1/2 style)'] = fig
    fig, (ax, margin_ax) = plt.subplots(2, 1, figsize=(6.4, 6.4), sharex=True)
    plot_edge_lengths(ax, record, series, bounds, margin_ax=margin_ax)
    figures['edge lengths'] = fig
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    plot_formation_error(ax, series, bounds, rate=rate)
    figures['formation error'] = fig
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    plot_inter_event_times(ax, record, None if bounds is None else bounds.xi)
    figures['inter-event times'] = fig
    fig, (ax_nu, ax_v) = plt.subplots(1, 2, figsize=(9.0, 3.8))
    plot_energy(ax_nu, ax_v, record, series, bounds)
    figures['tension and Lyapunov function'] = fig
    written = {}
    for title, fig in figures.items():
        fig.tight_layout()
        fig.savefig(out / FIGURE_FILES[title], dpi=dpi)
        plt.close(fig)
        written[title] = FIGURE_FILES[title]
    return written


# ---------------------------------------------------------------------------------- animation


def frame_indices(times: np.ndarray, *, frames: int) -> np.ndarray:
    """Sample indices for `frames` frames evenly spaced in time: the last sample at or before each frame
    time."""
    times = np.asarray(times, dtype=float)
    targets = np.linspace(times[0], times[-1], max(2, frames))
    return np.clip(np.searchsorted(times, targets, side='right') - 1, 0, len(times) - 1)


def animate(
    record: RunRecord,
    path: str | Path,
    *,
    frames: int = 150,
    fps: int = 15,
    dpi: int = 80,
    progress: Callable[[int, int], None] | None = None,
) -> Path:
    """GIF of the run: agents, their trails, edges coloured by length / Δ, the desired formation."""
    from matplotlib.animation import PillowWriter

    plt = pyplot()
    movie = _Movie.of(record, frames=frames)
    fig, artists = _movie_artists(plt, record, movie.x)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # The writer directly (not FuncAnimation.save, which renders every frame twice on Agg).
    writer = PillowWriter(fps=fps)
    try:
        with writer.saving(fig, str(path), dpi):
            for frame in range(len(movie.chosen)):
                _draw_frame(artists, movie, record, movie.chosen[frame])
                writer.grab_frame()
                if progress is not None:
                    progress(frame + 1, len(movie.chosen))
    finally:
        plt.close(fig)
    return path


@dataclass(frozen=True, kw_only=True)
class _Movie:
    """What the animation draws, frame by frame: planar samples, edges as index pairs, the desired
    formation's offsets from its centroid, every event time (sorted) and the frames' samples."""

    x: np.ndarray
    t: np.ndarray
    pairs: list[tuple[int, int]]
    offsets: np.ndarray
    events: np.ndarray
    chosen: np.ndarray

    @classmethod
    def of(cls, record: RunRecord, *, frames: int) -> _Movie:
        from formation_sim.model import theory

        scenario = record.scenario
        x = record.sample_positions
        if x.shape[2] == 1:  # a line: draw it on the x axis
            x = np.concatenate([x, np.zeros_like(x)], axis=2)
        x = x[:, :, :2]
        t = np.asarray(record.sample_times, dtype=float)
        index = {agent: k for k, agent in enumerate(scenario.agent_ids)}
        tau = theory.formation_feasibility(scenario).tau
        offsets = tau - tau.mean(axis=0)
        offsets = (
            np.concatenate([offsets, np.zeros_like(offsets)], axis=1)[:, :2]
            if offsets.shape[1] == 1
            else offsets[:, :2]
        )
        return cls(
            x=x,
            t=t,
            pairs=[(index[e.i], index[e.j]) for e in scenario.edges],
            offsets=offsets,
            events=np.sort(
                np.concatenate([np.asarray(v, dtype=float) for v in record.trigger_times.values()])
            ),
            chosen=frame_indices(t, frames=frames),
        )


@dataclass(frozen=True, kw_only=True)
class _MovieArtists:
    """The animation's artists, updated in place by `_draw_frame`."""

    trails: list[Line2D]
    desired_edges: LineCollection
    desired: PathCollection
    edges: LineCollection
    agents: PathCollection
    ids: list[Any]
    label: Any


def _movie_artists(plt: Any, record: RunRecord, x: np.ndarray) -> tuple[Figure, _MovieArtists]:
    """The animation's figure, its axes fitted to every sample, and its artists at t = 0."""
    from matplotlib.collections import LineCollection

    scenario = record.scenario
    fig, ax = plt.subplots(figsize=(7.0, 7.0))
    span = np.ptp(x.reshape(-1, 2), axis=0).max()
    pad = 0.1 * span + 0.05 * scenario.delta
    ax.set_xlim(x[..., 0].min() - pad, x[..., 0].max() + pad)
    ax.set_ylim(x[..., 1].min() - pad, x[..., 1].max() + pad)
    ax.set_aspect('equal')
    colours = [_colour(k) for k in range(len(scenario.agent_ids))]
    trails = [ax.plot([], [], '-', color=colours[k], lw=0.8, alpha=0.6)[0] for k in range(len(colours))]
    desired_edges = LineCollection([], colors=[(0.6, 0.6, 0.6, 0.6)], linewidths=0.8, linestyles='--')
    ax.add_collection(desired_edges)
    desired = ax.scatter([], [], s=60, facecolors='none', edgecolors=(0.5, 0.5, 0.5, 0.8))
    edges = LineCollection([], linewidths=2.0)
    ax.add_collection(edges)
    agents = ax.scatter(x[0, :, 0], x[0, :, 1], s=60, c=colours, zorder=3)
    # Ids beside the agents, for teams small enough to read them.
    ids = (
        [
            ax.annotate(
                str(agent),
                x[0, k],
                xytext=(6, 6),
                textcoords='offset points',
                fontsize=9,
                color=colours[k],
                zorder=4,
            )
            for k, agent in enumerate(scenario.agent_ids)
        ]
        if len(scenario.agent_ids) <= 30
        else []
    )
    label = ax.text(
        0.02,
        0.97,
        '',
        transform=ax.transAxes,
        va='top',
        fontsize=11,
        family='monospace',
        bbox={'facecolor': 'white', 'alpha': 0.8, 'edgecolor': 'none'},
    )
    ax.set_title(
        f'{scenario.name}: edges green → red as their length nears Δ = {scenario.delta:g}', fontsize=9
    )
    artists = _MovieArtists(
        trails=trails,
        desired_edges=desired_edges,
        desired=desired,
        edges=edges,
        agents=agents,
        ids=ids,
        label=label,
    )
    return fig, artists


def _draw_frame(artists: _MovieArtists, movie: _Movie, record: RunRecord, k: int) -> None:
    """Move every artist to sample `k`: trails up to it, edges coloured by length / Δ."""
    x = movie.x
    now = x[k]
    for a, trail in enumerate(artists.trails):
        trail.set_data(x[: k + 1, a, 0], x[: k + 1, a, 1])
    artists.agents.set_offsets(now)
    for k_agent, text in enumerate(artists.ids):
        text.xy = now[k_agent]
    artists.edges.set_segments([[now[a], now[b]] for a, b in movie.pairs])
    artists.edges.set_color(
        [
            edge_colour(
                float(np.linalg.norm(record.sample_positions[k][a] - record.sample_positions[k][b])),
                record.scenario.delta,
            )
            for a, b in movie.pairs
        ]
    )
    goal = now.mean(axis=0) + movie.offsets
    artists.desired.set_offsets(goal)
    artists.desired_edges.set_segments([[goal[a], goal[b]] for a, b in movie.pairs])
    events = int(np.searchsorted(movie.events, movie.t[k], side='right'))
    artists.label.set_text(f't = {movie.t[k]:7.3f} s   events: {events}')
