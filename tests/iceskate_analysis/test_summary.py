"""The run summary picture: written by the headless runner (also after a fall) from the run's
trajectory in memory, the same picture ``write_summary`` redraws from the run's folder, refused
without its input files or columns, the long-run decimation keeps the peaks, and run_scene says
where to look."""

from __future__ import annotations

from dataclasses import replace
import json

import numpy as np
import pytest

from iceskate_analysis.summary import (
    MAX_POINTS,
    _decimate,
    _shoulders,
    draw_summary,
    write_summary,
)
from iceskate_bringup.runner import main, run
from iceskate_bringup.scene import load_scene, parse_scene
from iceskate_sim.errors import SimulationError
from iceskate_sim.run.metrics import Trajectory
from iceskate_sim.run.scene import scene_path

PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'


def _assert_picture(path):
    from matplotlib.image import imread
    assert path.name == 'summary.png' and path.is_file()
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    image = imread(path)
    assert image.shape[0] > 400 and image.shape[1] > 400, image.shape
    # not a blank canvas: dark (text, lines) and light (background) pixels
    grey = image[..., :3].mean(axis=2)
    assert grey.min() < 0.3 and grey.max() > 0.95


@pytest.fixture(scope='module')
def stand_run(tmp_path_factory):
    out = tmp_path_factory.mktemp('stand')
    metrics = run(replace(load_scene('stand'), duration=0.3), out, progress=False)
    return out, metrics


def test_a_short_run_writes_the_summary_picture(stand_run):
    out, metrics = stand_run
    assert not metrics['fell']
    _assert_picture(out / 'summary.png')


def test_the_picture_shows_the_head_y_against_its_target(tmp_path, saved_figures,
                                                         legends_clear):
    """The README's headline figure: a panel of the head's forward position y and its target
    [m], labelled with the error RMS of metrics.json; every legend clear of the rest."""
    t = np.linspace(0.0, 2.0, 201)
    psi = np.column_stack([0.3 * t + 0.02 * np.sin(5.0 * t), np.full_like(t, 1.69),
                           np.zeros_like(t)])
    psi_d = np.column_stack([0.3 * t, np.full_like(t, 1.695), np.zeros_like(t)])
    columns = {'t': t, 'psi': psi, 'head_target': psi_d, 'mode': np.full(t.size, 3),
               'side': (t > 1.0).astype(int), 'step_index': (t > 1.0).astype(int),
               'q': np.zeros((t.size, 18))}
    metrics = {'scene': 'skate', 'steps': 1, 'failure': None,
               'head_error_rms': {'y': 0.0493, 'z': 0.005, 'pitch': 0.001}}
    draw_summary(columns.items(), metrics, tmp_path / 'summary.png')
    fig = saved_figures['summary.png']
    (ax,) = [ax for ax in fig.axes if ax.get_legend() is not None and any(
        text.get_text().startswith('head y') for text in ax.get_legend().get_texts())]
    lines = {line.get_label(): line for line in ax.get_lines()}
    assert set(lines) == {'head y (error RMS 4.93 cm)', 'target y_d'}
    np.testing.assert_array_equal(lines['head y (error RMS 4.93 cm)'].get_ydata(), psi[:, 0])
    np.testing.assert_array_equal(lines['target y_d'].get_ydata(), psi_d[:, 0])
    assert ax.get_ylabel() == 'head forward position\ny [m]'
    assert legends_clear(fig) == 6


def test_write_summary_returns_the_path_and_redraws(stand_run, tmp_path):
    out, _metrics = stand_run
    for name in ('trajectory.npz', 'metrics.json'):
        (tmp_path / name).write_bytes((out / name).read_bytes())
    path = write_summary(tmp_path)
    assert path == tmp_path / 'summary.png'
    _assert_picture(path)


def _pixels(path):
    from matplotlib.image import imread
    return imread(path)


def assert_same_picture(a, b):
    """Two PNGs show the same picture (pixel for pixel; their bytes too, Agg being
    deterministic)."""
    np.testing.assert_array_equal(_pixels(a), _pixels(b))
    assert a.read_bytes() == b.read_bytes()


