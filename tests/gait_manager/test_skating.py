"""Ice-skate walking: the acceptance criteria of the gait, measured on the shipped scenes.

One 15 s run of ``skate``, ``skate_literal`` (eq. (10) read as printed) and ``skate_no_yaw``
(headless, no bag) per test session.
"""

from dataclasses import replace
import json

import numpy as np
import pytest

from iceskate_bringup.runner import run
from iceskate_bringup.scene import load_scene, parse_scene
from iceskate_sim.run.metrics import arm_swing_ratio
from iceskate_sim.run.scene import scene_raw

EDGE_MODES = {2, 4, 6, 8, 10, 12, 14, 16, 18, 20}  # support on its toe or heel edge (Table 2)


@pytest.fixture(scope='module')
def skate_runs(tmp_path_factory):
    """{scene: (metrics, events, trajectory arrays)} of the full shipped runs."""
    runs = {}
    for name in ('skate', 'skate_literal', 'skate_no_yaw'):
        out = tmp_path_factory.mktemp(name)
        metrics = run(replace(load_scene(name), record_bag=False), out, progress=False)
        events = json.loads((out / 'events.json').read_text())
        runs[name] = metrics, events, dict(np.load(out / 'trajectory.npz'))
    return runs


@pytest.mark.parametrize('name', ['skate', 'skate_literal', 'skate_no_yaw'])
def test_skates_at_the_papers_cadence_without_falling(skate_runs, name):
    """15 s without a fall; from the 4th support exchange a step every 0.8-1.0 s (eq. (10)'s
    T/2 = 0.93 s) with a coefficient of variation under 10 %."""
    metrics, events, _ = skate_runs[name]
    assert not metrics['fell'], metrics['failure']
    assert metrics['sim_time_s'] == pytest.approx(15.0, abs=1e-9)
    exchanges = [e['t'] for e in events if e['event'] == 'E6']
    assert len(exchanges) == metrics['steps'] >= 12
    periods = np.diff(exchanges[3:])
    assert 0.8 <= periods.mean() <= 1.0 and periods.std() / periods.mean() <= 0.1, periods


@pytest.mark.parametrize('name', ['skate', 'skate_literal', 'skate_no_yaw'])
def test_the_head_keeps_pace_with_the_visual_lifting_target(skate_runs, name):
    """The target moves at the gait's speed and the robot keeps it: head y error RMS <= 5 cm
    over the whole run, height within 7.5 mm and pitch within 5 mrad RMS."""
    rms = skate_runs[name][0]['head_error_rms']
    assert rms['y'] <= 0.05 and rms['z'] <= 0.0075 and rms['pitch'] <= 0.005, rms

@pytest.mark.parametrize('name', ['skate', 'skate_literal', 'skate_no_yaw'])
def test_the_head_moves_forward_at_every_step(skate_runs, name):
    """Forward distance grows step by step: the head top is further ahead at every exchange."""
    _, events, a = skate_runs[name]
    exchanges = [e['t'] for e in events if e['event'] == 'E6']
    head_y = np.interp(exchanges, a['t'], a['psi'][:, 0])
    assert np.all(np.diff(head_y) > 0.05), np.diff(head_y)


def test_the_skate_glides_and_tips_on_its_edges(skate_runs):
    """Support gliding (3 or 4) and edge-tipping modes (support on toe or heel) are visited,
    most of the time is a glide on a flat sole alone (mode 3), and the support foot glides
    forward only (toe pick: y0 never decreases within a step)."""
    _, _, a = skate_runs['skate']
    modes = set(a['mode'].tolist())
    assert modes & {3, 4} and modes & EDGE_MODES
    assert np.mean(a['mode'] == 3) > 0.5
    fraction_on_edge = np.isin(a['mode'], list(EDGE_MODES)).mean()
    assert 0.05 < fraction_on_edge < 0.95
    same_step = np.diff(a['step_index']) == 0
    assert np.all(np.diff(a['q'][:, 0])[same_step] >= -1e-9)


@pytest.mark.parametrize('name', ['skate', 'skate_literal'])
def test_the_yaw_input_swings_the_arms_in_anti_phase(skate_runs, name):
    """From the 4th step on (the arm assist released), over the whole window to the end of the
    run and over its second half: with tau8 (either reading of eq. (10)) corr(q11, q14) <= -0.5,
    without it > -0.5, and the arm-swing ratio at least 3 (the paper's result)."""
    runs = {key: skate_runs[key][0] for key in (name, 'skate_no_yaw')}
    for key in ('arm_swing', 'arm_swing_steady'):
        swing, reference = runs[name][key], runs['skate_no_yaw'][key]
        assert swing['corr_q11_q14'] <= -0.5, key
        assert reference['corr_q11_q14'] > -0.5, key
        ratio = arm_swing_ratio({'arm_swing': swing}, {'arm_swing': reference})
        assert ratio >= 3.0, (key, ratio)
    steady = runs[name]['arm_swing_steady']
    assert 2000 < steady['samples'] < runs[name]['arm_swing']['samples']


def _shoulder_speeds(events: list[dict], a: dict, release: float) -> tuple[np.ndarray, ...]:
    """RMS speeds of q11, q14 [rad/s] over the 0.3 s before the 3rd exchange (the 4th step's
    start) and over the last 0.1 s of the release after it."""
    start = [e['t'] for e in events if e['event'] == 'E6'][2]

    def rms(begin: float, end: float) -> np.ndarray:
        window = (a['t'] >= begin) & (a['t'] < end)
        return np.sqrt(np.mean(a['v'][window][:, [11, 14]] ** 2, axis=0))
    return rms(start - 0.3, start), rms(start + release - 0.1, start + release)


