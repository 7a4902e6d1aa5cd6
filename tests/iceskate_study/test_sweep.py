"""Sweeps: the local pool and local Ray give the same table, a failing point is a row, bags for
selected points, SIGINT mid-sweep keeps the finished rows and the same command resumes."""

import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time

import pyarrow.parquet as pq
import pytest

from iceskate_study.spec import parse_spec
from iceskate_study.sweep import main, run_sweep
from iceskate_study.table import RESULTS, TIMING_COLUMNS


def _rows(out: Path) -> list[dict]:
    """The table's rows without the columns that measure time."""
    return [{k: v for k, v in row.items() if k not in TIMING_COLUMNS}
            for row in pq.read_table(out / RESULTS).to_pylist()]


def test_the_local_pool_and_local_ray_give_the_same_table(tmp_path, grid):
    ray = pytest.importorskip('ray')
    spec = parse_spec(grid, tmp_path / 'spec.yaml')
    local = run_sweep(spec, tmp_path / 'local', workers=2, progress=False)
    assert (local.total, local.ran, local.resumed) == (4, 4, 0)
    temp = Path(tempfile.gettempdir())
    before = set(temp.glob('iceskate-ray-*')) | set(Path('/tmp/ray').glob('session_*'))
    on_ray = run_sweep(spec, tmp_path / 'ray', workers=2, ray='local', progress=False)
    assert on_ray.ran == 4 and not ray.is_initialized()  # the local instance is stopped
    # its session files lived in a private folder of its own, removed with it
    assert set(temp.glob('iceskate-ray-*')) | set(Path('/tmp/ray').glob('session_*')) == before
    rows = _rows(tmp_path / 'local')
    assert rows == _rows(tmp_path / 'ray')
    assert [r['status'] for r in rows] == ['ok'] * 4
    assert [(r['floor.mu'], r['inputs.gait_manager.yaw.amplitude']) for r in rows] == [
        (0.005, 0.0), (0.005, 30.0), (0.01, 0.0), (0.01, 30.0)]
    assert all(r['steps'] >= 0 and r['forward_distance_m'] > 0 for r in rows)
    assert rows[0]['head_error_rms.z'] > 0  # a block kept whole: one column per entry
    again = run_sweep(spec, tmp_path / 'local', progress=False)  # nothing left to run
    assert (again.ran, again.resumed) == (0, 4)


def test_a_failing_point_is_a_row_and_selected_points_get_a_bag(tmp_path, grid):
    grid['overrides']['duration'] = 0.3
    grid['axes'] = {'initial.q.q7': [0.25, -1.0]}  # -1.0: the swing toe starts in the floor
    grid['bags'] = [{'initial.q.q7': 0.25}]
    result = run_sweep(parse_spec(grid, tmp_path / 'spec.yaml'), tmp_path / 'out', workers=1,
                       progress=False)
    assert result.counts == {'ok': 1, 'failed': 1}
    good, bad = pq.read_table(tmp_path / 'out' / RESULTS).to_pylist()
    assert bad['status'] == 'failed' and bad['steps'] is None and bad['run_dir'] is None
    assert 'the initial state cannot be simulated' in bad['failure']
    assert good['status'] == 'ok' and good['failure'] is None
    assert good['run_dir'] == f'runs/{good["key"]}'
    for name in ('metrics.json', 'bag/metadata.yaml', 'summary.png'):
        assert (tmp_path / 'out' / good['run_dir'] / name).is_file(), name


def test_sigint_mid_sweep_keeps_the_finished_rows_and_the_same_command_resumes(
        tmp_path, grid, write_spec):
    grid['axes'] = {'floor.mu': {'linspace': [0.004, 0.0155, 24]}}
    grid['overrides'] = {'duration': 6.0}  # ~0.3 s of wall time each: SIGINT comes mid-sweep
    spec, out = write_spec(grid), tmp_path / 'out'
    command = [sys.executable, '-m', 'iceskate_study.sweep', str(spec), '--out', str(out),
               '--workers', '1', '--quiet']
    proc = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not (out / RESULTS).exists() and proc.poll() is None:
            assert time.monotonic() < deadline, 'no table within 120 s'
            time.sleep(0.02)
        proc.send_signal(signal.SIGINT)  # to the sweep's process only: it stops its workers
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert err.count('\n') == 1 and err.startswith('sweep: interrupted by SIGINT: '), err
    before = _rows(out)
    assert 1 <= len(before) < 24
    assert 'the same command resumes' in err and f'{len(before)} of 24' in err
    done = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert f'({24 - len(before)} done now in' in done.stderr
    assert f'{len(before)} before): 24 ok' in done.stderr
    after = _rows(out)
    assert [r['point'] for r in after] == list(range(24))
    assert [r for r in after if r['key'] in {b['key'] for b in before}] == before


def test_a_table_without_a_run_column_is_refused_before_anything_runs(tmp_path, grid,
                                                                       write_spec, capsys):
    """Resuming into a table that lost its status column (edited) used to run every point
    again and then fail on a KeyError: one line, nothing run, the table untouched."""
    grid['overrides']['duration'] = 0.05
    grid['axes'] = {'floor.mu': [0.005]}
    spec = write_spec(grid)
    assert main([str(spec), '--out', str(tmp_path / 'out'), '--quiet']) == 0
    capsys.readouterr()
    path = tmp_path / 'out' / RESULTS
    table = pq.read_table(path)
    pq.write_table(table.drop_columns(['status']), path)
    before = path.read_bytes()
    assert main([str(spec), '--out', str(tmp_path / 'out'), '--quiet']) == 2
    err = capsys.readouterr().err
    assert err == (f"sweep: error: {path} lacks the column 'status' of a sweep's results table "
                   '(edited?); restore it or choose a new --out\n')
    assert path.read_bytes() == before


def test_a_folder_of_other_files_is_refused_and_left_alone(tmp_path, grid, write_spec, capsys):
    """A sweep goes on with its own folder (its results table) but never writes into one of
    other files."""
    out = tmp_path / 'mine'
    out.mkdir()
    (out / 'notes.txt').write_text('mine')
    assert main([str(write_spec(grid)), '--out', str(out), '--quiet']) == 2
    assert capsys.readouterr().err == (f"sweep: error: output directory {out} is not empty (it "
                                       "holds 'notes.txt'): a run writes only into a new or "
                                       'empty directory; choose another output directory\n')
    assert [p.name for p in out.iterdir()] == ['notes.txt']  # not even a lock file


def test_a_bad_spec_or_another_sweeps_folder_is_refused_in_one_line(tmp_path, grid, write_spec,
                                                                      capsys):
    grid['axes']['floor.mu'] = []
    assert main([str(write_spec(grid)), '--out', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err
    assert err == ("sweep: error: SPEC key 'axes.floor.mu': an axis needs at least one value, "
                   'got []\n')
    (tmp_path / 'old').mkdir()
    (tmp_path / 'old' / RESULTS).write_bytes(
        (Path(__file__).parent / 'test_sweep.py').read_bytes())
    grid['axes']['floor.mu'] = [0.005]
    assert main([str(write_spec(grid)), '--out', str(tmp_path / 'old')]) == 2
    assert capsys.readouterr().err.startswith('sweep: error: cannot read the results table')
    assert main([str(tmp_path / 'missing.yaml'), '--out', str(tmp_path / 'out')]) == 2
    assert capsys.readouterr().err.startswith('sweep: error: cannot read SPEC')
    assert not os.path.exists(tmp_path / 'out' / RESULTS)
