"""The shipped robustness studies, run whole (slow): the skate gait walks 60 s on every friction
of 0.002-0.02 with and without the yaw input, and survives chest pushes at any time after the
4th step (every 0.05 s from 4 to 12 s), both ways: every push, at half force (7.5 N s) and at
full force (15 N s). Without the front knee's bounded step in double support
(balance.front_knee_step 0) the push criterion fails (7 of 644 runs end)."""

from pathlib import Path

import pyarrow.parquet as pq
import pytest

from iceskate_study.spec import load_spec
from iceskate_study.sweep import run_sweep
from iceskate_study.table import RESULTS

pytestmark = pytest.mark.slow


def _rows(study: str, out: Path) -> list[dict]:
    """Every row of the shipped ``study`` run on 2 workers into ``out``."""
    result = run_sweep(load_spec(study), out, workers=2, progress=False, maps=False)
    assert result.ran == result.total and 'failed' not in result.counts, result.counts
    return pq.read_table(out / RESULTS).to_pylist()


def test_the_skate_gait_walks_a_minute_on_every_friction(tmp_path):
    rows = _rows('endurance', tmp_path)
    assert len(rows) == 34
    fell = [(r['floor.mu'], r['inputs.gait_manager.yaw.amplitude'], r['sim_time_s'])
            for r in rows if r['fell']]
    assert not fell, fell
    assert all(r['sim_time_s'] == pytest.approx(60.0, abs=1e-6) for r in rows)


@pytest.mark.timeout(1200)  # 644 runs of 15 s: ~200 s alone, ~300 s beside other tests
def test_the_skate_gait_survives_a_chest_push_at_any_time(tmp_path):
    rows = _rows('push_robustness', tmp_path)
    ended = {force: [r['disturbances[0].start'] for r in rows
                     if r['disturbances[0].force[1]'] == force and r['fell']]
             for force in (-150.0, -75.0, 75.0, 150.0)}
    assert not any(ended.values()), ended