def _redrawn(out, folder):
    """``write_summary`` of a copy of run folder ``out``'s trajectory and metrics."""
    folder.mkdir()
    for name in ('trajectory.npz', 'metrics.json'):
        (folder / name).write_bytes((out / name).read_bytes())
    return write_summary(folder)


def test_a_skate_run_with_support_exchanges_is_summarised(tmp_path):
    out = tmp_path / 'run'
    metrics = run(replace(load_scene('skate'), duration=2.5), out, progress=False)
    steps = np.load(out / 'trajectory.npz')['step_index']
    assert metrics['steps'] >= 2 and np.count_nonzero(np.diff(steps)) == metrics['steps']
    _assert_picture(out / 'summary.png')
    # drawn from the trajectory in memory: the picture of the saved files
    assert_same_picture(out / 'summary.png', _redrawn(out, tmp_path / 'again'))


def test_the_runners_picture_from_memory_is_the_one_of_the_saved_run(stand_run, tmp_path):
    """The headless runner draws summary.png from the run's ``Trajectory`` in memory
    (``draw_summary``); ``write_summary`` redraws it from trajectory.npz and metrics.json."""
    out, _metrics = stand_run
    assert_same_picture(out / 'summary.png', _redrawn(out, tmp_path / 'again'))


def _trajectory(out, spill, block: int = 37) -> Trajectory:
    """A Trajectory holding run ``out``'s saved samples, extended a block at a time."""
    with np.load(out / 'trajectory.npz') as npz:
        columns = {key: npz[key] for key in npz.files}
    efforts = {key[4:]: columns.pop(key) for key in list(columns) if key.startswith('tau_')}
    trajectory = Trajectory(spill, spill_bytes=10_000 if spill is not None else 2**40)
    n = len(columns['t'])
    for start in range(0, n, block):
        rows = slice(start, min(start + block, n))
        trajectory.extend({key: value[rows] for key, value in columns.items()},
                          {key: value[rows] for key, value in efforts.items()})
    return trajectory


@pytest.mark.parametrize('spilled', [False, True])
def test_draw_summary_from_a_trajectory_draws_the_saved_runs_picture(stand_run, tmp_path,
                                                                     spilled):
    """From the columns in memory or from the spill files they were moved to (mapped one
    at a time), the same picture as from the run's folder."""
    out, metrics = stand_run
    trajectory = _trajectory(out, tmp_path / 'spill' if spilled else None)
    assert bool(list((tmp_path / 'spill').glob('.trajectory-*'))) == spilled
    path = draw_summary(trajectory.columns(), json.loads((out / 'metrics.json').read_text()),
                        tmp_path / 'summary.png')
    assert path == tmp_path / 'summary.png'
    _assert_picture(path)
    assert_same_picture(path, _redrawn(out, tmp_path / 'again'))
    # another run's metrics give another title: the metrics are drawn
    other = draw_summary(trajectory.columns(), {**metrics, 'steps': 7}, tmp_path / 'other.png')
    assert not np.array_equal(_pixels(other), _pixels(path))


@pytest.mark.parametrize('column', ['t', 'psi', 'head_target', 'mode', 'side', 'step_index', 'q'])
def test_draw_summary_names_a_missing_column_in_one_sentence(stand_run, tmp_path, column):
    out, metrics = stand_run
    columns = [(key, value) for key, value in _trajectory(out, None).columns() if key != column]
    path = tmp_path / 'summary.png'
    with pytest.raises(SimulationError) as raised:
        draw_summary(columns, metrics, path)
    assert str(raised.value) == (f'the trajectory of {tmp_path} lacks the column(s) '
                                 f"['{column}']")
    assert not path.exists()


def test_draw_summary_of_an_empty_trajectory_is_refused_in_one_sentence(stand_run, tmp_path):
    out, metrics = stand_run
    path = tmp_path / 'summary.png'
    empty = Trajectory()
    empty.extend({key: value[:0] for key, value in _trajectory(out, None).columns()
                  if not key.startswith('tau_')}, {})
    assert len(empty) == 0
    with pytest.raises(SimulationError) as raised:
        draw_summary(empty.columns(), metrics, path)
    assert str(raised.value) == f'the trajectory of {tmp_path} holds no sample'
    with pytest.raises(SimulationError) as raised:  # nothing ever added: no column at all
        draw_summary(Trajectory().columns(), metrics, path)
    message = str(raised.value)
    assert message.startswith(f'the trajectory of {tmp_path} ') and '\n' not in message
    assert not path.exists()


