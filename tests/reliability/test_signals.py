"""Every way a run is ended from outside leaves a readable bag, metrics with the reason, one line
and the conventional exit code, and no process behind: SIGINT, SIGTERM and SIGHUP to run_scene's
PID or to its process group at a random (seeded) moment of the run, headless and through the ROS
graph; ``timeout``; SIGKILL (the bag is rebuilt from what reached the disk)."""

import json
import random
import shutil
import signal
import time

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from iceskate_analysis.bag_io import read_bag

pytestmark = pytest.mark.slow

SIGNALS = {'SIGINT': signal.SIGINT, 'SIGTERM': signal.SIGTERM, 'SIGHUP': signal.SIGHUP}
CASES = [(name, group) for name in SIGNALS for group in (False, True)]


def _delay(*key: object) -> float:
    """A random moment [s] after the run's first chunk, seeded per case."""
    return random.Random(repr(key)).uniform(0.0, 1.2)


def _messages(bag) -> int:
    """Messages of /joint_states in a bag, read by rosbags' AnyReader (needs its metadata)."""
    with AnyReader([bag]) as reader:
        states = [c for c in reader.connections if c.topic == '/joint_states']
        return sum(1 for _ in reader.messages(connections=states))


def _check_interrupted(run, code: int, stderr: str, name: str) -> None:
    """What an interrupted run leaves: exit code, one line, metrics, a bag every reader takes."""
    signum = SIGNALS[name]
    assert code == 128 + signum, stderr
    assert 'Traceback' not in stderr, stderr
    lines = [line for line in stderr.splitlines() if line.startswith('run_scene:')
             and not line.startswith('run_scene: controllers: ')]  # the run's start line
    assert len(lines) == 1 and lines[0].startswith(f'run_scene: interrupted by {name} at t='), \
        stderr
    metrics = run.metrics()
    assert metrics['interrupted'] and metrics['end'] == 'interrupted' and not metrics['fell'], \
        metrics
    assert metrics['failure'].startswith(f'interrupted by {name} at t='), metrics['failure']
    samples = len(np.load(run.out / 'trajectory.npz')['t'])
    assert _messages(run.out / 'bag') == samples > 0
    data = read_bag(run.out / 'bag')  # what coupling_analysis reads
    assert data.n_samples == samples and not any('rebuilt' in n for n in data.notes)


@pytest.mark.parametrize('name, group', CASES)
def test_headless_run_ends_cleanly_on_a_signal(launch, proc, name, group):
    # still running when the signal comes (the simulator runs tens of times real time)
    run = launch(str(proc.TINY), '--duration', '3600')
    run.wait_running()
    time.sleep(_delay('headless', name, group))
    run.signal(SIGNALS[name], group)
    code, _stdout, stderr = run.communicate()
    _check_interrupted(run, code, stderr, name)
    proc.assert_all_gone(run.seen)


def test_a_signal_ends_a_run_of_costly_periods_at_once(launch, proc, tmp_path):
    """Periods of thousands of steps each (the smallest integrator step): the blocks of periods
    shrink to their cost, so the signal is answered within a fraction of a second, not after a
    block of a thousand periods (tens of seconds here)."""
    import yaml

    from iceskate_sim.yaml_io import read_yaml
    raw = read_yaml(proc.TINY, 'scene')
    raw['integrator'] = {'method': 'rk4', 'step': 1.0e-6}
    scene = tmp_path / 'tiny_step.yaml'
    scene.write_text(yaml.safe_dump(raw))
    run = launch(str(scene), '--duration', '3600')
    proc.wait_until(lambda: run.watch() or (run.out / 'bag' / 'bag.mcap').is_file(), 60.0,
                    'the run to start')
    time.sleep(1.0)
    run.signal(signal.SIGINT, False)
    code, _stdout, stderr = run.communicate(timeout=5.0)
    assert code == 128 + signal.SIGINT, stderr
    assert run.metrics()['failure'].startswith('interrupted by SIGINT at t=')
    proc.assert_all_gone(run.seen)


def test_timeout_ends_a_headless_run_cleanly(launch, proc):
    """``timeout`` sends SIGTERM to the whole group (the bag writer too)."""
    if shutil.which('timeout') is None:
        pytest.skip('no timeout command')
    run = launch(str(proc.TINY), '--duration', '3600', prefix=('timeout', '5'))
    proc.wait_until(lambda: run.watch() or run.process.poll() is not None, 60.0, 'the end')
    code, _stdout, stderr = run.communicate()
    assert code == 124, stderr  # timeout's own code once it had to stop the command
    metrics = run.metrics()
    assert metrics['failure'].startswith('interrupted by SIGTERM at t=') and \
        metrics['interrupted'], metrics
    assert _messages(run.out / 'bag') == len(np.load(run.out / 'trajectory.npz')['t']) > 0
    assert stderr.count('run_scene: interrupted by SIGTERM') == 1 and 'Traceback' not in stderr
    proc.assert_all_gone(run.seen)


