"""The metric registry and the figures of a run computed from it: metrics.json, the one
arm-swing ratio and its fall rule, the one corr(q11, q14)."""

from types import SimpleNamespace

import numpy as np
import pytest

from iceskate_sim.run.metrics import (
    FALL_RULES,
    METRIC_NAMES,
    METRICS,
    SHOULDERS,
    Trajectory,
    arm_swing_ratio,
    compute_metrics,
    metric_ratio,
    metric_value,
    shoulder_correlation,
)


def _run(q11: float, q14: float, **end) -> dict:
    """The metrics of a run whose shoulders swing q11, q14 peak to peak [rad]."""
    return {'arm_swing': {'mean_peak_to_peak': (q11 + q14) / 2}, **end}


def test_the_arm_swing_ratio_is_mean_swing_over_mean_swing():
    assert arm_swing_ratio(_run(1.34, 1.17), _run(0.19, 0.24)) == pytest.approx(1.255 / 0.215)
    assert arm_swing_ratio({'arm_swing': None}, _run(0.19, 0.24)) is None  # < 4 steps
    assert arm_swing_ratio(_run(1.0, 1.0), {'arm_swing': None}) is None
    assert arm_swing_ratio(_run(1.0, 1.0), _run(0.0, 0.0)) is None  # no swing to compare with


@pytest.mark.parametrize('end', [{'fell': True, 'failure': 'fell: the chest touched'},
                                 {'fell': False, 'failure': 'diverged at t = 3 s'}])
def test_a_ratio_is_none_when_either_run_fell_or_failed(end):
    assert arm_swing_ratio(_run(1.0, 1.0, **end), _run(0.2, 0.2)) is None
    assert arm_swing_ratio(_run(1.0, 1.0), _run(0.2, 0.2, **end)) is None
    completed = {'fell': False, 'failure': None}
    assert arm_swing_ratio(_run(1.0, 1.0, **completed), _run(0.2, 0.2, **completed)) == (
        pytest.approx(5.0))


def test_a_table_row_and_metrics_json_give_the_same_ratio():
    """A study's table holds dotted columns, metrics.json nested blocks: metric_ratio reads
    both by the registry's names (a row of a run that completed has no failure column)."""
    nested = [_run(1.2, 1.0, fell=False, failure=None), _run(0.3, 0.1, fell=False, failure=None)]
    rows = [{'status': 'ok', 'arm_swing.mean_peak_to_peak': 1.1},
            {'status': 'ok', 'arm_swing.mean_peak_to_peak': 0.2}]
    name = METRICS['arm_swing_ratio'].ratio_of
    assert metric_value(rows[0], name[0]) == metric_value(nested[0], name[0]) == 1.1
    assert metric_ratio(name, *rows) == arm_swing_ratio(*nested) == pytest.approx(5.5)
    assert metric_ratio(name, rows[0], {**rows[1], 'failure': 'fell'}) is None


def test_corr_q11_q14_is_raw_not_detrended():
    """The one corr(q11, q14): a drift the two shoulders share counts (it is not detrended)."""
    t = np.linspace(0.0, 4.0, 401)
    swing = np.sin(2 * np.pi * t)
    assert shoulder_correlation(swing, -swing) == pytest.approx(-1.0)
    drifted = shoulder_correlation(swing + t, -swing + t)
    assert drifted == pytest.approx(np.corrcoef(swing + t, -swing + t)[0, 1])
    assert drifted > 0.4  # a detrended correlation would be -1
    assert np.isnan(shoulder_correlation(swing, np.zeros_like(t)))  # a still shoulder
    assert np.isnan(shoulder_correlation(swing[:2], -swing[:2]))  # too few samples


def _scene_run(steps: int = 6, samples: int = 600):
    """A made-up run of ``steps`` steps (scene with one push): what compute_metrics reads."""
    t = np.linspace(0.0, 6.0, samples)
    q = np.zeros((samples, 18))
    q[:, SHOULDERS[0]] = 0.5 * np.sin(2 * np.pi * t)
    q[:, SHOULDERS[1]] = -0.4 * np.sin(2 * np.pi * t)
    q[:, 8] = 0.1 * np.sin(np.pi * t)
    psi = np.stack([0.2 * t, np.full_like(t, 0.9), np.zeros_like(t)], axis=1)
    trajectory = Trajectory()
    trajectory.extend({'t': t, 'q': q, 'psi': psi, 'head_target': psi + 0.01,
                       'mode': np.where(t < 3.0, 1, 4), 'pivot': np.zeros(samples, dtype=int),
                       'zmp_y': np.zeros(samples),
                       'step_index': np.minimum((t // 1.0).astype(int), steps - 1)}, {})
    stats = SimpleNamespace(max_constraint_residual=0.0, max_constraint_drift=0.0, steps=10,
                            evaluations=10, suppressed_cycles=0, resolved_cycles=0)
    sim = SimpleNamespace(time=6.0, ended=None, state=SimpleNamespace(step_index=steps - 1),
                          events=[], stats=stats)
    scene = SimpleNamespace(name='made_up', pushes=(SimpleNamespace(start=1.0, duration=0.1),))
    return compute_metrics(scene, sim, trajectory, 1.0, None), q


def test_metrics_json_holds_the_registry_entries():
    """Every entry of metrics.json (blocks' entries too) is a registry metric and every metric
    of one run is in it; its arm swing is that of the shoulders SHOULDERS."""
    metrics, q = _scene_run()
    assert tuple(metrics) == METRIC_NAMES
    found = {f'{k}.{e}' for k, v in metrics.items() if isinstance(v, dict)
             and k in ('head_error_rms', 'head_error_final_max', 'arm_swing', 'arm_swing_steady')
             for e in v}
    entries = {name for name in METRICS if '.' in name}
    assert found == entries
    late = np.linspace(0.0, 6.0, 600) >= 3.0
    swing = metrics['arm_swing']
    assert swing['corr_q11_q14'] == pytest.approx(
        shoulder_correlation(q[late, SHOULDERS[0]], q[late, SHOULDERS[1]]))
    assert swing['q11_peak_to_peak'] == pytest.approx(np.ptp(q[late, SHOULDERS[0]]))
    assert metrics['yaw_range_rad'] == pytest.approx([-0.1, 0.1], abs=1e-3)


def test_every_metric_says_its_unit_label_and_fall_rule():
    for name, metric in METRICS.items():
        assert metric.name == name and metric.label and metric.inputs, name
        assert metric.fall in FALL_RULES, name
        assert metric.unit in ('m', 's', 'rad', '-', '×', ''), name
        assert all(m in METRICS for m in metric.ratio_of), name
        assert (metric.fall == 'none when fell') == bool(metric.ratio_of), name
    assert METRICS['arm_swing.corr_q11_q14'].caption == 'corr(q11, q14), from the 4th step [-]'