def test_a_run_that_ends_in_a_fall_is_summarised(tmp_path):
    """A hard push topples the standing robot; the picture is drawn from what was recorded."""
    import yaml
    raw = yaml.safe_load(scene_path('stand').read_text())
    raw |= {'duration': 2.0, 'record': {'bag': False}}
    raw['disturbances'] = [{'start': 0.2, 'duration': 0.1, 'frame': 'chest',
                            'force': [0.0, 900.0, 0.0]}]
    metrics = run(parse_scene(raw), tmp_path, progress=False)
    assert metrics['end'] == 'fell' and metrics['fell'] and metrics['sim_time_s'] < 2.0
    _assert_picture(tmp_path / 'summary.png')


def test_a_folder_without_trajectory_is_refused(stand_run, tmp_path):
    (tmp_path / 'metrics.json').write_bytes((stand_run[0] / 'metrics.json').read_bytes())
    with pytest.raises(SimulationError, match='trajectory.npz'):
        write_summary(tmp_path)
    assert not (tmp_path / 'summary.png').exists()


def test_a_trajectory_without_samples_is_refused(stand_run, tmp_path):
    (tmp_path / 'metrics.json').write_bytes((stand_run[0] / 'metrics.json').read_bytes())
    with np.load(stand_run[0] / 'trajectory.npz') as npz:
        np.savez(tmp_path / 'trajectory.npz', **{k: npz[k][:0] for k in npz.files})
    with pytest.raises(SimulationError, match='no sample'):
        write_summary(tmp_path)


def test_summary_draws_the_picture_of_a_run_that_has_none(stand_run, tmp_path, capsys):
    """``summary DIR`` (for the nodes run by hand, which draw none): the picture, its path on
    stdout; a damaged or missing run refused in one line."""
    from iceskate_analysis.summary import main
    for name in ('metrics.json', 'trajectory.npz'):
        (tmp_path / name).write_bytes((stand_run[0] / name).read_bytes())
    assert main([str(tmp_path)]) == 0
    assert capsys.readouterr().out.strip() == str(tmp_path / 'summary.png')
    _assert_picture(tmp_path / 'summary.png')
    (tmp_path / 'trajectory.npz').write_bytes(b'PK\x03\x04 cut short')
    assert main([str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f'summary: error: cannot read the run in {tmp_path}') and (
        err.count('\n') == 1 and 'Traceback' not in err)
    assert main([str(tmp_path / 'missing')]) == 2
    assert 'trajectory.npz, metrics.json missing' in capsys.readouterr().err


def test_decimation_keeps_every_extreme_and_the_time_order():
    t = np.arange(15_000) * 1e-3
    y = np.sin(2.0 * np.pi * 2.7 * t)
    y[7_777] = 5.0  # a one-sample spike
    y[123] = -4.0
    td, yd = _decimate(t, y)
    assert len(td) <= MAX_POINTS + 2
    assert np.all(np.diff(td) > 0)
    assert yd.max() == 5.0 and yd.min() == -4.0
    assert td[0] == t[0] and td[-1] == t[-1]
    short = t[:100]
    assert _decimate(short, y[:100])[0] is short


def test_run_scene_prints_the_json_then_where_the_outputs_are(tmp_path, capsys):
    out = tmp_path / 'out'
    assert main(['stand', '--out', str(out), '--duration', '0.05', '--quiet']) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)['scene'] == 'stand'  # stdout: the JSON alone
    last = captured.err.strip().splitlines()[-1]
    assert last == (f'outputs in {out}: metrics.json, events.json, trajectory.npz, bag/, '
                    'summary.png')


@pytest.mark.parametrize('chunk', [1, 7, 1000])
def test_the_shoulders_are_read_in_chunks_as_np_load_reads_them(stand_run, chunk):
    path = stand_run[0] / 'trajectory.npz'
    with np.load(path) as npz:
        q = npz['q']
    np.testing.assert_array_equal(_shoulders(path, chunk), q[:, [11, 14]])


