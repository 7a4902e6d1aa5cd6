"""Bags cut short (a copy interrupted, a disk full, a power cut) are read as far as they reached
the disk, by the analysis and by replay, which say so and name the file."""

from pathlib import Path
import shutil
import subprocess
import sys

import numpy as np
import pytest

from iceskate_analysis.bag_io import read_bag
from iceskate_sim.errors import SimulationError

TINY = Path(__file__).resolve().parents[1] / 'integration' / 'data' / 'tiny_stand.yaml'


@pytest.fixture(scope='module')
def long_bag(tmp_path_factory) -> Path:
    """A 1 s headless run of the tiny scene (about 4 MB: several 1 MB chunks)."""
    from dataclasses import replace

    from iceskate_bringup.runner import run
    from iceskate_bringup.scene import load_scene
    out = tmp_path_factory.mktemp('long')
    run(replace(load_scene(TINY), duration=1.0), out, progress=False)
    return out / 'bag'


def _cut(bag: Path, target: Path, fraction: float, metadata: bool = True) -> Path:
    shutil.copytree(bag, target)
    mcap = target / 'bag.mcap'
    with mcap.open('r+b') as stream:
        stream.truncate(int(mcap.stat().st_size * fraction))
    if not metadata:
        (target / 'metadata.yaml').unlink()
    return target


def test_a_cut_bag_is_read_up_to_its_last_complete_chunk(long_bag, tmp_path):
    whole = read_bag(long_bag)
    cut = read_bag(_cut(long_bag, tmp_path / 'cut', 0.6))
    assert 0.3 * whole.n_samples < cut.n_samples < 0.7 * whole.n_samples
    assert np.array_equal(cut.q, whole.q[:cut.n_samples])
    assert np.array_equal(cut.t_ns, whole.t_ns[:cut.n_samples])
    note = cut.notes[0]
    assert 'its index cannot be read' in note and 'rebuilt from bag.mcap' in note, note
    assert 'the rest did not reach the disk' in note
    assert cut.scene_name == 'tiny_stand'  # the metadata's custom data is still read


def test_a_bag_with_no_complete_chunk_is_refused_naming_it(long_bag, tmp_path):
    bag = _cut(long_bag, tmp_path / 'stub', 0.1, metadata=False)
    with pytest.raises(SimulationError, match=f'cannot read bag {bag}: it has no metadata.yaml'
                                              '.*no complete chunk'):
        read_bag(bag)


@pytest.mark.ros
@pytest.mark.parametrize('fraction, metadata, code, expected', [
    (0.6, True, 0, 'its index cannot be read'),
    (0.6, False, 0, 'it has no metadata.yaml'),
    (0.1, False, 1, 'replay: error: cannot read bag '),
])
def test_replay_reads_a_cut_bag_and_says_how_much(long_bag, tmp_path, ros_env, fraction,
                                                  metadata, code, expected):
    pytest.importorskip('rclpy')
    bag = _cut(long_bag, tmp_path / 'cut', fraction, metadata)
    result = subprocess.run([sys.executable, '-m', 'iceskate_analysis.replay', str(bag),
                             '--fast'], env=ros_env, capture_output=True, text=True, timeout=60)
    assert result.returncode == code, result.stderr
    assert expected in result.stderr and str(bag) in result.stderr, result.stderr
    assert 'Traceback' not in result.stderr
    if code == 0:
        assert 'rebuilt from bag.mcap' in result.stderr
