"""``coupling_analysis``, ``summary`` and ``mode_coverage``, run as commands on a real 20 s run,
end on SIGINT or SIGTERM promptly: exit 128 + the signal's number, one line on stderr, no
traceback, and nothing in their output folder (every file is renamed into it once all are
complete). Every wait has a deadline."""

from __future__ import annotations

import os
from pathlib import Path
import re
import shutil
import signal
import subprocess
import sys
import time
from typing import Any

import pytest

pytestmark = pytest.mark.slow


@pytest.fixture(scope='module')
def skate_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``run_scene skate --duration 20``: its output folder (a bag of 5000 samples, about 5 s
    of analysis)."""
    out = tmp_path_factory.mktemp('skate') / 'run'
    subprocess.run([sys.executable, '-m', 'iceskate_bringup.runner', 'skate', '--duration',
                    '20', '--out', str(out), '--quiet'], check=True, capture_output=True,
                   timeout=240)
    return out


def _wait_until(done: Any, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not done():
        if time.monotonic() > deadline:
            pytest.fail(f'timed out after {timeout} s waiting for {what}')
        time.sleep(0.01)


def _has_open(pid: int, path: Path) -> bool:
    """Whether process ``pid`` has the file ``path`` open."""
    try:
        fds = list(Path(f'/proc/{pid}/fd').iterdir())
    except OSError:
        return False
    for fd in fds:
        try:
            if os.readlink(fd) == str(path):
                return True
        except OSError:  # closed meanwhile
            continue
    return False


def _catches_sighup(pid: int) -> bool:
    """Whether process ``pid`` has a handler for SIGHUP (``StopRequest`` is installed)."""
    try:
        status = Path(f'/proc/{pid}/status').read_text()
    except OSError:
        return False
    caught = re.search(r'^SigCgt:\s*([0-9a-f]+)$', status, re.MULTILINE)
    return caught is not None and bool(int(caught[1], 16) >> (signal.SIGHUP - 1) & 1)


def _interrupt(command: list[str], signum: int, started: Any) -> tuple[int, float, str, str]:
    """Start ``command`` (a session of its own), send ``signum`` once ``started(process)``:
    (exit code, seconds from the signal to the end, stdout, stderr)."""
    process = subprocess.Popen([sys.executable, '-m', *command], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        _wait_until(lambda: process.poll() is not None or started(process), 120.0,
                    f'{command[0]} to start its work')
        assert process.poll() is None, process.communicate(timeout=10.0)
        sent = time.monotonic()
        process.send_signal(signum)
        stdout, stderr = process.communicate(timeout=20.0)
        return process.returncode, time.monotonic() - sent, stdout, stderr
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.communicate(timeout=10.0)


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_the_analysis_ends_on_a_signal_while_it_reads_the_bag(skate_run, tmp_path, signum):
    out = tmp_path / 'analysis'
    mcap = skate_run / 'bag' / 'bag.mcap'

    def reading(process: subprocess.Popen) -> bool:
        if not _has_open(process.pid, mcap):
            return False
        time.sleep(0.3)  # well into the scan or the reading of the messages
        return True
    code, took, stdout, stderr = _interrupt(
        ['iceskate_analysis.coupling_cli', str(skate_run), '--out', str(out), '--quiet'],
        signum, reading)
    assert code == 128 + signum and took < 1.0, (code, took, stderr)
    assert 'Traceback' not in stderr and len(stderr.splitlines()) == 1, stderr
    name = signal.Signals(signum).name
    assert re.fullmatch(rf'coupling_analysis: interrupted by {name} at t=\S+ s \((scanning|'
                        rf'reading|analysing) bag {re.escape(str(skate_run / "bag"))}\); '
                        rf'nothing written into {re.escape(str(out))}\n', stderr), stderr
    assert stdout == ''
    assert list(out.iterdir()) == []  # not even a hidden partial file


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_the_analysis_ends_on_a_signal_while_it_writes_and_draws(skate_run, tmp_path, signum):
    """Signalled once the CSV is being written (the figures follow): within a figure's
    drawing (bounded: at most ``FIGURE_ROWS`` samples drawn), and a folder that held an
    earlier analysis keeps it as it was."""
    out = tmp_path / 'analysis'
    out.mkdir()
    (out / 'summary.json').write_text('{"earlier": true}\n')
    staged_csv = out / '.skate_series.partial.csv'
    code, took, _stdout, stderr = _interrupt(
        ['iceskate_analysis.coupling_cli', str(skate_run), '--out', str(out), '--quiet',
         '--animate', '--frames', '40'],
        signum, lambda process: staged_csv.exists())
    assert code == 128 + signum and took < 2.0, (code, took, stderr)
    assert 'Traceback' not in stderr and len(stderr.splitlines()) == 1, stderr
    assert re.fullmatch(rf'coupling_analysis: interrupted by {signal.Signals(signum).name} at '
                        r't=19\.99\d+ s \((writing the CSV of bag|drawing) .*\); nothing '
                        r'written into .*\n', stderr), stderr
    assert sorted(p.name for p in out.iterdir()) == ['summary.json']
    assert (out / 'summary.json').read_text() == '{"earlier": true}\n'


@pytest.mark.parametrize('tool', ['summary', 'mode_coverage'])
@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_summary_and_mode_coverage_end_on_a_signal_writing_nothing(skate_run, tmp_path, tool,
                                                                    signum):
    run = tmp_path / 'run'
    run.mkdir()
    for name in ('trajectory.npz', 'metrics.json', 'events.json'):
        shutil.copy(skate_run / name, run / name)
    out = tmp_path / 'coverage'
    command, written = (['iceskate_analysis.summary', str(run)], run / 'summary.png') \
        if tool == 'summary' else \
        (['iceskate_analysis.coverage_cli', str(run), str(skate_run), '--out', str(out)], out)

    def started(process: subprocess.Popen) -> bool:  # then in the imports of its work
        return _catches_sighup(process.pid)
    code, took, stdout, stderr = _interrupt(command, signum, started)
    assert code == 128 + signum and took < 2.0, (code, took, stderr)
    assert stdout == '' and 'Traceback' not in stderr, stderr
    what = f'{written} not written' if tool == 'summary' else f'nothing written into {out}'
    assert stderr == f'{tool}: interrupted by {signal.Signals(signum).name}; {what}\n'
    if tool == 'summary':
        assert sorted(p.name for p in run.iterdir()) == ['events.json', 'metrics.json',
                                                         'trajectory.npz']
    else:
        assert not out.exists() or list(out.iterdir()) == []
