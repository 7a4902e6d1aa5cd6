"""Bags cut short (a copy interrupted, a disk full, a power cut) are read as far as they reached
the disk, by the analysis and by replay, which say so and name the file."""

from pathlib import Path
import random
import shutil
import subprocess
import sys

import numpy as np
import pytest

from iceskate_analysis.bag_io import read_bag
from iceskate_sim.errors import SimulationError

#: What reading one chunk of a bag's file may hold beyond another [B] (1 MB chunks).
CHUNK = 3_000_000
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


def test_a_bag_damaged_in_the_middle_is_read_up_to_the_damage_never_beyond(long_bag, tmp_path):
    """64 KiB of noise in the middle of the file, metadata.yaml present: the samples before the
    damage, no gap, and a note that says so."""
    whole = read_bag(long_bag)
    target = tmp_path / 'damaged'
    shutil.copytree(long_bag, target)
    data = bytearray((target / 'bag.mcap').read_bytes())
    middle = len(data) // 2
    data[middle:middle + 65536] = random.Random(1).randbytes(65536)
    (target / 'bag.mcap').write_bytes(bytes(data))
    damaged = read_bag(target)
    assert 0 < damaged.n_samples < whole.n_samples
    assert np.array_equal(damaged.t_ns, whole.t_ns[:damaged.n_samples])  # no gap
    assert np.array_equal(damaged.q, whole.q[:damaged.n_samples])
    note = next(n for n in damaged.notes if 'rebuilt from bag.mcap' in n)
    assert 'bag.mcap is damaged, a broken record' in note and 'nothing after it is read' in note


def test_a_bag_with_a_gap_is_read_with_a_note_of_it(long_bag, tmp_path):
    """The messages of [0.4 s, 0.5 s) left out of a copy: the samples around the gap are read
    and a note names the gap (the analysis never takes it for a whole run)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer
    target = tmp_path / 'gap.mcap'
    with (long_bag / 'bag.mcap').open('rb') as source, target.open('wb') as sink:
        writer = Writer(sink)
        writer.start(profile='ros2', library='test')
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in make_reader(source).iter_messages():
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding,
                                                            schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id],
                    dict(channel.metadata))
            if not 400_000_000 <= message.log_time < 500_000_000:
                writer.add_message(channels[channel.id], message.log_time, message.data,
                                   message.publish_time)
        writer.finish()
    data = read_bag(target)
    assert data.n_samples == read_bag(long_bag).n_samples - 100
    note = next(n for n in data.notes if n.startswith('the samples have'))
    assert 'the samples have 1 gap(s) (sampled every 0.001 s); the longest from t = 0.399000 s ' \
           'to 0.500000 s' in note


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


@pytest.mark.slow
def test_the_analysis_holds_a_few_blocks_whatever_the_length_of_the_run(tmp_path, monkeypatch):
    """The peak memory of analysing a 6 s run exceeds that of a 1 s run by the shoulders'
    angles kept whole (32 B a sample) and what a chunk of the file holds at a time (CHUNK), not
    by the samples' rows (over 4 kB each when a bag was held whole)."""
    from dataclasses import replace
    import tracemalloc

    from iceskate_analysis import coupling
    from iceskate_analysis.bag_io import BagReading
    from iceskate_bringup.runner import run
    from iceskate_bringup.scene import load_scene
    monkeypatch.setattr(coupling, 'FIGURE_ROWS', 256)
    bags = {}
    for seconds in (1.0, 6.0):
        run(replace(load_scene(TINY), duration=seconds), tmp_path / str(seconds), progress=False)
        bags[seconds] = tmp_path / str(seconds) / 'bag'
    coupling.analyse_bag(BagReading(bags[1.0]), 'warm-up', size=256)  # the lazy imports
    peaks, samples = {}, {}
    for seconds, bag in bags.items():
        tracemalloc.start()
        try:
            case = coupling.analyse_bag(BagReading(bag), 'run', size=256)
            peaks[seconds] = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        samples[seconds] = case.summary()['samples']
    extra = samples[6.0] - samples[1.0]
    assert extra >= 4500
    assert peaks[6.0] - peaks[1.0] < CHUNK + 100 * extra, (peaks, samples)
