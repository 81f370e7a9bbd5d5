"""`formation simulate`: the figure of each controller (the continuous one has no event raster)."""

from __future__ import annotations

import matplotlib.image
import pytest
from matplotlib.collections import LineCollection

from formation_sim.sim.baselines import simulate_continuous
from formation_sim.cli import main
from formation_sim.sim.engine import simulate
from formation_sim.analysis.plots import FIGURE_FILE, run_figure
from formation_sim.model.scenario import load_scenario


@pytest.fixture(scope='module')
def scenario():
    return load_scenario('paper_single')


def test_continuous_figure_has_no_raster_and_says_why(scenario):
    fig = run_figure(simulate_continuous(scenario, horizon=0.5))
    assert len(fig.axes) == 1
    assert 'no triggering events' in fig.get_suptitle()
    (ax,) = fig.axes
    assert not ax.get_title().startswith('(a)')  # a lone panel is not labelled
    assert len(ax.get_lines()) == 2 * scenario.n + len(scenario.edges)  # trajectories, start circles, final edges


def test_event_triggered_figure_draws_one_tick_per_trigger(scenario):
    record = simulate(scenario, horizon=0.5)
    fig = run_figure(record)
    assert len(fig.axes) == 2
    raster = fig.axes[1]
    ticks = sum(len(c.get_segments()) for c in raster.collections if isinstance(c, LineCollection))
    assert ticks == record.total_events > 0
    assert f'({record.total_events} events)' in raster.get_title()
    assert 'no triggering events' not in fig.get_suptitle()


@pytest.mark.parametrize(('flags', 'panels'), [([], 2), (['--continuous'], 1)], ids=['events', 'continuous'])
def test_simulate_writes_the_figure_with_the_panels_of_its_controller(tmp_path, capsys, flags, panels):
    out = tmp_path / 'run'
    assert main(['simulate', 'paper_single', '--horizon', '0.5', '--out', str(out), '--quiet', *flags]) == 0
    assert capsys.readouterr().out.strip() == str(out)
    height, width = matplotlib.image.imread(out / FIGURE_FILE).shape[:2]
    # 7 in wide at 110 dpi; 9 in high with the raster below, 5.6 in without it.
    assert (width, height) == (770, 990 if panels == 2 else 616)
