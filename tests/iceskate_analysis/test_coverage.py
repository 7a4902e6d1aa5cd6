"""The modes and transitions finished runs visited (``mode_coverage``)."""

from __future__ import annotations

from dataclasses import replace
import json
import os
import pathlib
import subprocess
import sys

import pytest

from iceskate_analysis.coverage import KIND_OF_EVENT, Coverage, coverage_of, load_events
from iceskate_analysis.coverage_cli import main
from iceskate_bringup.runner import run
from iceskate_bringup.scene import load_scene
from iceskate_sim.errors import SimulationError
from iceskate_sim.installed import shipped_files
from iceskate_sim.model.modes import TABLE_2
from iceskate_sim.physics.hybrid import GUARDS
from iceskate_sim.run.scene import SCENE_RESOURCE

STAND = pathlib.Path(__file__).resolve().parents[1] / 'integration' / 'data' / 'tiny_stand.yaml'


def _event(t: float, a: int, b: int, event: str) -> dict:
    return {'t': t, 'from_mode': a, 'to_mode': b, 'event': event, 'cause': ''}


def test_a_run_counts_the_modes_the_dynamics_entered_and_their_time():
    """Entries are the transitions into a mode (the initial mode is a set-up state, not a
    visit); the time in each mode adds up to the run's duration; transitions are counted by
    (from, to, event)."""
    coverage = Coverage()
    coverage.add('a', [_event(0.5, 1, 2, 'E1'), _event(0.75, 2, 1, 'E3'),
                       _event(1.5, 1, 2, 'E1')], 2.0)
    coverage.add('b', [_event(1.0, 3, 7, 'S1')], 3.0)
    assert coverage.entries[1] == 1 and coverage.entries[2] == 2 and coverage.entries[7] == 1
    assert coverage.entries[3] == 0  # b's initial mode only
    assert coverage.visited == [1, 2, 7]
    assert coverage.missing == [m for m in range(1, 21) if m not in (1, 2, 7)]
    assert coverage.time_s[1] == pytest.approx(0.5 + 0.75)
    assert coverage.time_s[2] == pytest.approx(0.25 + 0.5)
    assert coverage.time_s[3] == pytest.approx(1.0) and coverage.time_s[7] == pytest.approx(2.0)
    assert sum(coverage.time_s.values()) == pytest.approx(5.0)
    assert coverage.transitions == {(1, 2, 'E1'): 2, (2, 1, 'E3'): 1, (3, 7, 'S1'): 1}
    assert coverage.visited_by == {2: ['a'], 1: ['a'], 7: ['b']}
    data = coverage.as_dict()
    assert data['missing'] == coverage.missing and data['modes']['2']['entries'] == 2
    assert {'from_mode': 1, 'to_mode': 2, 'event': 'E1', 'kind': 'support roll',
            'count': 2} in data['transitions']
    assert '3 of 20 modes of Table 2 entered; never: 3, 4, 5, 6' in coverage.table()


def test_every_guard_has_a_kind():
    assert {guard.name for guard in GUARDS} | {'R'} == set(KIND_OF_EVENT)


def test_an_event_outside_table_2_is_refused_in_one_sentence():
    with pytest.raises(SimulationError, match='not a transition between modes of Table 2'):
        Coverage().add('a', [_event(0.1, 1, 21, 'E1')], 1.0)
    with pytest.raises(SimulationError, match='not a transition between modes of Table 2'):
        Coverage().add('a', [_event(0.1, 1, 2, 'E9')], 1.0)


def test_a_resolved_cycle_into_the_same_mode_is_a_transition_not_an_entry():
    """'R' may end in the mode it left (another side or pivot): counted as a transition, with
    its time, but it enters nothing; a run without transitions spends its time in ``still``."""
    coverage = Coverage()
    coverage.add('a', [_event(0.5, 4, 4, 'R')], 1.0)
    coverage.add('b', [], 2.0, still=17)
    assert coverage.transitions == {(4, 4, 'R'): 1}
    assert coverage.entries[4] == 0 and 4 not in coverage.visited_by
    assert coverage.time_s[4] == pytest.approx(1.0) and coverage.time_s[17] == pytest.approx(2.0)