def test_the_release_brakes_the_swing_the_arm_assist_left(skate_runs, tmp_path):
    """Without tau8, the shoulder brake at the start of the 4th step takes out most of the
    swing the arm assist gave: at the brake's end the shoulders' RMS speed is under half of
    what it was just before the exchange, and well under what it is then when the arms are
    let go at once (release_time 0)."""
    raw = scene_raw('skate_no_yaw')
    release = raw['inputs']['gait_manager']['arm_assist']['release_time']
    assert release > 0.0
    raw['inputs']['gait_manager']['arm_assist']['release_time'] = 0.0
    raw['duration'], raw['record'] = 4.0, {'bag': False}
    run(parse_scene(raw), tmp_path, progress=False)
    free = np.load(tmp_path / 'trajectory.npz')
    _, free_end = _shoulder_speeds(json.loads((tmp_path / 'events.json').read_text()), free,
                                   release)
    _, events, a = skate_runs['skate_no_yaw']
    before, braked_end = _shoulder_speeds(events, a, release)
    assert np.all(braked_end < 0.5 * before), (before, braked_end)
    assert np.all(braked_end < 0.7 * free_end), (free_end, braked_end)


def _pushed_skate(start: float, force: float, duration: float = 15.0) -> dict:
    """The shipped skate scene (no bag, ``duration`` [s]) with a 0.1 s chest push of ``force``
    [N] (> 0: forward) from ``start`` [s]."""
    raw = scene_raw('skate')
    raw['duration'], raw['record'] = duration, {'bag': False}
    raw['disturbances'] = [{'start': start, 'duration': 0.1, 'frame': 'chest',
                            'force': [0.0, force, 0.0]}]
    return raw


@pytest.mark.parametrize(('start', 'force'), [(6.5, 150.0), (6.5, -150.0), (6.35, -150.0)])
def test_a_chest_push_after_the_fourth_step_is_survived(tmp_path, start, force):
    """A 150 N x 0.1 s (15 N s) chest push, forward or backward (at 6.35 s: mid-glide, the
    robot then lands short, in double support): no fall to the end of the 15 s run, and the
    gait steps on after it (forward: the bounded speed feedback lets the robot keep the speed
    it got instead of braking its support foot out from under it)."""
    metrics = run(parse_scene(_pushed_skate(start, force)), tmp_path, progress=False)
    assert not metrics['fell'], metrics['failure']
    assert metrics['sim_time_s'] == pytest.approx(15.0, abs=1e-9)
    events = json.loads((tmp_path / 'events.json').read_text())
    assert sum(e['event'] == 'E6' and e['t'] > start + 0.1 for e in events) >= 8


def test_without_the_front_knee_bound_a_short_landing_leaves_the_floor(tmp_path):
    """The backward push at 6.35 s with the front knee's reference step unbounded
    (front_knee_step 0): the knee, bent by the short landing, straightens at once and vaults
    the body off both feet (flight) before 7 s."""
    raw = _pushed_skate(6.35, -150.0, duration=7.0)
    raw['inputs']['gait_manager']['balance']['front_knee_step'] = 0.0
    metrics = run(parse_scene(raw), tmp_path, progress=False)
    assert metrics['fell'] and metrics['failure'].startswith('flight'), metrics['failure']


def test_without_the_feedback_bound_a_forward_push_is_a_fall(tmp_path):
    """The same forward push with the speed and pace terms unbounded (feedback_limit 0): the
    braking drives the support foot out and the robot falls before 9 s."""
    raw = _pushed_skate(6.5, 150.0, duration=9.0)
    raw['inputs']['gait_manager']['balance']['feedback_limit'] = 0.0
    metrics = run(parse_scene(raw), tmp_path, progress=False)
    assert metrics['fell'], 'survived without the bound'


def test_skate_glide_skates_the_papers_ice_cycle(tmp_path):
    """``skate_glide``: from the 4th exchange on, at least 80 % of the exchanges come from a
    flat front sole (a mode with the swing sole flat, 13-20) after at least 0.1 s of double
    support per step, a step every 0.8-1.0 s, 15 s without a fall, the head on its target."""
    metrics = run(replace(load_scene('skate_glide'), record_bag=False), tmp_path, progress=False,
                  picture=False)
    assert not metrics['fell'], metrics['failure']
    events = json.loads((tmp_path / 'events.json').read_text())
    exchanges = [e for e in events if e['event'] == 'E6'][3:]
    assert np.mean([e['from_mode'] >= 13 for e in exchanges]) >= 0.8
    start, end = exchanges[0]['t'], exchanges[-1]['t']
    entered = [(e['t'], e['to_mode']) for e in events if start <= e['t'] <= end]
    double = sum(min(b, end) - a for (a, mode), (b, _) in zip(entered, entered[1:], strict=False)
                 if mode >= 5)
    assert double / (len(exchanges) - 1) >= 0.1
    periods = np.diff([e['t'] for e in exchanges])
    assert 0.8 <= periods.mean() <= 1.0 and periods.std() / periods.mean() <= 0.1, periods
    rms = metrics['head_error_rms']
    assert rms['y'] <= 0.05 and rms['z'] <= 0.007, rms
