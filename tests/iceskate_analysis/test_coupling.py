"""Eq. (11) on recorded bags: closure, agreement with a direct evaluation, the arm swing."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from iceskate_analysis.bag_io import read_bag
from iceskate_analysis.coupling import (
    analyse_case,
    arm_swing,
    decompose,
    dynamics_for_bag,
    interval_accelerations,
    parse_joint,
)
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.dynamics import ContactState
from iceskate_sim.model.modes import get_mode
from iceskate_sim.model.robot import COORDINATE_NAMES, N_COORDINATES
from iceskate_sim.run.metrics import shoulder_correlation
from oracle.dynamics import GaitDynamics

CLOSURE = 1e-9  # relative closure residual the decomposition must reach
DIRECT = 1e-9  # relative agreement with a direct evaluation (scaled by max(1, |reference|))


@pytest.fixture(scope='module')
def sim(sim_bag):
    return read_bag(sim_bag)


@pytest.fixture(scope='module')
def synthetic(synthetic_bag):
    return read_bag(synthetic_bag)


@pytest.mark.parametrize('joint', [11, 14])
def test_eq11_closes_at_solver_precision_on_a_simulated_run(sim, joint):
    d = decompose(sim, (joint,))[joint]
    assert d.valid.all()
    rel = d.residual_rel
    assert np.all(np.isfinite(rel))
    assert rel.max() <= CLOSURE, f'closure residual {rel.max():.2e} at {d.name}'
    assert np.abs(d.own_inertia).max() > 0.0  # the arm does accelerate: not a trivial 0 = 0
    assert np.abs(d.m_total).max() > 0.0


def test_eq11_closes_at_every_coordinate_in_every_visited_mode(synthetic):
    """y0 (gliding friction), q1 (tipping), legs (sliding-heel constraint), arms, neck."""
    decompositions = decompose(synthetic, tuple(range(N_COORDINATES)))
    for joint, d in decompositions.items():
        assert d.valid.any(), f'joint {joint} never active'
        worst = np.nanmax(d.residual_rel)
        assert worst <= CLOSURE, f'closure residual {worst:.2e} at {d.name}'
    # the swing constraints act on the legs, never on the upper body (docs/model.md §13)
    assert np.nanmax(np.abs(decompositions[5].constraint)) > 0.0
    for joint in range(8, 18):
        assert np.all(np.nan_to_num(decompositions[joint].constraint) == 0.0)
    # q1 is a coordinate only in mode 2; y0 only in mode 3
    assert np.array_equal(decompositions[1].valid, synthetic.mode == 2)
    assert np.array_equal(decompositions[0].valid, synthetic.mode == 3)


def _direct(robot, side, pivot, q, v):
    """M, h (RNEA, gravity off, q̈ = 0), g (RNEA, q̇ = q̈ = 0) straight from pinocchio."""
    model = robot.support_model(side, pivot).model
    data = model.createData()
    M = pin.crba(model, data, q).copy()
    M = np.triu(M) + np.triu(M, 1).T
    zero = np.zeros(N_COORDINATES)
    g = pin.rnea(model, data, q, zero, zero).copy()
    no_gravity = model.copy()
    no_gravity.gravity = pin.Motion.Zero()
    h = pin.rnea(no_gravity, no_gravity.createData(), q, v, zero).copy()
    return M, h, g


def _close(actual, expected, what):
    scale = max(1.0, float(np.max(np.abs(expected))))
    error = float(np.max(np.abs(np.asarray(actual) - np.asarray(expected))))
    assert error <= DIRECT * scale, f'{what}: error {error:.2e} (scale {scale:.2e})'


@pytest.mark.parametrize('which', ['sim', 'synthetic'])
def test_decomposition_agrees_with_a_direct_evaluation(which, sim, synthetic):
    bag = sim if which == 'sim' else synthetic
    dyn = dynamics_for_bag(bag)
    equations = GaitDynamics(dyn.robot, dyn.params)  # eq. (7) solved directly (the oracle)
    joints = (11, 14, 8)
    decompositions = decompose(bag, joints, dynamics=dyn)
    sources = bag.sources
    picks = np.unique(np.linspace(0, bag.n_samples - 1, 5).round().astype(int))
    checked = 0
    for k in picks:
        mode = get_mode(int(bag.mode[k]))
        side, pivot = bag.side_name(k), bag.pivot_name(k)
        q, v = bag.q[k], bag.v[k]
        act = mode.active
        if not (mode.swing_sliding or mode.y0_active):  # slide directions are not recorded
            tau = np.sum([bag.efforts[s][k] for s in sources], axis=0)
            contact = ContactState(mode, side, pivot, float(bag.heel_anchor_y[k]))
            qdd = equations.evaluate(contact, q, v, tau).qdd
            _close(qdd, bag.qdd[k], f'sample {k}: evaluate() reproduces the recorded q̈')
            checked += 1
        M, h, g = _direct(dyn.robot, side, pivot, q, v)
        qdd = np.where(np.isin(np.arange(N_COORDINATES), act), bag.qdd[k], 0.0)
        for i, d in decompositions.items():
            _close(d.own_inertia[k], M[i, i] * qdd[i], f'sample {k}: M_ii q̈_i at q{i}')
            others = [j for j in act if j != i]
            _close(d.coupling[k, others], M[i, others] * qdd[others],
                   f'sample {k}: M_ij q̈_j at q{i}')
            _close(d.m_total[k], -np.sum(M[i, others] * qdd[others]), f'sample {k}: M_total')
            _close(d.coriolis[k], h[i], f'sample {k}: h_{i}')
            _close(d.gravity[k], g[i], f'sample {k}: g_{i}')
            _close(d.damping[k], dyn.robot.damping[i] * v[i], f'sample {k}: d_i q̇_i')
    assert checked >= 2


def test_shoulders_couple_to_torso_yaw_with_opposite_signs(synthetic):
    """docs/model.md §2.5 mechanism check: M_11,8 and M_14,8 have opposite signs."""
    case = analyse_case(synthetic, 'synthetic', 11)
    summary = case.summary()
    right = summary['joints']['q11']['mean_M_i8']
    left = summary['joints']['q14']['mean_M_i8']
    assert right * left < 0.0
    assert abs(right + left) < 0.2 * abs(right)


def test_arm_swing_measures_anti_phase_from_the_fourth_step(synthetic, spec):
    swing = _swing(synthetic)
    assert swing.window_from_step == 3
    assert swing.samples == spec.samples_per_step
    assert swing.window_start_s == pytest.approx(3 * spec.samples_per_step * spec.dt)
    for arm in ('q11', 'q14'):
        assert swing.peak_to_peak[arm] == pytest.approx(2 * spec.arm_amplitude, rel=0.05)
        assert swing.dominant_frequency[arm] == pytest.approx(spec.arm_frequency, rel=0.05)
    assert swing.correlation == pytest.approx(-1.0, abs=1e-6)
    assert abs(swing.phase_difference_deg) == pytest.approx(180.0, abs=5.0)


def test_arm_swing_measures_the_phase_lag_without_yaw(synthetic_no_yaw_bag, spec):
    swing = _swing(read_bag(synthetic_no_yaw_bag))
    assert swing.peak_to_peak['q11'] == pytest.approx(2 * spec.no_yaw_amplitude, rel=0.05)
    assert swing.correlation > 0.8
    # q14 leads q11 by NO_YAW_LEAD: the phase of q11 relative to q14 is negative
    assert swing.phase_difference_deg == pytest.approx(-np.degrees(spec.no_yaw_lead), abs=5.0)


def test_a_run_short_of_four_steps_is_measured_over_the_whole_run(sim):
    swing = _swing(sim)
    assert swing.window_from_step is None
    assert swing.samples == sim.n_samples


def test_the_analysis_corr_q11_q14_is_that_of_metrics_json():
    """One corr(q11, q14): the analysis's is the registry's (raw over the window from the 4th
    step), not a detrended one; the phase is of the detrended angles."""
    t = np.linspace(0.0, 6.0, 601)
    step_index = (t // 1.0).astype(int)
    right, left = np.sin(2 * np.pi * t) + 0.3 * t, -np.sin(2 * np.pi * t) + 0.3 * t
    swing = arm_swing(t, right, left, step_index)
    window = step_index >= 3
    assert swing.correlation == shoulder_correlation(right[window], left[window])
    assert swing.correlation > -0.9  # the shared drift counts (detrended: -1)
    assert abs(swing.phase_difference_deg) == pytest.approx(180.0, abs=5.0)


def _swing(bag):
    return arm_swing(bag.t, bag.q[:, 11], bag.q[:, 14], bag.step_index)


def test_coupling_terms_are_ranked_by_rms(synthetic):
    ranking = analyse_case(synthetic, 'synthetic', 11).ranking(11)
    d = decompose(synthetic, (11,))[11]
    window = synthetic.step_index >= 3
    for name, value in ranking:  # the RMS over the arm-swing window, summed window by window
        x = d.coupling[window & d.valid, COORDINATE_NAMES.index(name)]
        assert value == pytest.approx(np.sqrt(np.mean(x * x)), rel=1e-12)
    values = [value for _, value in ranking]
    assert values == sorted(values, reverse=True)
    assert 'q11' not in dict(ranking)
    assert {'q8', 'q12'} <= set(dict(ranking))
    assert 'q14' not in dict(ranking)  # the two arms are separate branches: M_11,14 = 0


def test_summary_reports_what_the_issue_asks_for(synthetic):
    summary = analyse_case(synthetic, 'synthetic', 11).summary()
    assert summary['closure_residual_max_rel'] <= CLOSURE
    assert summary['torso_yaw_input'] is True
    for arm in ('q11', 'q14'):
        assert summary['arms'][arm]['peak_to_peak_rad'] > 0.0
    assert {'correlation', 'phase_difference_deg'} <= set(summary['arms'])
    assert {'own_inertia', 'tau', 'm_total', 'coriolis', 'gravity', 'damping',
            'residual'} <= set(summary['rms'])
    assert summary['rms_m_total_minus_g'] > 0.0
    assert set(summary['joints']) == {'q11', 'q14'}


@pytest.mark.parametrize('value, expected', [('11', 11), (14, 14), ('q14', 14), ('y0', 0)])
def test_parse_joint_accepts_indices_and_names(value, expected):
    assert parse_joint(value) == expected


@pytest.mark.parametrize('value', ['18', '-1', 'shoulder', 'q18'])
def test_parse_joint_refuses_unknown_joints(value):
    with pytest.raises(SimulationError, match='unknown joint'):
        parse_joint(value)


def test_interval_accelerations_are_the_velocity_steps_within_a_mode(sim):
    """Defined over the intervals with the same mode, side, pivot and step at both ends and
    no transition in between: this run's stick-slip also goes out and back within a period."""
    a, defined = interval_accelerations(sim)
    same_mode = ((np.diff(sim.mode) == 0) & (np.diff(sim.side) == 0)
                 & (np.diff(sim.pivot) == 0) & (np.diff(sim.step_index) == 0))
    same = same_mode & (sim.last_transition_ns[1:] <= sim.t_ns[:-1])
    assert np.array_equal(defined[:-1], same) and not defined[-1]
    assert np.count_nonzero(same_mode & ~same) >= 3  # out and back between two samples
    assert defined.sum() >= 2 and not defined.all()  # the run changes mode
    expected = (sim.v[1:] - sim.v[:-1]) / np.diff(sim.t)[:, None]
    assert np.array_equal(a[:-1][same], expected[same])
    assert np.all(np.isnan(a[~defined]))


