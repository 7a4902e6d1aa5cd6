"""Bags cut short (a copy interrupted, a disk full, a power cut) are read as far as they reached
the disk, by the analysis and by replay, which say so and name the file."""

from collections.abc import Callable
import os
from pathlib import Path
import random
import re
import shutil
import signal
import subprocess
import sys
import threading
import time

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


def _rewrite(bag: Path, target: Path, log_time: Callable[[int], int | None]) -> Path:
    """An .mcap copy of ``bag``'s messages at ``log_time(their log time)`` [ns] (None: left
    out), without metadata.yaml."""
    from mcap.reader import make_reader
    from mcap.writer import Writer
    with (bag / 'bag.mcap').open('rb') as source, target.open('wb') as sink:
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
            when = log_time(message.log_time)
            if when is not None:
                writer.add_message(channels[channel.id], when, message.data, when)
        writer.finish()
    return target


def _gap_bag(bag: Path, target: Path) -> Path:
    """A copy of ``bag`` without the messages of [0.4 s, 0.5 s)."""
    return _rewrite(bag, target, lambda t: None if 400_000_000 <= t < 500_000_000 else t)


def test_a_bag_with_a_gap_is_read_with_a_note_of_it(long_bag, tmp_path):
    """The messages of [0.4 s, 0.5 s) left out of a copy: the samples around the gap are read
    and a note names the gap (the analysis never takes it for a whole run)."""
    data = read_bag(_gap_bag(long_bag, tmp_path / 'gap.mcap'))
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
    (0.1, False, 2, 'replay: error: cannot read bag '),
])
def test_replay_reads_a_cut_bag_and_says_how_much(long_bag, tmp_path, ros_env, fraction,
                                                  metadata, code, expected):
    """The note is the analysis's, word for word."""
    pytest.importorskip('rclpy')
    bag = _cut(long_bag, tmp_path / 'cut', fraction, metadata)
    result = subprocess.run([sys.executable, '-m', 'iceskate_analysis.replay', str(bag),
                             '--fast'], env=ros_env, capture_output=True, text=True, timeout=60)
    assert result.returncode == code, result.stderr
    assert expected in result.stderr and str(bag) in result.stderr, result.stderr
    assert 'Traceback' not in result.stderr
    if code == 0:
        note = read_bag(bag).notes[0]
        assert 'rebuilt from bag.mcap' in note
        assert f'replay: note: {note}' in result.stderr.splitlines(), result.stderr