def test_sigkilled_run_bag_is_rebuilt_from_the_mcap_file(launch, proc, tmp_path, capsys):
    """SIGKILL to the whole group (the writer dies too): no metadata.yaml, no index; the
    project's reader rebuilds the run from the complete chunks, coupling_analysis says so."""
    from iceskate_analysis.coupling_cli import main as coupling_analysis
    run = launch(str(proc.TINY), '--duration', '60')
    run.wait_running()
    proc.wait_until(lambda: (run.out / 'bag' / 'bag.mcap').stat().st_size > 3 << 20, 60.0,
               'three chunks')
    run.signal(signal.SIGKILL, group=True)
    code, _stdout, _stderr = run.communicate()
    assert code == -signal.SIGKILL
    proc.assert_all_gone(run.seen)
    bag = run.out / 'bag'
    assert not (bag / 'metadata.yaml').exists() and not (run.out / 'metrics.json').exists()
    data = read_bag(run.out)
    assert data.n_samples > 500 and 'rebuilt from bag.mcap' in data.notes[0], data.notes
    assert np.all(np.diff(data.t_ns) == 1_000_000)  # every sample of the complete chunks
    assert coupling_analysis([str(bag), '--out', str(tmp_path / 'analysis'), '--quiet']) == 0
    assert 'rebuilt from bag.mcap' in capsys.readouterr().err
    summary = json.loads((tmp_path / 'analysis' / 'summary.json').read_text())
    (case,) = summary['cases'].values()
    assert case['samples'] == data.n_samples


def test_sigkill_to_run_scene_alone_still_closes_the_bag(launch, proc):
    """The bag writer notices its parent's death (parent-death signal) and closes the bag."""
    run = launch(str(proc.TINY), '--duration', '60')
    run.wait_running()
    run.signal(signal.SIGKILL, group=False)
    run.communicate()
    proc.assert_all_gone(run.seen)
    assert (run.out / 'bag' / 'metadata.yaml').is_file()
    assert _messages(run.out / 'bag') > 0


@pytest.mark.ros
@pytest.mark.parametrize('name, group', CASES)
def test_ros_run_ends_cleanly_on_a_signal_and_stops_its_nodes(launch, proc, name, group):
    pytest.importorskip('rclpy')
    run = launch(str(proc.TINY), '--ros', '--duration', '8')
    run.wait_running()
    time.sleep(_delay('ros', name, group))
    run.signal(SIGNALS[name], group)
    nodes = dict(run.seen)
    assert len(nodes) >= 4  # simulator, its bag writer, visual_lifting, gait_manager
    code, _stdout, stderr = run.communicate()
    _check_interrupted(run, code, stderr, name)
    proc.assert_all_gone(nodes)


@pytest.mark.ros
def test_sigkilled_ros_launcher_takes_its_nodes_along(launch, proc):
    """run_scene --ros killed outright: its nodes get the parent-death signal, the simulator
    ends the run cleanly (saying why) and nothing is left."""
    pytest.importorskip('rclpy')
    run = launch(str(proc.TINY), '--ros', '--duration', '30')
    run.wait_running()
    run.signal(signal.SIGKILL, group=False)
    nodes = dict(run.seen)
    run.communicate()
    proc.assert_all_gone(nodes)
    assert not [p for p in proc.descendants(run.pid) if proc.alive(p)]
    metrics = run.metrics()
    assert metrics['interrupted'] and 'its parent process' in metrics['failure'], metrics
    assert _messages(run.out / 'bag') == len(np.load(run.out / 'trajectory.npz')['t']) > 0


@pytest.mark.parametrize('name', ['SIGINT', 'SIGTERM'])
def test_a_sweep_of_a_million_runs_ends_at_once_on_a_signal(tmp_path, proc, name):
    """A SPEC whose axis has the most values a SPEC may have (10**6 runs): the sweep checks
    their scenes for many minutes before its first run; a signal meanwhile ends it within
    seconds, in one line, with nothing written and no process left."""
    import os
    import subprocess
    import sys

    import yaml
    spec = tmp_path / 'million.yaml'
    spec.write_text(yaml.safe_dump({
        'study': 'million', 'scene': 'skate', 'overrides': {'duration': 0.01},
        'axes': {'floor.mu': {'linspace': [0.004, 0.02, 1_000_000]}}, 'metrics': ['steps']}))
    out = tmp_path / 'out'
    sweep = subprocess.Popen([sys.executable, '-m', 'iceskate_study.sweep', str(spec), '--out',
                              str(out), '--workers', '1', '--quiet'],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             start_new_session=True)
    try:
        time.sleep(3.0)  # past the imports: among the scenes' checks
        assert sweep.poll() is None, sweep.communicate()
        seen = proc.descendants(sweep.pid)
        sent = time.monotonic()
        sweep.send_signal(SIGNALS[name])
        _stdout, stderr = sweep.communicate(timeout=10.0)
        took = time.monotonic() - sent
    finally:
        if sweep.poll() is None:
            os.killpg(sweep.pid, signal.SIGKILL)
            sweep.communicate()
    assert sweep.returncode == 128 + SIGNALS[name], stderr
    assert took < 2.5, took
    assert stderr == (f'sweep: interrupted by {name} before any run started; the same command '
                      'resumes\n')
    proc.assert_all_gone(seen)
    assert not (out / 'results.parquet').exists()
