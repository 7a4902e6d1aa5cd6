"""scripts/tune_gait.py: the robust objective's scoring and the starting point of a search."""

import importlib.util
import pathlib

import numpy as np
import pytest

from iceskate_sim.yaml_io import read_yaml

ROOT = pathlib.Path(__file__).resolve().parents[2]
pytest.importorskip('cma')


@pytest.fixture(scope='module')
def tune():
    spec = importlib.util.spec_from_file_location('tune_gait', ROOT / 'scripts' / 'tune_gait.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def skate():
    return read_yaml(ROOT / 'ros_ws/src/iceskate_bringup/scenes/skate.yaml', 'scene')


def exchanges(times):
    return [{'event': 'E6', 't': t, 'from_mode': 8, 'to_mode': 4} for t in times]


@pytest.mark.parametrize('name', ['robust', 'pushes'])
def test_walking_counts_only_while_the_robot_steps(tune, skate, monkeypatch, name):
    """A case that stands still after its last exchange counts STALL s beyond it; a nominal
    case stepping every 0.9 s evenly loses nothing for its cadence."""
    steady = exchanges(np.arange(0.5, 12.0, 0.9))
    stalled = exchanges([0.5, 1.4, 2.3])
    cases = tune.SCENARIOS[name]

    def fake(raw):
        pushed = 'disturbances' in raw
        return ({'sim_time_s': 12.0, 'fell': False, 'head_error_rms': {'y': 0.05}},
                stalled if pushed else steady)
    monkeypatch.setattr(tune, 'run_metrics', fake)
    score, details, _ = tune.robust_score(skate, 12.0, cases)
    pushed = [case for case in cases if 'push' in case]
    walked = [details[str(case)]['walked_s'] for case in cases]
    assert walked == [12.0 if case not in pushed else 2.3 + tune.STALL for case in cases]
    share = 1.0 - len(pushed) / len(cases)
    assert details['step_period_s']['mean'] == pytest.approx(0.9)
    assert score == pytest.approx(10.0 * (np.mean(walked) / 12.0 + share), abs=1e-9)


def test_cadence_and_head_error_cost_as_documented(tune, skate, monkeypatch):
    fast = exchanges(np.arange(0.5, 12.0, 0.4))
    monkeypatch.setattr(tune, 'run_metrics', lambda raw: (
        {'sim_time_s': 12.0, 'fell': False, 'head_error_rms': {'y': 0.15}}, fast))
    score, _, nominal = tune.robust_score(skate, 12.0, tune.SCENARIOS['robust'])
    assert nominal[1] == fast
    miss = (tune.CADENCE[0] - 0.4) / 0.1
    head = (0.15 - tune.HEAD_Y_RMS) / tune.HEAD_Y_RMS
    assert score == pytest.approx(20.0 - miss - head, abs=1e-6)


def test_the_no_yaw_twin_runs_without_tau8_and_its_head_error_counts(tune, skate,
                                                                     monkeypatch):
    """'twins' ends with the nominal case without the yaw source; the head y penalty takes the
    larger of the nominal case's error and its twin's."""
    steady = exchanges(np.arange(0.5, 12.0, 0.9))
    seen = []

    def fake(raw):
        enabled = raw['inputs']['gait_manager']['enabled']
        seen.append('yaw' in enabled)
        error = 0.04 if 'yaw' in enabled else 0.075
        return {'sim_time_s': 12.0, 'fell': False, 'head_error_rms': {'y': error}}, steady
    monkeypatch.setattr(tune, 'run_metrics', fake)
    cases = tune.SCENARIOS['twins']
    score, details, _ = tune.robust_score(skate, 12.0, cases)
    assert seen == [True] * (len(cases) - 1) + [False]
    assert details['head_y_rms_m'] == 0.075
    assert score == pytest.approx(20.0 - (0.075 - tune.HEAD_Y_RMS) / tune.HEAD_Y_RMS, abs=1e-9)


def test_head_height_costs_only_with_its_weight(tune, skate, monkeypatch):
    """The larger head height error of the nominal case and its twin beyond HEAD_Z_RMS costs
    ``height_weight`` per HEAD_Z_RMS; with weight 0 (the earlier searches) it costs nothing."""
    steady = exchanges(np.arange(0.5, 12.0, 0.9))

    def fake(raw):
        with_yaw = 'yaw' in raw['inputs']['gait_manager']['enabled']
        height = 0.009 if with_yaw else 0.012
        return ({'sim_time_s': 12.0, 'fell': False,
                 'head_error_rms': {'y': 0.03, 'z': height}}, steady)
    monkeypatch.setattr(tune, 'run_metrics', fake)
    cases = tune.SCENARIOS['twins']
    unweighted, details, _ = tune.robust_score(skate, 12.0, cases)
    weighted, _, _ = tune.robust_score(skate, 12.0, cases, height_weight=5.0)
    assert details['head_z_rms_m'] == 0.012
    assert unweighted == pytest.approx(20.0, abs=1e-9)
    assert weighted == pytest.approx(20.0 - 5.0 * (0.012 - tune.HEAD_Z_RMS) / tune.HEAD_Z_RMS,
                                     abs=1e-9)


def test_the_ice_cycle_costs_only_with_its_weight(tune, skate, monkeypatch):
    """The nominal case's shortfall of the ice cycle costs ``cycle_weight`` per goal missed
    in full: heel exchanges (none from a flat sole) after 0.01 s of double support miss the
    share in full and 0.09 of the 0.1 s; with weight 0 (the earlier searches) it costs nothing
    and is reported."""
    events = []
    for t in np.arange(0.5, 12.0, 0.9):
        events += [{'event': 'E4', 't': t - 0.01, 'from_mode': 4, 'to_mode': 8},
                   {'event': 'E6', 't': t, 'from_mode': 8, 'to_mode': 4}]
    monkeypatch.setattr(tune, 'run_metrics', lambda raw: (
        {'sim_time_s': 12.0, 'fell': False, 'head_error_rms': {'y': 0.03, 'z': 0.005}}, events))
    cases = tune.SCENARIOS['robust']
    unweighted, details, _ = tune.robust_score(skate, 12.0, cases)
    weighted, _, _ = tune.robust_score(skate, 12.0, cases, cycle_weight=10.0)
    assert details['flat_sole_share'] == 0.0
    assert details['double_support_s'] == pytest.approx(0.01)
    assert unweighted == pytest.approx(20.0, abs=1e-9)
    assert weighted == pytest.approx(20.0 - 10.0 * (1.0 + 0.9), abs=1e-9)


def test_the_arm_swing_and_the_cadence_cost_with_their_weights(tune, skate, monkeypatch):
    """With the no-yaw twin among the cases, an arm-swing ratio of 1.5 against it misses half of
    ARM_SWING_RATIO: ``arm_weight`` / 2; a step every 1.05 s costs ``cadence_weight`` x 0.5."""
    steady = exchanges(np.arange(0.5, 12.0, 1.05))

    def fake(raw):
        with_yaw = 'yaw' in raw['inputs']['gait_manager']['enabled']
        swing = {'mean_peak_to_peak': 0.3 if with_yaw else 0.2}
        return ({'sim_time_s': 12.0, 'fell': False, 'arm_swing': swing,
                 'head_error_rms': {'y': 0.03, 'z': 0.005}}, steady)
    monkeypatch.setattr(tune, 'run_metrics', fake)
    cases = tune.SCENARIOS['twins']
    plain, details, _ = tune.robust_score(skate, 12.0, cases)
    weighted, _, _ = tune.robust_score(skate, 12.0, cases, arm_weight=8.0, cadence_weight=3.0)
    assert details['arm_swing_ratio'] == pytest.approx(1.5)
    assert plain == pytest.approx(20.0 - 0.5, abs=1e-9)
    assert weighted == pytest.approx(20.0 - 3.0 * 0.5 - 8.0 * 0.5, abs=1e-9)
    # without the twin, or with a twin that fell: no ratio, the whole weight
    _, details, _ = tune.robust_score(skate, 12.0, tune.SCENARIOS['robust'])
    assert details['arm_swing_ratio'] is None
    monkeypatch.setattr(tune, 'run_metrics', lambda raw: (
        {'sim_time_s': 12.0, 'fell': 'yaw' not in raw['inputs']['gait_manager']['enabled'],
         'arm_swing': {'mean_peak_to_peak': 0.3}, 'head_error_rms': {'y': 0.03, 'z': 0.005}},
        steady))
    fallen, details, _ = tune.robust_score(skate, 12.0, cases, arm_weight=8.0)
    assert details['arm_swing_ratio'] is None
    assert fallen == pytest.approx(20.0 - 0.5 - 8.0, abs=1e-9)  # the whole weight


def test_phase_cases_push_before_the_nominal_cases_exchanges(tune, skate, monkeypatch):
    """'phases' places each push ``lead`` s before the nominal case's clean exchange number
    ``exchange``; when the nominal case stops short of it the case counts as not walked."""
    steady = np.arange(0.5, 12.0, 0.9)
    pushes = []

    def fake(raw):
        pushes.extend((d['start'], d['force'][1]) for d in raw.get('disturbances', []))
        return ({'sim_time_s': 12.0, 'fell': False, 'head_error_rms': {'y': 0.03, 'z': 0.005}},
                exchanges(steady))
    monkeypatch.setattr(tune, 'run_metrics', fake)
    cases = tune.SCENARIOS['phases']
    placed = [case['push_before'] for case in cases if 'push_before' in case]
    score, _, _ = tune.robust_score(skate, 12.0, cases)
    assert pushes == [pytest.approx((steady[k] - lead, force)) for k, lead, force in placed]
    assert score == pytest.approx(20.0, abs=1e-9)

    short = steady[:6]  # the nominal case's exchanges 6 and later never come
    monkeypatch.setattr(tune, 'run_metrics', lambda raw: (
        {'sim_time_s': 12.0, 'fell': False, 'head_error_rms': {'y': 0.03, 'z': 0.005}},
        exchanges(short)))
    _, details, _ = tune.robust_score(skate, 12.0, cases)
    missing = [case for case in cases if case.get('push_before', (0,))[0] >= len(short)]
    assert missing and all(details[str(case)]['walked_s'] == 0.0 for case in missing)


def test_the_search_starts_at_the_scene_values_and_the_defaults(tune, skate):
    balance = skate['inputs']['gait_manager']['balance']
    balance.pop('glide_time', None)
    point = tune.point_of(tune.unit_of(skate))
    assert point['balance.swing_time'] == pytest.approx(balance['swing_time'])
    assert point['balance.glide_time'] == 0.0  # not in the scene: the parameter's default
    assert point['weight_transfer.heel_share'] == 2.0  # the default, the top of its range


def test_the_arm_weight_needs_the_no_yaw_twin(tune, monkeypatch):
    monkeypatch.setattr('sys.argv', ['tune_gait.py', '--objective', 'robust', '--scenarios',
                                     'robust', '--arm-weight', '5'])
    with pytest.raises(SystemExit, match='no no-yaw twin'):
        tune.main()


def test_set_means_what_run_scene_set_means(tune, skate):
    """``--set KEY=VALUE`` sets a dotted scene key, VALUE read as YAML, as ``run_scene --set``;
    a malformed argument or a key the scene refuses stops in one line."""
    overrides = tune.settings(['inputs.gait_manager.balance.drive=37', 'floor.mu=0.01',
                               'inputs.visual_lifting.kp=[30, 290, 1100]'])
    assert overrides == {'inputs.gait_manager.balance.drive': 37, 'floor.mu': 0.01,
                         'inputs.visual_lifting.kp': [30, 290, 1100]}
    edited = tune.with_settings(skate, overrides)
    assert edited['inputs']['gait_manager']['balance']['drive'] == 37
    assert edited['floor']['mu'] == 0.01 and edited['inputs']['visual_lifting']['kp'] == [
        30, 290, 1100]
    assert skate['floor'].get('mu') != 0.01  # the base scene is left as it was
    with pytest.raises(SystemExit, match='give KEY=VALUE'):
        tune.settings(['balance.drive'])
    with pytest.raises(SystemExit, match="tune_gait.py: --set: .*'balance'"):
        tune.with_settings(skate, tune.settings(['balance.drive=37']))  # the old short form


def test_the_scores_read_the_metrics_by_their_registry_names(tune):
    """The arm-swing score adds the registry's arm_swing_ratio and -corr(q11, q14) only where
    that ratio exists: not when the run without yaw fell, nor when it failed."""
    def run(p2p, corr, **end):
        return {'sim_time_s': 15.0, 'fell': False, 'failure': None,
                'arm_swing': {'mean_peak_to_peak': p2p, 'corr_q11_q14': corr}, **end}
    events = exchanges(np.arange(0.5, 15.0, 0.9))
    base = tune.arm_swing_score(run(0.6, -0.9), run(0.3, 0.5, fell=True, failure='fell'),
                                events, 15.0)
    assert tune.arm_swing_score(run(0.6, -0.9), run(0.3, 0.5, failure='diverged'),
                                events, 15.0) == base
    assert tune.arm_swing_score(run(0.6, -0.9), run(0.3, 0.5), events, 15.0) == pytest.approx(
        base + 2.0 + 2.0 * 0.9)
    with pytest.raises(KeyError):
        tune.read(run(0.6, -0.9), 'arm_swing.correlation')  # no such metric


def test_check_cases_edit_the_scene(tune, skate):
    long = tune.scenario(skate, {'mu': 0.005, 'duration': 60.0})
    assert long['duration'] == 60.0 and long['floor']['mu'] == 0.005
    pushed = tune.scenario(skate, {'mu': 0.002, 'push': (8.0, -150.0)})
    assert pushed['disturbances'] == [{'start': 8.0, 'duration': 0.1, 'frame': 'chest',
                                       'force': [0.0, -150.0, 0.0]}]


def test_the_ice_cycle_is_measured_from_the_fourth_clean_exchange(tune):
    """The share of flat-sole exchanges and the double support per step count from the 4th
    clean exchange to the last: a step here lands on the heel (mode 8 -> 16, the sole flat in
    double support) and hands over from the flat front sole (16 -> 3) every 1 s, 0.3 s of it
    in double support; the first three are heel exchanges (8 -> 4) without double support."""
    events = []
    for k in range(8):
        t = 1.0 + k
        if k < 3:
            events += [{'event': 'E6', 't': t, 'from_mode': 8, 'to_mode': 4}]
        else:
            events += [{'event': 'E6', 't': t, 'from_mode': 16, 'to_mode': 3},
                       {'event': 'E2', 't': t + 0.7, 'from_mode': 3, 'to_mode': 8},
                       {'event': 'E4', 't': t + 0.8, 'from_mode': 8, 'to_mode': 16}]
    share, double = tune.cycle(events)
    assert share == 1.0
    assert double == pytest.approx(0.3)
    events[6] = {**events[6], 'from_mode': 8}  # the 5th exchange from the heel
    assert tune.cycle(events)[0] == pytest.approx(4 / 5)
    assert np.isnan(tune.cycle(events[:5])).all()  # fewer than two exchanges from the 4th
