"""A study's folder: `study.json` (what the study is) and `rows.csv` (one row per finished case).

CSV rather than Parquet: rows are appended one by one as cases finish, each line written whole,
flushed and fsynced, so a study killed at any instant loses at most the line being written (cut
lines are dropped when the folder is opened again); Parquet files cannot be appended to, would
need a file per row or a rewrite, and pyarrow (~100 MB installed) for a table of a few thousand
rows. pandas reads it as it is: `pandas.read_csv('DIR/rows.csv')`; `read_rows` reads it without
pandas. Floats are written with repr, so every number reads back to the bit.
"""

from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path
from typing import Any

from formation_sim.sim.files import write_atomically
from formation_sim.study.case import COLUMNS
from formation_sim.study.errors import StudyError
from formation_sim.study.spec import PARAMETERS, Study

ROWS_FILE = 'rows.csv'
STUDY_FILE = 'study.json'
SCHEMA = 'formation-study/1'
STRING_COLUMNS = frozenset(
    {'key', 'algorithm', 'sampling', 'graph', 'status', 'error', 'worker', 'beta_d_bound', 'stop'}
)


def _cell(value: Any) -> str:
    if value is None:
        return ''
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, float):
        return repr(value)
    return str(value).replace('\r', ' ').replace('\n', ' ')


def _value(column: str, text: str) -> Any:
    if text == '':
        return None
    if column in STRING_COLUMNS:
        return text
    try:
        return int(text)
    except ValueError:
        return float(text)


def _line(values) -> str:
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator='\n').writerow(values)
    return buffer.getvalue()


def read_rows(folder: str | Path) -> list[dict[str, Any]]:
    """Every whole row of a study folder, sorted by case; a cut last line is left out."""
    path = Path(folder) / ROWS_FILE
    if not path.exists():
        return []
    text = path.read_text()
    if not text.endswith('\n'):
        text = text[: text.rfind('\n') + 1]
    reader = csv.reader(io.StringIO(text))
    header = next(reader, None)
    if header is None:
        return []
    unknown = sorted(set(header) - set(COLUMNS))
    if unknown:
        raise StudyError(f"{path}: column {unknown[0]!r} is not one of this version's; use another --out")
    # A folder of an earlier version lacks the parameters added since: their defaults, as its cases ran.
    missing = {
        column: PARAMETERS[column].default if column in PARAMETERS else None
        for column in COLUMNS
        if column not in header
    }
    rows = []
    for cells in reader:
        values = {column: _value(column, cell) for column, cell in zip(header, cells)}
        rows.append({column: values[column] if column in values else missing[column] for column in COLUMNS})
    return sorted(rows, key=lambda row: row['case'])


class StudyFolder:
    """The study folder, opened to add rows: refuses a folder holding another study."""

    def __init__(self, folder: str | Path, study: Study) -> None:
        self.folder = Path(folder)
        self.study = study
        if self.folder.exists() and not self.folder.is_dir():
            raise StudyError(f'--out {self.folder} is a file, not a folder')
        marker = self.folder / STUDY_FILE
        if marker.exists():
            known = json.loads(marker.read_text())
            if known.get('digest') != study.digest:
                raise StudyError(
                    f'{self.folder} holds another study ({known.get("name")!r}, {known.get("cases")} '
                    f'cases, digest {known.get("digest")}; this SPEC: {study.name!r}, '
                    f'{len(study.cases)} cases, digest {study.digest}): nothing was changed; choose '
                    'another --out'
                )
        elif self.folder.exists() and any(self.folder.iterdir()):
            raise StudyError(
                f'{self.folder} holds files but no {STUDY_FILE}: not a study folder; nothing was '
                'changed; choose another --out'
            )
        self.rows = read_rows(self.folder) if marker.exists() else []
        self.done = {row['key'] for row in self.rows}

    def open(self) -> None:
        """Create the folder and its files, drop a cut last line: ready for `append`."""
        self.folder.mkdir(parents=True, exist_ok=True)
        marker = self.folder / STUDY_FILE
        if not marker.exists():
            record = {
                'schema': SCHEMA,
                'name': self.study.name,
                'digest': self.study.digest,
                'cases': len(self.study.cases),
                'spec': self.study.text,
            }
            write_atomically(marker, json.dumps(record, indent=1) + '\n')
        path = self.folder / ROWS_FILE
        if not path.exists():
            write_atomically(path, _line(COLUMNS))
        elif path.read_text().split('\n', 1)[0] != _line(COLUMNS).rstrip('\n'):
            # Written by an earlier version (fewer columns): rewritten whole with today's, once.
            write_atomically(
                path,
                ''.join([_line(COLUMNS), *(_line([_cell(row[c]) for c in COLUMNS]) for row in self.rows)]),
            )
        with path.open('rb+') as handle:
            data = handle.read()
            if not data.endswith(b'\n'):
                handle.truncate(data.rfind(b'\n') + 1)
        self._handle = path.open('a', encoding='utf-8')

    def append(self, row: dict[str, Any]) -> bool:
        """Write one row whole (flushed, fsynced); False if its case has a row already."""
        if row['key'] in self.done:
            return False
        self._handle.write(_line([_cell(row[column]) for column in COLUMNS]))
        self._handle.flush()
        os.fsync(self._handle.fileno())
        self.done.add(row['key'])
        self.rows.append(row)
        return True

    def close(self) -> None:
        handle = getattr(self, '_handle', None)
        if handle is not None:
            handle.close()
            self._handle = None