def test_the_averaged_view_with_the_recorded_accelerations_is_the_exact_row(sim):
    """``period_averaged`` only swaps the accelerations: given the recorded ones it gives the
    exact decomposition back (where defined), the rest of the row untouched."""
    d = decompose(sim, (11,))[11]
    a, defined = interval_accelerations(sim)
    same = d.period_averaged(sim.qdd, defined)
    assert np.array_equal(same.valid, d.valid & defined)
    keep = same.valid
    assert np.allclose(same.own_inertia[keep], d.own_inertia[keep], rtol=0, atol=1e-12)
    assert np.allclose(same.m_total[keep], d.m_total[keep], rtol=1e-12, atol=1e-12)
    assert np.array_equal(same.gravity, d.gravity) and np.array_equal(same.tau, d.tau)
    averaged = d.period_averaged(a, defined)
    row = d.mass_row[keep]
    assert np.allclose(averaged.own_inertia[keep], row[:, 11] * a[keep, 11], rtol=1e-15)


def test_interval_accelerations_are_the_integrators_velocity_steps(tmp_path):
    """Semi-implicit Euler with one step per control period advances v by h times the
    recorded q̈ (the dynamics at t_k under the held command): over every interval without an
    event the interval average is the recorded q̈ (up to the end-of-period projection)."""
    import json

    from iceskate_bringup.runner import run
    from iceskate_bringup.scene import load_scene, parse_scene
    h = 1e-4
    raw = {**load_scene('stand').raw, 'duration': 0.2, 'control_period': h,
           'integrator': {'method': 'symplectic_euler', 'step': h},
           'record': {'bag_rate': None}}  # every period
    run(parse_scene(raw), tmp_path, progress=False)
    bag = read_bag(tmp_path / 'bag')
    events = np.array([e['t'] for e in json.loads((tmp_path / 'events.json').read_text())])
    a, defined = interval_accelerations(bag)
    t = bag.t
    quiet = defined.copy()
    quiet[:-1] &= ~np.array([np.any((events > t[k]) & (events <= t[k + 1]))
                             for k in range(len(t) - 1)])
    rows = np.flatnonzero(quiet)
    assert rows.size > 500 and len(events) > 0  # eventful, with many quiet intervals
    for k in rows:
        active = bag.active[k]
        error = np.abs(a[k, active] - bag.qdd[k, active])
        assert np.all(error <= 1e-7 * np.max(np.abs(bag.qdd[k, active])) + 1e-7), (k, error.max())


