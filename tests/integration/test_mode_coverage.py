"""Every mode of Table 2 is entered by the dynamics of the shipped scenes."""

from __future__ import annotations

from dataclasses import replace

from iceskate_analysis.coverage import coverage_of
from iceskate_bringup.runner import run
from iceskate_bringup.scene import load_scene
from iceskate_sim.installed import shipped_files
from iceskate_sim.model.modes import TABLE_2
from iceskate_sim.run.scene import SCENE_RESOURCE


def test_the_shipped_scenes_enter_every_mode_of_table_2(tmp_path):
    """Each shipped scene run whole (headless, no bag): together they enter all 20 modes by
    transitions the dynamics took (a run's initial mode does not count), each for some time.
    ``stand_ice`` and ``walk_slippery`` are there for modes 11, 15, 19 and 14."""
    names = sorted(shipped_files(SCENE_RESOURCE, 'scenes'))
    assert {'stand_ice', 'walk_slippery'} <= set(names)
    for name in names:
        metrics = run(replace(load_scene(name), record_bag=False), tmp_path / name,
                      progress=False, picture=False)
        assert not metrics['fell'], (name, metrics['failure'])
    coverage = coverage_of(tmp_path / name for name in names)
    assert coverage.missing == [], coverage.table()
    assert all(coverage.time_s[mode] > 0.0 for mode in TABLE_2), coverage.table()
    assert set(coverage.visited_by[14]) == {'walk_slippery'}
    assert {11, 15, 19} <= {mode for mode, runs in coverage.visited_by.items()
                            if 'stand_ice' in runs}