def test_mode_coverage_writes_the_table_and_the_diagram_of_real_runs(tmp_path, capsys):
    """Two runs of the tiny scene (one of them 0.3 s) through the console entry: the table,
    the JSON and the picture; the JSON's counts are the runs' own events."""
    scene = load_scene(str(STAND))
    for name, duration in (('long', 0.6), ('short', 0.3)):
        run(replace(scene, duration=duration), tmp_path / name, progress=False, picture=False)
    out = tmp_path / 'coverage'
    assert main([str(tmp_path / 'long'), str(tmp_path / 'short'), '--out', str(out)]) == 0
    line = capsys.readouterr().out
    assert 'modes entered' in line and 'coverage.png' in line
    data = json.loads((out / 'coverage.json').read_text())
    events = [e for name in ('long', 'short')
              for e in json.loads((tmp_path / name / 'events.json').read_text())]
    assert sum(t['count'] for t in data['transitions']) == len(events)
    total = sum(m['time_s'] for m in data['modes'].values())
    assert total == pytest.approx(0.9, abs=1e-9)
    assert (out / 'coverage.png').stat().st_size > 10_000
    assert (out / 'coverage.md').read_text().startswith('# Modes and transitions of 2 run(s)')
    assert coverage_of([tmp_path / 'long']).runs == ['long']


def test_mode_coverage_names_a_folder_that_is_not_a_run(tmp_path, capsys):
    assert main([str(tmp_path), '--out', str(tmp_path / 'c')]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith('mode_coverage: error:') and 'is not a finished run' in err
    assert '\n' not in err
    (tmp_path / 'metrics.json').write_text('{"sim_time_s": 1.0}')
    for bad in ('{"not": "a list"}', '[{"t": "0.1", "from_mode": 1, "to_mode": 2, "event": "E1"}]',
                '[{"t": 0.1, "from_mode": [1], "to_mode": 2, "event": "E1"}]'):
        (tmp_path / 'events.json').write_text(bad)
        assert main([str(tmp_path), '--out', str(tmp_path / 'c')]) == 2
        err = capsys.readouterr().err
        assert 'events.json: not an event log' in err and 'Traceback' not in err
    (tmp_path / 'events.json').write_text('[')
    assert main([str(tmp_path), '--out', str(tmp_path / 'c')]) == 2
    assert f'{tmp_path / "events.json"} is not JSON' in capsys.readouterr().err
    (tmp_path / 'events.json').write_text('[]')
    (tmp_path / 'metrics.json').write_text('{"sim_time_s": 1.0, "mode_time_fraction": {"x": 1}}')
    assert load_events(tmp_path) == ([], 1.0, None)


def test_the_shipped_scenes_enter_every_mode_of_table_2(tmp_path):
    """Each shipped scene run whole (headless, no bag): together they enter all 20 modes by
    transitions the dynamics took (a run's initial mode does not count), each for some time.
    ``stand_ice`` and ``walk_slippery`` are there for modes 11, 15, 19 and 14, which no other
    shipped scene enters."""
    names = sorted(shipped_files(SCENE_RESOURCE, 'scenes'))
    assert {'stand_ice', 'walk_slippery'} <= set(names)
    for name in names:
        metrics = run(replace(load_scene(name), record_bag=False), tmp_path / name,
                      progress=False, picture=False)
        assert not metrics['fell'], (name, metrics['failure'])
    coverage = coverage_of(tmp_path / name for name in names)
    assert coverage.missing == [], coverage.table()
    assert all(coverage.time_s[mode] > 0.0 for mode in TABLE_2), coverage.table()
    assert coverage.visited_by[14] == ['walk_slippery']
    assert all(coverage.visited_by[mode] == ['stand_ice'] for mode in (11, 15, 19))


def test_mode_coverage_refuses_an_events_json_that_is_a_fifo_at_once(tmp_path):
    """Reading a FIFO blocks until a writer comes: it is refused in one line before."""
    os.mkfifo(tmp_path / 'events.json')
    (tmp_path / 'metrics.json').write_text('{"sim_time_s": 1.0}')
    result = subprocess.run([sys.executable, '-m', 'iceskate_analysis.coverage_cli',
                             str(tmp_path), '--out', str(tmp_path / 'c')],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        f'mode_coverage: error: run file {tmp_path / "events.json"} is a named pipe (FIFO), '
        'not a regular file, and is not read']