def test_write_csv_writes_every_row_exactly_across_its_blocks(tmp_path):
    """Rows are turned into text a block at a time; every value reads back exactly, integers as
    integers and nan as 'nan', whatever the block boundaries; columns of unequal length are
    refused."""
    import csv

    from iceskate_analysis.coupling import CSV_BLOCK, write_csv
    n = 2 * CSV_BLOCK + 3
    rng = np.random.default_rng(5)
    x = rng.normal(size=n)
    x[CSV_BLOCK] = np.nan
    columns = {'k': np.arange(n), 'x': x, 'flag': x > 0}
    cut = CSV_BLOCK - 7  # two blocks given, the header once, in the order asked
    blocks = [{name: a[:cut] for name, a in columns.items()},
              {name: a[cut:] for name, a in columns.items()}]
    path = write_csv(tmp_path / 'series.csv', blocks, ['k', 'x', 'flag'])
    with path.open(encoding='utf-8') as stream:
        rows = list(csv.reader(stream))
    assert rows[0] == ['k', 'x', 'flag'] and len(rows) == n + 1
    assert [int(r[0]) for r in rows[1:]] == list(range(n))
    np.testing.assert_array_equal(np.array([float(r[1]) for r in rows[1:]]), x)
    assert [r[2] for r in rows[1:]] == [str(int(f)) for f in x > 0]
    with pytest.raises(ValueError, match='different lengths'):
        write_csv(tmp_path / 'bad.csv', [{'a': np.zeros(3), 'b': np.zeros(4)}])


