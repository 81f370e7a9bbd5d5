"""The report from a study's rows: the audit table sums the rows, savings against periodic sampling."""

from __future__ import annotations

import pytest

from formation_sim.study.case import run_case
from formation_sim.study.errors import StudyError
from formation_sim.study.report import audit_table, periodic_savings, stops_table, write_report
from formation_sim.study.spec import build_study
from formation_sim.study.store import StudyFolder


@pytest.fixture(scope='module')
def folder(tmp_path_factory):
    study = build_study(
        {
            'name': 'r',
            'seed': 2,
            'defaults': {'horizon': 1.0, 'alpha': 10.0},
            'cases': [
                {'n': 6, 'algorithm': ['eta1', 'eta2'], 'graph': ['star', 'cycle']},
                {'n': 6, 'graph': 'star', 'sampling': ['event', 'periodic'], 'period': [0.01, 0.5]},
            ],
        }
    )
    path = tmp_path_factory.mktemp('study')
    return path, _run_into(path, study)


def _run_into(path, study) -> list[dict]:
    """Every case of `study` run here, its rows written to the study folder `path` (and returned)."""
    store = StudyFolder(path, study)
    store.open()
    for case in study.cases:
        store.append(run_case(case))
    store.close()
    return store.rows


def test_the_audit_table_adds_up_the_rows(folder):
    _, rows = folder
    table = {(t['theorem'], t['guarantee'].split(':')[0]): t for t in audit_table(rows)}
    eta2 = [r for r in rows if r['algorithm'] == 'eta2']
    assert table[('2', 'connectivity')]['checks'] == sum(r['conn_checks'] for r in eta2)
    assert table[('2', 'Theorem 2 rate as printed')]['runs'] == len(eta2) == 2
    assert ('1', 'Theorem 2 rate as printed') not in table
    one = table[('1', 'Zeno')]
    assert one['smallest_margin'] == min(
        r['zeno_margin'] for r in rows if r['algorithm'] == 'eta1' and r['sampling'] == 'event'
    )
    assert (
        one['violations'] == 0 and one['runs'] == 2
    )  # the second block's event run is the first's star: run once


def test_savings_compare_with_the_cheapest_periodic_run_at_most_as_far_from_formation(folder):
    _, rows = folder
    savings = periodic_savings(rows)
    eta = next(
        r for r in rows if r['sampling'] == 'event' and r['graph'] == 'star' and r['algorithm'] == 'eta1'
    )
    periodic = [r for r in rows if r['sampling'] == 'periodic' and r['status'] == 'ok']
    good = [r['total_events'] for r in periodic if r['final_formation_error'] <= eta['final_formation_error']]
    assert good  # the period 0.01 s run ends closer to the formation
    assert [s for r, s in savings if r is eta] == [pytest.approx(1.0 - eta['total_events'] / min(good))]


def test_the_report_is_written_and_a_folder_without_rows_refused(folder, tmp_path):
    path, rows = folder
    report = write_report(path, out=tmp_path / 'report')
    text = report.read_text()
    # Sampled every 0.5 s, the star leaves Δ: that periodic run is a failed row, the report says so.
    failed = [r for r in rows if r['status'] == 'failed']
    assert len(failed) == 1 and failed[0]['period'] == 0.5 and 'out of its range' in failed[0]['error']
    assert f'{len(rows)} rows, 1 failed.' in text and '![events_vs_n.png](events_vs_n.png)' in text
    assert {'events_vs_n.png', 'saved_vs_periodic.png', 'inter_event_vs_xi.png', 'edge_vs_delta.png'} <= {
        p.name for p in (tmp_path / 'report').iterdir()
    }
    with pytest.raises(StudyError, match='no rows.csv: not a study folder'):
        write_report(tmp_path / 'report')


def test_runs_stopped_at_a_fraction_of_their_error_are_counted_by_how_they_ended(tmp_path):
    study = build_study(
        {
            'name': 's',
            'seed': 4,
            'defaults': {'alpha': 10.0, 'until_error': 0.05},
            'cases': [
                {'n': 4, 'graph': 'star', 'algorithm': ['eta1', 'eta2'], 'horizon': 60.0},
                {'n': 4, 'graph': 'cycle', 'algorithm': 'eta1', 'horizon': 0.05},
            ],
        }
    )
    rows = _run_into(tmp_path, study)
    reached = [r for r in rows if r['horizon'] == 60.0]
    assert [r['stop'] for r in reached] == ['error_reached'] * 2  # both reach 5 % well before 60 s
    assert all(r['final_formation_error'] <= 0.05 * r['initial_formation_error'] for r in reached)
    table = {t['algorithm']: t for t in stops_table(rows)}
    one = table['eta1']
    assert one['runs'] == 2 and one['error_reached'] == 1 and one['horizon'] == 1
    assert table['eta2'] == {
        'algorithm': 'eta2',
        'runs': 1,
        'error_reached': 1,
        'rounding_floor': 0,
        'horizon': 0,
        'stop_time_median': reached[1]['stop_time'],
        'stop_time_max': reached[1]['stop_time'],
    }
    text = write_report(tmp_path, out=tmp_path / 'report').read_text()
    assert '## How the runs ended' in text and '![stop_time_vs_rate.png](stop_time_vs_rate.png)' in text
