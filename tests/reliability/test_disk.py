"""A full disk: the run ends with one sentence naming the file it could not write, its
metrics.json written (the room for it is kept from the start) with ``end: io_error``, its bag
closed with the chunks written whole and readable, no process left and no traceback. The disk
is a small tmpfs (mounting one needs root, as in CI; elsewhere these tests skip and say why),
or, for the trajectory, a write that fails as a full disk does."""

from collections.abc import Callable, Iterator
import errno
import json
from pathlib import Path
import subprocess

import pytest
from rosbags.highlevel import AnyReader
import yaml

from iceskate_sim.recording.bag_types import make_typestore

#: A disk that a 2-minute skate run fills in its first seconds (its bag alone: 15 MB per 15 s).
SMALL_DISK = '12m'


@pytest.fixture
def disk(tmp_path: Path) -> Iterator[Callable[[str], Path]]:
    """``disk(size)``: a new tmpfs of ``size`` (e.g. '12m'), unmounted at the end."""
    mounted: list[Path] = []

    def mount(size: str) -> Path:
        where = tmp_path / f'disk{len(mounted)}'
        where.mkdir()
        done = subprocess.run(['mount', '-t', 'tmpfs', '-o', f'size={size}', 'tmpfs',
                               str(where)], capture_output=True, text=True, timeout=30)
        if done.returncode != 0:
            pytest.skip(f'a tmpfs cannot be mounted here (needs root): {done.stderr.strip()}')
        mounted.append(where)
        return where
    try:
        yield mount
    finally:
        for where in mounted:
            subprocess.run(['umount', '-l', str(where)], capture_output=True, timeout=30)


def _bag_is_whole(bag: Path) -> int:
    """The bag's messages, read by rosbags, equal what its metadata.yaml counts; returns it."""
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    with AnyReader([bag], default_typestore=make_typestore()) as reader:
        read = sum(1 for _ in reader.messages())
    assert read == info['message_count'] > 500
    return read


def test_a_disk_that_fills_up_ends_the_run_with_metrics_and_a_readable_bag(disk, launch, proc):
    out = disk(SMALL_DISK) / 'run'
    run = launch('skate', '--duration', '120', out=out)
    code, stdout, stderr = run.communicate(timeout=120)
    assert code == 1, stderr
    (line,) = [line for line in stderr.splitlines() if 'error' in line]
    assert line.startswith('run_scene: error: ') and str(out) in line, stderr
    assert 'No space left on device' in line or 'no space left on device' in line, line
    assert 'Traceback' not in stderr
    metrics = run.metrics()
    assert metrics['end'] == 'io_error' and not metrics['fell']
    assert 0.0 < metrics['sim_time_s'] < 120.0  # ended early, at once
    assert json.loads((out / 'events.json').read_text())
    _bag_is_whole(out / 'bag')
    assert not [path for path in out.rglob('*.room')]  # the disk kept is given back
    proc.assert_all_gone(run.seen)


@pytest.mark.ros
def test_a_disk_that_fills_up_under_the_graph_ends_the_run_as_headless_does(disk, launch,
                                                                            proc):
    """The node graph (``--ros``): the simulator ends the run with the disk named, its
    metrics ``io_error`` and its bag readable, as a headless run does."""
    pytest.importorskip('rclpy')
    out = disk('4m') / 'run'
    run = launch('skate', '--ros', '--duration', '120', out=out)
    code, stdout, stderr = run.communicate(timeout=300)
    assert code == 1, stderr
    (line,) = [line for line in stderr.splitlines() if 'error' in line]
    assert line.startswith('run_scene: error: ') and str(out) in line, stderr
    assert 'No space left on device' in line or 'no space left on device' in line, line
    assert 'Traceback' not in stderr
    metrics = run.metrics()
    assert metrics['end'] == 'io_error' and not metrics['fell']
    assert 0.0 < metrics['sim_time_s'] < 120.0
    assert json.loads((out / 'events.json').read_text())
    _bag_is_whole(out / 'bag')
    assert not [path for path in out.rglob('*.room')]
    proc.assert_all_gone(run.seen)


def test_a_disk_without_room_for_the_metrics_is_refused_before_the_run(disk, launch):
    out = disk('1m') / 'run'
    run = launch('stand', '--duration', '1', out=out)
    code, _, stderr = run.communicate(timeout=60)
    assert code == 1 and 'Traceback' not in stderr
    assert f'output directory {out} has no room for the metrics' in stderr, stderr
    assert not (out / 'metrics.json').exists() and not list(out.rglob('*.room'))


def test_a_trajectory_that_cannot_be_written_ends_the_run_as_an_io_error(tmp_path, monkeypatch,
                                                                        capsys):
    """The disk fills up as trajectory.npz is written: one line, metrics.json says so, the
    partial file is gone and the bag is whole."""
    from iceskate_bringup.runner import main
    from iceskate_sim.run.metrics import Trajectory

    def full(self, path: Path) -> None:
        path.write_bytes(b'PK\x03\x04 partial')
        raise OSError(errno.ENOSPC, 'No space left on device')
    monkeypatch.setattr(Trajectory, 'save', full)
    out = tmp_path / 'run'
    assert main(['stand', '--out', str(out), '--quiet', '--duration', '0.5']) == 1
    err = capsys.readouterr().err
    assert (f'run_scene: error: cannot write {out / "trajectory.npz"}: no space left on device'
            in err) and 'Traceback' not in err
    metrics = json.loads((out / 'metrics.json').read_text())
    assert metrics['end'] == 'io_error' and 'trajectory.npz' in metrics['failure']
    assert not (out / 'trajectory.npz').exists() and not (out / 'summary.png').exists()
    _bag_is_whole(out / 'bag')
