"""Run folders: no run replaces another unless asked, fresh folders never collide and stay inside runs/."""

from __future__ import annotations

import os
import re
import threading
from pathlib import Path

import pytest

from formation_sim.sim.errors import RunFolderError
from formation_sim.sim.run_folder import (
    RUN_ENTRIES,
    check_out_dir,
    check_report_dir,
    claim_out_dir,
    clear_out_dir,
    folder_name,
    new_run_folder,
)


def _make_run(folder, *names):
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        if name in ('bag', 'logs', 'analysis') or name.startswith('compare-'):
            (folder / name).mkdir()
            (folder / name / 'inner.txt').write_text('old')
        else:
            (folder / name).write_text('old')
    return folder


def test_a_new_or_empty_folder_is_accepted(tmp_path):
    check_out_dir(tmp_path / 'new' / 'deeper')
    (tmp_path / 'empty').mkdir()
    check_out_dir(tmp_path / 'empty')
    assert (
        claim_out_dir(tmp_path / 'new' / 'deeper', scenario_name='s', kind='run')
        == tmp_path / 'new' / 'deeper'
    )
    assert (tmp_path / 'new' / 'deeper').is_dir()


def test_a_folder_holding_a_run_is_refused_naming_what_is_there(tmp_path):
    run = _make_run(tmp_path / 'run', 'summary.json', 'formation.png', 'bag')
    with pytest.raises(RunFolderError) as caught:
        clear_out_dir(run)
    assert str(caught.value) == (
        f'{run} already holds an earlier run (bag/, formation.png, summary.json); nothing was changed. '
        'Choose another --out (or none: a new folder under runs/), or add --force to replace the earlier run'
    )
    assert sorted(p.name for p in run.iterdir()) == ['bag', 'formation.png', 'summary.json']


def test_any_other_content_is_refused_too(tmp_path):
    (tmp_path / 'notes').mkdir()
    (tmp_path / 'notes' / 'todo.txt').write_text('mine')
    with pytest.raises(RunFolderError, match=r'notes already holds files \(todo.txt\); nothing was changed'):
        check_out_dir(tmp_path / 'notes')


def test_force_removes_every_file_of_the_earlier_run_and_nothing_else(tmp_path):
    run = _make_run(tmp_path / 'run', *sorted(RUN_ENTRIES), 'compare-other')
    removed = clear_out_dir(run, force=True)
    assert removed == sorted([*RUN_ENTRIES, 'compare-other'])
    assert list(run.iterdir()) == []  # nothing stale beside the next run
    beside = tmp_path / 'beside.txt'
    beside.write_text('kept')
    assert beside.read_text() == 'kept'


def test_force_never_removes_files_no_run_writes(tmp_path):
    run = _make_run(tmp_path / 'run', 'summary.json', 'bag')
    (run / 'thesis.tex').write_text('mine')
    with pytest.raises(RunFolderError) as caught:
        clear_out_dir(run, force=True)
    assert (
        f"{run} holds thesis.tex, which no run writes; --force replaces only an earlier run's files"
        in str(caught.value)
    )
    assert sorted(p.name for p in run.iterdir()) == ['bag', 'summary.json', 'thesis.tex']


def test_a_file_on_the_way_is_refused(tmp_path):
    (tmp_path / 'file').write_text('x')
    with pytest.raises(RunFolderError, match=r'file is a file, not a folder$'):
        check_out_dir(tmp_path / 'file', force=True)
    with pytest.raises(
        RunFolderError,
        match=rf'{re.escape(str(tmp_path / "file"))} is a file, so no folder can be made under it',
    ):
        check_out_dir(tmp_path / 'file' / 'run')
    assert (tmp_path / 'file').read_text() == 'x'


@pytest.mark.skipif(os.geteuid() == 0, reason='root may write anywhere')
def test_an_unwritable_place_is_refused(tmp_path):
    locked = tmp_path / 'locked'
    locked.mkdir()
    locked.chmod(0o500)
    try:
        with pytest.raises(RunFolderError, match=r'cannot write in .*locked \(permission denied\)'):
            check_out_dir(locked / 'run')
    finally:
        locked.chmod(0o700)


