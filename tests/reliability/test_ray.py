"""A Ray node that dies mid-sweep (its raylet killed): the runs it lost are Ray's failure, not
theirs, so none gets a failed row; the sweep ends in one line saying how many runs are left
(Ray's own dump of the raylet's last log lines goes to a file of the output folder, not to the
terminal), and the same command (here on the local pool) runs them."""

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import pyarrow.parquet as pq
import pytest
import yaml

from iceskate_study.table import RESULTS

pytestmark = pytest.mark.slow
#: 16 runs of 4 s of skate, one at a time: the sweep is still going when the raylet dies
#: (and the test leaves a core to the tests beside it).
SPEC = {'study': 'raylet', 'scene': 'skate', 'overrides': {'duration': 4.0},
        'axes': {'floor.mu': {'linspace': [0.004, 0.0155, 16]}}, 'metrics': ['steps', 'fell']}
RUNS = 16


def test_a_raylet_killed_mid_sweep_leaves_its_runs_for_the_next_call(tmp_path, proc):
    pytest.importorskip('ray')
    spec, out = tmp_path / 'spec.yaml', tmp_path / 'out'
    spec.write_text(yaml.safe_dump(SPEC))
    command = [sys.executable, '-m', 'iceskate_study.sweep', str(spec), '--out', str(out),
               '--quiet']
    sweep = subprocess.Popen([*command, '--ray', 'local', '--workers', '1'],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             start_new_session=True)
    try:
        deadline = time.monotonic() + 180
        while not (out / RESULTS).exists() and sweep.poll() is None:
            assert time.monotonic() < deadline, 'no table within 180 s'
            time.sleep(0.02)
        raylets = [pid for pid in proc.descendants(sweep.pid)
                   if Path(f'/proc/{pid}/comm').read_text().strip() == 'raylet']
        assert len(raylets) == 1, 'the local Ray instance has one raylet'
        os.kill(raylets[0], signal.SIGKILL)
        printed, err = sweep.communicate(timeout=120)
    finally:
        if sweep.poll() is None:
            os.killpg(sweep.pid, signal.SIGKILL)
            sweep.communicate()
    assert sweep.returncode == 1, err
    (line,) = [line for line in err.splitlines() if line.startswith('sweep: ')]
    assert line.startswith('sweep: error: Ray lost a run') and 'the same command runs them' in line
    before = pq.read_table(out / RESULTS).to_pylist()
    assert 1 <= len(before) < RUNS and all(row['status'] == 'ok' for row in before), before
    assert f'{RUNS - len(before)} runs have no row yet' in line
    assert printed == '' and line.endswith(f"(Ray's messages: {out / 'ray_messages.log'})")
    assert 'Raylet is terminated' in (out / 'ray_messages.log').read_text()
    done = subprocess.run([*command, '--workers', '1'], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert f'{len(before)} before): {RUNS} ok' in done.stderr
