"""Runs from Python (``iceskate_bringup.api``): a run in memory holds what ``run_scene`` writes
(the same samples to the bit, the same events and metrics), overrides are checked as in a scene
file, and a loaded scene takes overrides the same way."""

import json

import numpy as np
import pytest

from iceskate_bringup.api import load_scene, run, with_overrides
from iceskate_bringup.runner import main
from iceskate_sim.errors import SimulationError

TIMING = {'wall_time_s', 'real_time_factor'}


def test_a_run_in_memory_holds_what_run_scene_writes(tmp_path):
    assert main(['skate', '--out', str(tmp_path / 'cli'), '--quiet', '--set', 'duration=1.5',
                 '--set', 'floor.mu=0.01']) == 0
    in_memory = run('skate', {'duration': 1.5, 'floor.mu': 0.01})
    with np.load(tmp_path / 'cli' / 'trajectory.npz') as written:
        assert set(written.files) == set(in_memory.columns)
        for key in written.files:
            assert np.array_equal(written[key], in_memory.columns[key]), key
    metrics = json.loads((tmp_path / 'cli' / 'metrics.json').read_text())
    assert {k: v for k, v in metrics.items() if k not in TIMING} == json.loads(json.dumps(
        {k: v for k, v in in_memory.metrics.items() if k not in TIMING}))
    assert json.loads((tmp_path / 'cli' / 'events.json').read_text()) == json.loads(
        json.dumps(in_memory.events))
    assert in_memory.error is None and in_memory.metrics['end'] == 'completed'
    assert in_memory.scene.simulator.friction.mu == 0.01


def test_overrides_are_checked_as_in_a_scene_file(tmp_path):
    stand = load_scene('stand')
    shorter = with_overrides(stand, {'duration': 0.1, 'floor.mu': 0.3})
    assert (shorter.duration, shorter.simulator.friction.mu) == (0.1, 0.3)
    assert stand.duration != 0.1  # the loaded scene is left as it was
    with pytest.raises(SimulationError, match=r"scene key 'floor\.mew': unknown key"):
        with_overrides(stand, {'floor.mew': 0.3})
    with pytest.raises(SimulationError, match='duration'):
        run('stand', {'duration': -1.0})
    done = run(shorter, out=tmp_path / 'out')
    assert done.metrics['sim_time_s'] == pytest.approx(0.1)
    assert (tmp_path / 'out' / 'metrics.json').is_file() and (tmp_path / 'out' / 'bag').is_dir()
