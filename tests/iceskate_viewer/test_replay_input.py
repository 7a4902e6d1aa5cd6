"""``view`` on runs it must not take as they are: times that are zero, NaN, negative or go
back (one sentence, exit 2), a trajectory far longer than a slider shows (thinned, in bounded
memory, said in one line), and a bag rebuilt after a killed run (its reading's note said, as
``coupling_analysis`` says it)."""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest

from hostile import long_trajectory
from iceskate_viewer.replay import MAX_FRAMES, load_run, main


def _with_times(skate_run: pathlib.Path, target: pathlib.Path, t: np.ndarray) -> pathlib.Path:
    """A copy of ``skate_run``'s trajectory.npz in ``target`` with its times ``t``."""
    target.mkdir()
    with np.load(skate_run / 'trajectory.npz') as data:
        np.savez(target / 'trajectory.npz', **{**{name: data[name] for name in data.files},
                                                't': t})
    return target


@pytest.mark.timeout(60)
@pytest.mark.parametrize('case, expected', [
    ('zero', 'time t does not increase: sample 1 is at 0 s after 0 s'),
    ('nan', 'time t of sample 7 is nan (not a finite number)'),
    ('inf', 'time t of sample 0 is inf (not a finite number)'),
    ('back', 'time t does not increase: sample 600 is at 0.5 s after 0.599 s'),
    ('repeat', 'time t does not increase: sample 3 is at 0.002 s after 0.002 s'),
    ('negative', 'time t starts at -1 s (before 0 s)'),
    ('text', 'column t holds <U1 of shape (1200,)'),
])
def test_times_a_slider_cannot_take_are_one_sentence(skate_run, tmp_path, capsys, case,
                                                     expected):
    with np.load(skate_run / 'trajectory.npz') as data:
        t = data['t'].copy()
    t = {'zero': np.zeros_like(t), 'nan': np.where(np.arange(len(t)) == 7, np.nan, t),
         'inf': np.where(np.arange(len(t)) == 0, np.inf, t),
         'back': np.concatenate([t[:600], t[600:] - 0.1]),
         'repeat': np.concatenate([t[:3], t[2:-1]]), 'negative': t - 1.0,
         'text': np.full(len(t), 'x')}[case]
    run_dir = _with_times(skate_run, tmp_path / case, t)
    assert main([str(run_dir), '--port', '0']) == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines() == [err.strip()] and 'Traceback' not in err
    assert err.startswith(f'view: error: {run_dir / "trajectory.npz"}') and expected in err, err


@pytest.mark.timeout(60)
@pytest.mark.parametrize('column, shape', [('q', (1200, 17)), ('mode', (1199,)),
                                           ('head_target', (1200,))])
def test_a_column_of_the_wrong_shape_is_one_sentence(skate_run, tmp_path, capsys, column,
                                                     shape):
    run_dir = tmp_path / column
    run_dir.mkdir()
    with np.load(skate_run / 'trajectory.npz') as data:
        columns = {name: data[name] for name in data.files}
    columns[column] = np.zeros(shape)
    np.savez(run_dir / 'trajectory.npz', **columns)
    assert main([str(run_dir), '--port', '0']) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and f'column {column} holds' in err, err


@pytest.mark.timeout(60)
@pytest.mark.parametrize('column, code', [('mode', 0), ('mode', 21), ('side', 2), ('pivot', -1),
                                          ('pivot', 1.5)])
def test_a_code_the_view_cannot_draw_is_one_sentence(skate_run, tmp_path, capsys, column, code):
    run_dir = tmp_path / column
    run_dir.mkdir()
    with np.load(skate_run / 'trajectory.npz') as data:
        columns = {name: data[name] for name in data.files}
    columns[column] = np.where(np.arange(len(columns['t'])) == 700, code, columns[column])
    np.savez(run_dir / 'trajectory.npz', **columns)
    assert main([str(run_dir), '--port', '0']) == 2
    err = capsys.readouterr().err
    assert err.strip() == (f'view: error: {run_dir / "trajectory.npz"}: column {column} holds '
                           f'codes the view does not know: {code:g}'), err


@pytest.mark.timeout(60)
def test_a_single_sample_at_zero_is_shown(skate_run, tmp_path):
    with np.load(skate_run / 'trajectory.npz') as data:
        run_dir = tmp_path / 'one'
        run_dir.mkdir()
        np.savez(run_dir / 'trajectory.npz', **{name: data[name][:1] for name in data.files})
    run = load_run(run_dir)
    assert run.t.tolist() == [0.0] and run.columns['q'].shape == (1, 18)


#: Samples of the long trajectory: 3 M (~600 MB as arrays, a few MB deflated on disk).
LONG = 3_000_000
#: What reading it may add to the peak memory of the process [MB]: the frames kept
#: (MAX_FRAMES x ~200 bytes) and the chunks read.
LONG_MB = 120


@pytest.mark.timeout(120)
def test_a_long_trajectory_is_thinned_in_bounded_memory(tmp_path):
    """3 M samples: ``view`` keeps ``MAX_FRAMES`` of them, evenly spaced in time, says so in one
    line, and its peak memory grows by a fraction of the ~600 MB the arrays would take (a
    process of its own: ``ru_maxrss`` is its peak)."""
    run_dir = tmp_path / 'long'
    run_dir.mkdir()
    long_trajectory(run_dir / 'trajectory.npz', LONG)
    probe = (
        'import json, resource, sys\n'
        'from iceskate_viewer.replay import load_run\n'
        'before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n'
        'run = load_run(sys.argv[1])\n'
        'after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n'
        'print(json.dumps({"grown_mb": (after - before) / 1024, "frames": len(run.t),\n'
        '                  "first": float(run.t[0]), "last": float(run.t[-1]),\n'
        '                  "spread": float((run.t[1:] - run.t[:-1]).max()\n'
        '                                  - (run.t[1:] - run.t[:-1]).min()),\n'
        '                  "q": list(run.columns["q"].shape)}))\n')
    done = subprocess.run([sys.executable, '-c', probe, str(run_dir)], capture_output=True,
                          text=True, timeout=90, env={**os.environ, 'OMP_NUM_THREADS': '1'})
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert out['frames'] == MAX_FRAMES and out['q'] == [MAX_FRAMES, 18]
    assert out['first'] == 0.0 and out['last'] == pytest.approx(1e-3 * (LONG - 1))
    assert out['spread'] <= 1.5e-3  # evenly spaced, to a sample (1 ms)
    assert out['grown_mb'] < LONG_MB, out
    (line,) = done.stderr.strip().splitlines()
    assert line == (f'view: {run_dir / "trajectory.npz"}: {LONG} samples over 3000 s; showing '
                    f'{MAX_FRAMES} of them (at most {MAX_FRAMES}), evenly spaced in time')


@pytest.mark.timeout(120)
def test_a_bag_rebuilt_after_a_killed_run_is_said(skate_run, tmp_path, capsys):
    """No metadata.yaml (the run never closed its bag): the view reads it and says the note
    of the bag's reading (the same note ``coupling_analysis`` prints)."""
    from iceskate_analysis.bag_io import read_bag
    run_dir = tmp_path / 'killed'
    shutil.copytree(skate_run / 'bag', run_dir / 'bag')
    (run_dir / 'bag' / 'metadata.yaml').unlink()
    notes = read_bag(run_dir / 'bag').notes
    assert any('rebuilt' in note for note in notes)
    capsys.readouterr()
    run = load_run(run_dir)
    assert len(run.t) > 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f'view: {run_dir}: note: {note}' for note in notes]
