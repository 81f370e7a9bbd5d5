"""The study folder: rows appended whole, read back to the bit, a cut line dropped, other folders refused."""

from __future__ import annotations

import json

import pytest

from formation_sim.study.case import COLUMNS, run_case
from formation_sim.study.errors import StudyError
from formation_sim.study.spec import build_study
from formation_sim.study.store import ROWS_FILE, STUDY_FILE, StudyFolder, read_rows


def _study(n=3, name='t'):
    return build_study(
        {
            'name': name,
            'seed': 1,
            'defaults': {'horizon': 0.5, 'alpha': 10.0},
            'cases': [{'n': n, 'graph': ['star', 'path']}],
        }
    )


def test_rows_read_back_to_the_bit_and_a_row_is_written_once(tmp_path):
    study = _study()
    folder = StudyFolder(tmp_path / 's', study)
    folder.open()
    rows = [run_case(case) for case in study.cases]
    rows[0]['error'] = 'a, "quoted"\nline'  # commas, quotes and newlines stay in one cell
    assert folder.append(rows[1]) and folder.append(rows[0]) and not folder.append(rows[0])
    folder.close()
    back = read_rows(tmp_path / 's')
    assert [r['case'] for r in back] == [0, 1]  # sorted by case, whatever the order they came in
    rows[0]['error'] = 'a, "quoted" line'
    assert back == rows  # every float to the bit (repr), None as an empty cell
    assert tuple((tmp_path / 's' / ROWS_FILE).read_text().splitlines()[0].split(',')) == COLUMNS
    assert json.loads((tmp_path / 's' / STUDY_FILE).read_text())['digest'] == study.digest


def _folder_with_first_row(tmp_path):
    """A study folder at tmp_path holding the first of the study's two rows; the second not appended."""
    study = _study()
    folder = StudyFolder(tmp_path, study)
    folder.open()
    first, second = (run_case(case) for case in study.cases)
    folder.append(first)
    folder.close()
    return study, first, second, tmp_path / ROWS_FILE


def test_a_cut_last_line_is_dropped_and_the_study_goes_on(tmp_path):
    study, first, second, path = _folder_with_first_row(tmp_path)
    whole = path.read_text()
    path.write_text(whole + whole.splitlines()[1][:40])  # a row cut by a kill mid-write
    assert [r['key'] for r in read_rows(tmp_path)] == [first['key']]
    again = StudyFolder(tmp_path, study)
    assert again.done == {first['key']}
    again.open()
    again.append(second)
    again.close()
    text = path.read_text()
    assert text.startswith(whole) and text.count('\n') == 3  # the cut piece is gone, the new row whole
    assert [r['key'] for r in read_rows(tmp_path)] == [first['key'], second['key']]


def test_a_folder_of_another_study_or_of_other_files_is_refused(tmp_path):
    StudyFolder(tmp_path / 'a', _study()).open()
    with pytest.raises(
        StudyError, match=r"holds another study \('t', 2 cases, digest .*; this SPEC: 'u', 2 cases"
    ):
        StudyFolder(tmp_path / 'a', _study(n=4, name='u'))
    (tmp_path / 'b').mkdir()
    (tmp_path / 'b' / 'notes.txt').write_text('mine')
    with pytest.raises(StudyError, match='holds files but no study.json: not a study folder'):
        StudyFolder(tmp_path / 'b', _study())
    (tmp_path / 'c').write_text('')
    with pytest.raises(StudyError, match='is a file, not a folder'):
        StudyFolder(tmp_path / 'c', _study())


def test_a_folder_of_an_earlier_version_reads_with_the_new_parameters_at_their_defaults(tmp_path):
    study, first, second, path = _folder_with_first_row(tmp_path)
    lines = path.read_text().splitlines()
    drop = [COLUMNS.index('speed_scale'), COLUMNS.index('threshold_floor')]
    old = (
        '\n'.join(','.join(c for k, c in enumerate(line.split(',')) if k not in drop) for line in lines)
        + '\n'
    )
    path.write_text(old)  # as a study folder written before the two parameters existed
    assert read_rows(tmp_path) == [first]
    again = StudyFolder(tmp_path, study)
    again.open()  # rewritten once with today's columns
    again.append(second)
    again.close()
    assert read_rows(tmp_path) == [first, second]
    assert tuple(path.read_text().splitlines()[0].split(',')) == COLUMNS