@pytest.mark.ros
def test_replay_notes_a_gap_as_the_analysis_does(long_bag, tmp_path, ros_env):
    pytest.importorskip('rclpy')
    bag = _gap_bag(long_bag, tmp_path / 'gap.mcap')
    result = subprocess.run([sys.executable, '-m', 'iceskate_analysis.replay', str(bag),
                             '--fast'], env=ros_env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    data = read_bag(bag)
    gap = next(n for n in data.notes if n.startswith('the samples have 1 gap(s)'))
    notes = [line for line in result.stderr.splitlines() if line.startswith('replay: note: ')]
    assert notes == [f'replay: note: {data.notes[0]}', f'replay: note: {gap}'], result.stderr


@pytest.mark.ros
@pytest.mark.parametrize('tool, given, kind', [
    ('coupling_analysis', 'run', 'fifo'), ('coupling_analysis', 'file', 'fifo'),
    ('coupling_analysis', 'bag', 'device'), ('replay', 'run', 'fifo'), ('replay', 'file', 'fifo'),
])
def test_a_bag_file_that_is_no_regular_file_is_refused_at_once(tmp_path, ros_env, tool, given,
                                                               kind):
    """Opening a FIFO blocks until a writer comes and /dev/zero never ends: a bag's files are
    looked at before any is opened (``bag_io.open_bag``, which ``view`` reads through too), and
    one that is not a regular file is refused in one line, exit 2."""
    if tool == 'replay':
        pytest.importorskip('rclpy')
    bag = tmp_path / 'run' / 'bag'
    bag.mkdir(parents=True)
    if kind == 'fifo':
        os.mkfifo(bag / 'bag.mcap')
    else:
        (bag / 'bag.mcap').symlink_to('/dev/zero')
    path = {'run': tmp_path / 'run', 'bag': bag, 'file': bag / 'bag.mcap'}[given]
    command = ([sys.executable, '-m', 'iceskate_analysis.coupling_cli', str(path), '--out',
                str(tmp_path / 'out'), '--quiet'] if tool == 'coupling_analysis' else
               [sys.executable, '-m', 'iceskate_analysis.replay', str(path), '--fast'])
    result = subprocess.run(command, env=ros_env, capture_output=True, text=True, timeout=60)
    what = 'a named pipe (FIFO)' if kind == 'fifo' else 'a character device'
    assert result.returncode == 2, result.stderr
    assert result.stderr.splitlines() == [f'{tool}: error: bag file {bag / "bag.mcap"} is '
                                          f'{what}, not a regular file, and is not read']


@pytest.mark.ros
@pytest.mark.parametrize('rate', ['1e-9', 'nan', '1e9'])
def test_replay_refuses_a_rate_outside_its_range_in_one_line(long_bag, ros_env, rate):
    """1e-9 would pace a 1 ms step to 11 days."""
    pytest.importorskip('rclpy')
    result = subprocess.run([sys.executable, '-m', 'iceskate_analysis.replay', str(long_bag),
                             '--rate', rate], env=ros_env, capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 2, result.stderr
    assert result.stderr.splitlines() == [f'replay: error: --rate {float(rate):g} is outside '
                                          '0.01 to 100 (--fast plays without pacing)']


@pytest.mark.ros
@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_replay_ends_within_a_second_on_a_signal_in_a_long_wait(long_bag, tmp_path, ros_env,
                                                                proc, signum):
    """The messages after 0.05 s an hour later: replay waits for them at the recorded pace and
    a signal ends the wait within a second: exit 128 + its number, one line, nothing left."""
    pytest.importorskip('rclpy')
    bag = _rewrite(long_bag, tmp_path / 'late.mcap',
                   lambda t: t if t < 50_000_000 else t + 3600 * 10**9)
    replay = subprocess.Popen([sys.executable, '-m', 'iceskate_analysis.replay', str(bag)],
                              env=ros_env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              text=True, start_new_session=True)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(replay.stderr), daemon=True)
    reader.start()
    try:
        # the notes (the hour is a gap) come once the bag is open, right before the playing
        proc.wait_until(lambda: replay.poll() is not None or any(
            'the samples have 1 gap(s)' in line for line in lines), 60.0, 'the notes')
        time.sleep(1.0)  # the first 0.05 s played: waiting for the hour
        assert replay.poll() is None, lines
        children = proc.descendants(replay.pid)  # (replay itself is waited for)
        sent = time.monotonic()
        replay.send_signal(signum)
        code = replay.wait(timeout=10.0)
        took = time.monotonic() - sent
        reader.join(timeout=10.0)
    finally:
        if replay.poll() is None:
            os.killpg(replay.pid, signal.SIGKILL)
            replay.wait(timeout=10.0)
    assert code == 128 + signum and took < 1.0, (code, took, lines)
    proc.assert_all_gone(children, timeout=5.0)
    name = signal.Signals(signum).name
    ends = [line for line in lines if line.startswith('replay: interrupted')]
    assert len(ends) == 1 and not any('Traceback' in line for line in lines), lines
    match = re.fullmatch(rf'replay: interrupted by {name} at t=(\S+) s \((\d+) of (\d+) '
                         r'messages replayed\)\n', ends[0])
    assert match and 0.04 <= float(match[1]) < 0.05 and int(match[2]) < int(match[3]), ends


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
