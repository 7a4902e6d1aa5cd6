"""The run summary picture: written by the headless runner (also after a fall), refused without
its input files, the long-run decimation keeps the peaks, and run_scene says where to look."""

from __future__ import annotations

from dataclasses import replace
import json

import numpy as np
import pytest

from iceskate_analysis.summary import MAX_POINTS, _decimate, _shoulders, write_summary
from iceskate_bringup.runner import main, run
from iceskate_bringup.scene import load_scene, parse_scene, scene_path
from iceskate_sim.errors import SimulationError

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


def test_write_summary_returns_the_path_and_redraws(stand_run, tmp_path):
    out, _metrics = stand_run
    for name in ('trajectory.npz', 'metrics.json'):
        (tmp_path / name).write_bytes((out / name).read_bytes())
    path = write_summary(tmp_path)
    assert path == tmp_path / 'summary.png'
    _assert_picture(path)


def test_a_skate_run_with_support_exchanges_is_summarised(tmp_path):
    metrics = run(replace(load_scene('skate'), duration=2.5), tmp_path, progress=False)
    steps = np.load(tmp_path / 'trajectory.npz')['step_index']
    assert metrics['steps'] >= 2 and np.count_nonzero(np.diff(steps)) == metrics['steps']
    _assert_picture(tmp_path / 'summary.png')


def test_a_run_that_ends_in_a_fall_is_summarised(tmp_path):
    """A hard push topples the standing robot; the picture is drawn from what was recorded."""
    import yaml
    raw = yaml.safe_load(scene_path('stand').read_text())
    raw |= {'duration': 2.0, 'record': {'bag': False}}
    raw['disturbances'] = [{'start': 0.2, 'duration': 0.1, 'frame': 'chest',
                            'force': [0.0, 900.0, 0.0]}]
    metrics = run(parse_scene(raw), tmp_path, progress=False)
    assert metrics['fell'] and metrics['sim_time_s'] < 2.0
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
                                                    'trajectory.npz', 'bag'}