def test_a_q_of_the_wrong_shape_is_refused(tmp_path):
    np.savez(tmp_path / 'trajectory.npz', q=np.zeros((4, 17)))
    with pytest.raises(SimulationError, match=r'q of shape \(4, 17\)'):
        _shoulders(tmp_path / 'trajectory.npz')


def test_a_run_without_the_picture_writes_the_other_outputs(tmp_path):
    metrics = run(replace(load_scene('stand'), duration=0.2), tmp_path, progress=False,
                  picture=False)
    assert not metrics['fell']
    assert {p.name for p in tmp_path.iterdir()} == {'metrics.json', 'events.json',
                                                    'trajectory.npz', 'bag', '.run.lock'}


def test_the_summary_process_draws_what_draw_summary_draws(stand_run, tmp_path):
    """The runner's picture process (forked before the run) draws the in-process picture,
    run after run, and names a missing column or an unwritable path as draw_summary does."""
    import errno

    from iceskate_analysis.summary_process import SummaryProcess
    from iceskate_sim.shutdown import process_alive
    out, metrics = stand_run
    columns = list(_trajectory(out, None).columns())
    expected = draw_summary(columns, metrics, tmp_path / 'here.png')
    painter = SummaryProcess()
    pid = painter.pid
    try:
        for k in range(2):
            assert_same_picture(painter.draw(columns, metrics, tmp_path / f'there_{k}.png'),
                                expected)
        with pytest.raises(SimulationError) as raised:
            painter.draw([(k, v) for k, v in columns if k != 'psi'], metrics,
                         tmp_path / 'summary.png')
        assert str(raised.value) == f"the trajectory of {tmp_path} lacks the column(s) ['psi']"
        with pytest.raises(OSError) as failed:
            painter.draw(columns, metrics, tmp_path / 'missing' / 'summary.png')
        assert failed.value.errno == errno.ENOENT
        assert painter.draw(columns, metrics, tmp_path / 'after.png').is_file()
    finally:
        painter.close()
    assert not process_alive(pid)


def test_the_summary_process_ignores_stop_signals_and_its_end_is_one_sentence(stand_run,
                                                                               tmp_path):
    """SIGINT to the process (a Ctrl-C reaches the whole group) leaves it drawing: the run
    decides; once it is gone, a draw says so in one sentence instead of waiting."""
    import os
    import signal

    from iceskate_analysis.summary_process import SummaryProcess
    out, metrics = stand_run
    columns = list(_trajectory(out, None).columns())
    painter = SummaryProcess()
    try:
        os.kill(painter.pid, signal.SIGINT)
        assert painter.draw(columns, metrics, tmp_path / 'a.png').is_file()
        os.kill(painter.pid, signal.SIGKILL)
        with pytest.raises(SimulationError, match=r'^the process drawing .*b\.png ended early'):
            painter.draw(columns, metrics, tmp_path / 'b.png')
    finally:
        painter.close()
    assert not (tmp_path / 'b.png').exists()


def test_the_summary_process_dies_with_its_parent(tmp_path):
    """A run killed by SIGKILL leaves no picture process behind."""
    import subprocess
    import sys
    import time

    from iceskate_sim.shutdown import process_alive
    pid_file = tmp_path / 'pid'
    code = ('import pathlib, sys, time\n'
            'from iceskate_analysis.summary_process import SummaryProcess\n'
            f'pathlib.Path({str(pid_file)!r}).write_text(str(SummaryProcess().pid))\n'
            'time.sleep(60)\n')
    parent = subprocess.Popen([sys.executable, '-c', code])
    try:
        deadline = time.monotonic() + 60.0
        while not pid_file.is_file() or not pid_file.read_text():
            assert time.monotonic() < deadline and parent.poll() is None, 'no picture process'
            time.sleep(0.05)
        pid = int(pid_file.read_text())
        assert process_alive(pid)
    finally:
        parent.kill()
        parent.wait(timeout=10.0)
    deadline = time.monotonic() + 10.0
    while process_alive(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not process_alive(pid)
