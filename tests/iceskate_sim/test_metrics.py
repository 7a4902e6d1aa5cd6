"""The figures of a run computed from its metrics: the one arm-swing ratio."""

import pytest

from iceskate_sim.run.metrics import arm_swing_ratio


def _run(q11: float, q14: float) -> dict:
    """The metrics of a run whose shoulders swing q11, q14 peak to peak [rad]."""
    return {'arm_swing': {'mean_peak_to_peak': (q11 + q14) / 2}}


def test_the_arm_swing_ratio_is_mean_swing_over_mean_swing():
    assert arm_swing_ratio(_run(1.34, 1.17), _run(0.19, 0.24)) == pytest.approx(1.255 / 0.215)
    assert arm_swing_ratio({'arm_swing': None}, _run(0.19, 0.24)) is None  # < 4 steps
    assert arm_swing_ratio(_run(1.0, 1.0), {'arm_swing': None}) is None
    assert arm_swing_ratio(_run(1.0, 1.0), _run(0.0, 0.0)) is None  # no swing to compare with