def _flat(value, path=''):
    """(path, leaf) of every leaf of nested dicts and lists."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _flat(item, f'{path}/{key}')
    elif isinstance(value, list):
        for k, item in enumerate(value):
            yield from _flat(item, f'{path}[{k}]')
    else:
        yield path, value


@pytest.mark.parametrize('size', [1, 5, 37])
def test_the_analysis_in_blocks_equals_the_analysis_of_the_whole_run(synthetic, size):
    """Blocks of any size give the summary of one block of the whole run: the sums of squares,
    maxima, counts, rankings and the arm swing do not depend on where blocks end."""
    whole = dict(_flat(analyse_case(synthetic, 's', 11, size=synthetic.n_samples).summary()))
    parts = dict(_flat(analyse_case(synthetic, 's', 11, size=size).summary()))
    assert parts.keys() == whole.keys()
    for key, value in whole.items():
        if isinstance(value, float) and np.isfinite(value):
            assert parts[key] == pytest.approx(value, rel=1e-12, abs=1e-300), key
        else:
            assert parts[key] == value or (value != value and parts[key] != parts[key]), key


def test_the_figures_keep_every_sample_of_a_short_run_and_every_2_to_the_k_of_a_long_one(
        synthetic, monkeypatch):
    import iceskate_analysis.coupling as coupling
    n = synthetic.n_samples
    assert np.array_equal(analyse_case(synthetic, 's', 11).kept.t_ns, synthetic.t_ns)
    monkeypatch.setattr(coupling, 'FIGURE_ROWS', 16)
    case = analyse_case(synthetic, 's', 11, size=7)
    stride = 1 << int(np.ceil(np.log2(n / 16)))
    assert np.array_equal(case.kept.t_ns, synthetic.t_ns[::stride])
    exact = decompose(synthetic, (11, 14))
    for joint, d in case.decompositions.items():
        assert np.array_equal(d.coriolis, exact[joint].coriolis[::stride], equal_nan=True)
    a, defined = interval_accelerations(synthetic)
    averaged = exact[11].period_averaged(a, defined)
    assert np.array_equal(case.averaged(case.main).own_inertia, averaged.own_inertia[::stride],
                          equal_nan=True)


def test_the_csv_is_the_same_whatever_the_blocks(synthetic_bag, tmp_path):
    from iceskate_analysis.bag_io import BagReading
    from iceskate_analysis.coupling import analyse_bag
    texts = []
    for size in (3, 100_000):
        path = tmp_path / f'series_{size}.csv'
        analyse_bag(BagReading(synthetic_bag), 's', 11, csv=path, size=size)
        texts.append(path.read_text())
    assert texts[0] == texts[1] and texts[0].count('\n') == read_bag(synthetic_bag).n_samples + 1


def test_files_made_from_bags_go_to_a_folder_of_this_user_alone(tmp_path, monkeypatch):
    """A bag's URDF is trusted by its name in that folder: it must be this user's, mode 0700,
    not a link; another folder there is refused in one sentence."""
    import os
    import tempfile

    from iceskate_analysis.coupling import _private_cache
    from iceskate_sim.errors import SimulationError
    monkeypatch.setattr(tempfile, 'gettempdir', lambda: str(tmp_path))
    folder = _private_cache()
    assert folder == tmp_path / f'iceskate-{os.getuid()}'
    assert folder.stat().st_mode & 0o777 == 0o700
    folder.chmod(0o777)  # opened to others: another user could plant a URDF
    with pytest.raises(SimulationError, match='is not a folder of this user alone'):
        _private_cache()
    folder.rmdir()
    (tmp_path / 'elsewhere').mkdir(mode=0o700)
    folder.symlink_to(tmp_path / 'elsewhere')
    with pytest.raises(SimulationError, match='is not a folder of this user alone'):
        _private_cache()