def test_a_place_that_cannot_hold_folders_is_refused_when_claimed():
    # /proc accepts no new folders, even for root (which os.access cannot tell).
    with pytest.raises(RunFolderError, match=r'/proc/formation-run: cannot prepare the run folder: '):
        claim_out_dir(Path('/proc/formation-run'), scenario_name='s', kind='run')


@pytest.mark.parametrize(
    ('name', 'folder'),
    [
        ('paper_single', 'paper_single'),
        ('../../escaped', 'escaped'),
        ('/etc/passwd', 'etc-passwd'),
        ('..', 'scenario'),
        ('a b\tc', 'a-b-c'),
        ('Σχήμα', 'scenario'),
        ('x' * 300, 'x' * 64),
    ],
)
def test_folder_names_from_scenario_names_are_one_safe_path_component(name, folder):
    assert folder_name(name) == folder


def test_new_run_folders_stay_inside_runs_and_never_collide(tmp_path):
    root = tmp_path / 'runs'
    made = [new_run_folder('../../escaped', 'simulate', root=root) for _ in range(3)]
    assert len(set(made)) == 3
    for folder in made:
        assert folder.parent == root and folder.is_dir()
        assert re.fullmatch(r'escaped-simulate-\d{8}-\d{6}(-\d+)?', folder.name)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['runs']  # nothing escaped


def test_concurrent_claims_get_different_folders(tmp_path):
    root = tmp_path / 'runs'
    made: list = []
    threads = [
        threading.Thread(target=lambda: made.append(new_run_folder('s', 'run', root=root))) for _ in range(8)
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(set(made)) == 8


def test_a_report_never_overwrites_a_run(tmp_path):
    run = _make_run(tmp_path / 'run', 'summary.json')
    with pytest.raises(
        RunFolderError, match=r'holds a run \(summary.json or bag/\) whose files the report would overwrite'
    ):
        check_report_dir(run)
    check_report_dir(tmp_path / 'report')  # new: fine
    check_report_dir(_make_run(tmp_path / 'old_report', 'analysis'))  # an earlier report: rewritten


def test_run_entries_cover_what_simulate_leaves(tmp_path):
    from formation_sim.cli import main

    run = tmp_path / 'run'
    assert main(['simulate', 'paper_single', '--horizon', '0.2', '--out', str(run), '--quiet']) == 0
    assert {p.name for p in run.iterdir()} <= RUN_ENTRIES


@pytest.mark.ros
def test_run_entries_cover_what_a_distributed_run_leaves(distributed_single_run):
    assert {p.name for p in distributed_single_run.out_dir.iterdir()} <= RUN_ENTRIES


@pytest.mark.parametrize('inside', ['', 'x', 'x/y'])
def test_a_bag_folder_and_any_folder_inside_it_are_refused_for_runs_and_reports(tmp_path, inside):
    """Issue 28: `analyze --out RUN/bag` and `run --out RUN/bag/x` wrote inside a bag's folder."""
    from formation_sim.sim.run_folder import check_report_dir

    bag = tmp_path / 'run' / 'bag'
    bag.mkdir(parents=True)
    (bag / 'bag_0.mcap').write_bytes(b'\x89MCAP0\r\n')
    out = bag / inside if inside else bag
    for check in (check_out_dir, check_report_dir):
        with pytest.raises(RunFolderError, match=r'the bag folder .*bag \(it holds a recording') as refused:
            check(out)
        assert ('is the bag folder' if not inside else 'lies inside the bag folder') in str(refused.value)
    assert sorted(p.name for p in bag.iterdir()) == ['bag_0.mcap']  # nothing changed
    (bag / 'bag_0.mcap').unlink()
    (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information: {}\n')  # a bag by its metadata alone
    with pytest.raises(RunFolderError, match='the bag folder'):
        check_out_dir(bag / 'x', force=True)
    check_out_dir(tmp_path / 'run' / 'other')  # beside the bag: a folder like any other
