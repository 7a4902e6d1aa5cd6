"""Walking stabiliser (gait_manager.balance) and the 'com' weight-transfer rule."""

from dataclasses import replace
import math

import numpy as np
import pytest

from gait_manager.balance import (
    ANKLE_HEIGHT,
    BalanceParameters,
    balance_command,
    leg_ik,
    swing_ankle_target,
)
from gait_manager.errors import GaitManagerError
from gait_manager.feedforward import WeightTransferParameters, capture_split_force
from iceskate_bringup.runner import run
from iceskate_bringup.scene import load_scene
from iceskate_sim.robot import GRAVITY, SOLE_HEEL_Y
from iceskate_sim.scene import standing_posture


@pytest.mark.parametrize('target', [(0.1, -0.7), (-0.15, -0.72), (0.3, -0.6), (0.0, -0.5)])
def test_leg_ik_reaches_the_target_with_the_knee_forward(target):
    thigh, shank = 0.38, 0.40
    phi_thigh, phi_shank = leg_ik(*target, thigh, shank)
    ankle = (thigh * math.sin(phi_thigh) + shank * math.sin(phi_shank),
             -thigh * math.cos(phi_thigh) - shank * math.cos(phi_shank))
    assert ankle == pytest.approx(target, abs=1e-12)
    assert phi_thigh >= phi_shank  # knee forward: swing knee q6 = phi_shank - phi_thigh <= 0


def test_leg_ik_out_of_reach_points_the_straight_leg_at_the_target():
    phi_thigh, phi_shank = leg_ik(0.5, -1.0, 0.38, 0.40)
    assert phi_thigh == pytest.approx(phi_shank, abs=1e-3)  # acos near 1: sqrt round-off
    assert phi_thigh == pytest.approx(math.atan2(0.5, 1.0), abs=1e-3)


def test_swing_path_rises_then_presses_below_the_floor(make_obs):
    p = BalanceParameters()
    heights = [swing_ankle_target(make_obs(t=s * p.swing_time), p, 0.0, 0.0, p.speed)[1]
               for s in np.linspace(0.0, 1.0, 41)]
    assert heights[0] == pytest.approx(ANKLE_HEIGHT)
    assert max(heights) == pytest.approx(ANKLE_HEIGHT + p.clearance)
    assert heights[-1] == pytest.approx(ANKLE_HEIGHT - p.press)
    y_end, _ = swing_ankle_target(make_obs(t=p.swing_time), p, 0.0, 0.2, p.speed + 0.1)
    assert y_end == pytest.approx(0.2 + p.step_length / 2 + p.placement_gain * 0.1)


def test_balance_parameters_are_validated():
    with pytest.raises(GaitManagerError, match='balance.swing_time'):
        BalanceParameters.from_dict({'swing_time': -1.0})
    with pytest.raises(GaitManagerError, match='balance.nonsense'):
        BalanceParameters.from_dict({'nonsense': 1.0})


def test_no_reference_jump_at_an_exchange(make_obs, dynamics):
    """Right after an exchange the support knee and ankle references equal the current
    angles (blend 0), so the PD gives no step torque."""
    q = standing_posture('bent_knees', 0.05, 0.0)[0]
    q[2], q[3] = -0.2, 0.4
    cmd = balance_command(make_obs(t=2.0, q=q, t_exchange=2.0), dynamics, BalanceParameters(),
                          20.0, 2.0)
    assert cmd.reference[2] == q[2] and cmd.reference[3] == q[3]
    later = balance_command(make_obs(t=3.0, q=q, t_exchange=2.0), dynamics,
                            BalanceParameters(), 20.0, 2.0)
    assert later.reference[3] == pytest.approx(BalanceParameters().stance_knee)


def test_com_rule_is_the_static_two_foot_split(make_obs, dynamics):
    """At rest (capture point = CoM) f_des = m g (y_com - y_rear_toe)/(y_front_heel -
    y_rear_toe), computed here from GaitDynamics' own CoM and frames."""
    q, pivot = standing_posture('staggered', 0.0, 0.7)
    q[2:8] = -q[2:8]  # swing (front) foot ahead of the support (rear) one
    obs = make_obs(t=1.0, q=q, mode=17, pivot=pivot, t_exchange=0.0, t_touchdown=0.5)
    contact = obs.contact()
    rear_toe = dynamics.frame_placement(contact, q, 'support_toe').translation[1]
    front_heel = dynamics.frame_placement(contact, q, 'swing_heel').translation[1]
    com = dynamics.center_of_mass(contact, q)[1]
    assert rear_toe < com < front_heel
    weight = dynamics.robot.total_mass * GRAVITY
    params = WeightTransferParameters(rule='com', share=1.5, share_min=0.0)
    expected = weight * (com - rear_toe) / (front_heel - rear_toe)
    assert capture_split_force(obs, dynamics, params) == pytest.approx(expected, rel=1e-9)
    capped = replace(params, share=0.1)
    assert capture_split_force(obs, dynamics, capped) == pytest.approx(0.1 * weight)
    floor = replace(params, share_min=0.9, ramp_time=1.0)
    assert capture_split_force(obs, dynamics, floor) == pytest.approx(
        max(expected, 0.45 * weight))
    assert capture_split_force(make_obs(t=1.0, q=q, mode=1), dynamics, params) == 0.0


def test_com_rule_puts_no_load_on_a_swing_foot_behind_the_support(make_obs, dynamics):
    """The old support foot touching again behind the new support after an exchange: its
    heel lies behind the support heel and gets f_des = 0 whatever the capture point, while the
    same feet the other way round (the swing foot ahead) get the floor share."""
    q, pivot = standing_posture('staggered', 0.0, 0.7)
    params = WeightTransferParameters(rule='com', share=1.0, share_min=0.5, ramp_time=0.0)
    weight = dynamics.robot.total_mass * GRAVITY
    for sign, expected_at_least in ((1.0, None), (-1.0, 0.5 * weight)):
        feet = q.copy()
        feet[2:8] = sign * q[2:8]
        obs = make_obs(t=1.0, q=feet, v=np.full(18, 0.5), mode=17, pivot=pivot,
                       t_exchange=0.0, t_touchdown=0.5)
        contact = obs.contact()
        behind = (dynamics.frame_placement(contact, feet, 'swing_heel').translation[1]
                  < dynamics.frame_placement(contact, feet, 'support_heel').translation[1])
        assert behind == (sign > 0.0)
        force = capture_split_force(obs, dynamics, params)
        if expected_at_least is None:
            assert force == 0.0
        else:
            assert force >= expected_at_least


def test_com_rule_bounds_the_share_while_only_the_front_heel_touches(make_obs, dynamics):
    """heel_share caps f_des / (m g) in the heel modes (Hs, Hp) only; a flat front sole (Fs,
    Fp) gets the whole share."""
    q, pivot = standing_posture('staggered', 0.0, 0.7)
    q[2:8] = -q[2:8]  # swing (front) foot ahead of the support (rear) one
    weight = dynamics.robot.total_mass * GRAVITY
    params = WeightTransferParameters(rule='com', share=1.0, share_min=0.8, ramp_time=0.0,
                                      heel_share=0.3)
    for mode, expected in ((9, 0.3), (5, 0.3), (17, None), (13, None)):  # Hp, Hs, Fp, Fs
        obs = make_obs(t=1.0, q=q, mode=mode, pivot=pivot, t_exchange=0.0, t_touchdown=0.5)
        force = capture_split_force(obs, dynamics, params)
        if expected is None:
            assert force >= 0.8 * weight
        else:
            assert force == pytest.approx(expected * weight)
    unbounded = replace(params, heel_share=WeightTransferParameters().heel_share)
    assert capture_split_force(make_obs(t=1.0, q=q, mode=9, pivot=pivot, t_exchange=0.0,
                                        t_touchdown=0.5), dynamics, unbounded) >= 0.8 * weight


def test_walk_scene_walks(tmp_path):
    """The shipped walk scene: several clean support exchanges in 3 s, moving forward."""
    scene = replace(load_scene('walk'), duration=3.0, record_bag=False)
    metrics = run(scene, tmp_path, progress=False)
    assert not metrics['fell'], metrics['failure']
    assert metrics['steps'] >= 4
    assert metrics['forward_distance_m'] > 0.5


def _central_difference(f, q: np.ndarray, direction: np.ndarray, h: float = 1e-6) -> float:
    return (f(q + h * direction) - f(q - h * direction)) / (2.0 * h)


def test_ankle_com_feedback_is_the_com_offset_from_the_ankle(make_obs, dynamics):
    """The com_* terms add k (y_com - y_ankle - offset) + b (v_com - v_ankle) to the support
    ankle; y_ankle from the heel frame (flat sole), velocities by central differences."""
    q = standing_posture('bent_knees', 0.05, 0.0)[0]
    q[4] += 0.1  # lean the torso forward: CoM ahead of the ankle
    v = np.zeros(18)
    v[[0, 2, 3, 4, 9]] = [0.3, 0.2, -0.4, 0.5, 0.1]
    obs = make_obs(t=1.0, q=q, v=v, mode=3)  # flat sole gliding at 0.3 m/s
    contact = obs.contact()
    base = BalanceParameters()
    k, b, offset = 150.0, 30.0, 0.02
    with_feedback = replace(base, com_stiffness=k, com_damping=b, com_offset=offset)

    def com_y(x: np.ndarray) -> float:
        return dynamics.center_of_mass(contact, x)[1]

    def ankle_y(x: np.ndarray) -> float:
        return dynamics.frame_placement(contact, x, 'support_heel').translation[1] - SOLE_HEEL_Y

    expected = (k * (com_y(q) - ankle_y(q) - offset)
                + b * (_central_difference(com_y, q, v) - _central_difference(ankle_y, q, v)))
    assert abs(com_y(q) - ankle_y(q) - offset) > 0.01  # the position term is not trivial
    difference = (balance_command(obs, dynamics, with_feedback, 20.0, 2.0).effort
                  - balance_command(obs, dynamics, base, 20.0, 2.0).effort)
    assert difference[2] == pytest.approx(expected, rel=1e-6)
    assert np.count_nonzero(difference) == 1


def test_braking_force_is_bounded_by_max_brake(make_obs, dynamics):
    """Far above the desired speed the virtual force is -max_brake: the effort on joints 2-4
    moves by -max_brake times the CoM Jacobian row y (central differences)."""
    q = standing_posture('bent_knees', 0.05, 0.0)[0]
    v = np.zeros(18)
    v[0] = 2.0  # gliding much faster than params.speed
    obs = make_obs(t=1.0, q=q, v=v, mode=3)
    contact = obs.contact()
    brake = 25.0
    free = balance_command(obs, dynamics, replace(BalanceParameters(), max_brake=0.0), 20.0, 2.0)
    braked = balance_command(obs, dynamics, replace(BalanceParameters(), max_brake=brake),
                             20.0, 2.0)
    for j in (2, 3, 4):
        jac = _central_difference(lambda x: dynamics.center_of_mass(contact, x)[1], q,
                                  np.eye(18)[j])
        assert braked.effort[j] - free.effort[j] == pytest.approx(-brake * jac, rel=1e-6)


def _speed_joint_efforts(obs, dynamics, params: BalanceParameters,
                         head_start_y: float = 0.0) -> np.ndarray:
    return balance_command(obs, dynamics, params, 20.0, 2.0, head_start_y).effort


@pytest.mark.parametrize('t', [0.2, 1.0, 3.5])
def test_drive_and_pace_terms_add_to_the_virtual_force(make_obs, dynamics, t):
    """drive F_0 (ramped over 0.5 s) and pace_gain k_p (y_H(0) + v_d t - y_H) add to the
    virtual force: the efforts of joints 2-4 move by that force times the CoM Jacobian row y
    (central differences), y_H from the head-top frame; nothing else moves."""
    q = standing_posture('bent_knees', 0.05, 0.0)[0]
    obs = make_obs(t=t, q=q, mode=3)
    contact = obs.contact()
    base = replace(BalanceParameters(), speed_gain=0.0, max_force=1e3, max_brake=1e3)
    drive, pace, start = 12.0, 150.0, -0.7
    head_y = dynamics.frame_placement(contact, q, 'head_top').translation[1]
    lag = start + base.speed * t - head_y
    assert abs(lag) > 0.1  # the pace term is not trivial
    force = drive * min(t / 0.5, 1.0) + pace * lag
    difference = (_speed_joint_efforts(obs, dynamics, replace(base, drive=drive, pace_gain=pace),
                                       start)
                  - _speed_joint_efforts(obs, dynamics, base, start))
    for j in (2, 3, 4):
        jac = _central_difference(lambda x: dynamics.center_of_mass(contact, x)[1], q,
                                  np.eye(18)[j])
        assert difference[j] == pytest.approx(force * jac, rel=1e-6)
    assert np.count_nonzero(difference[[0, 1, *range(5, 18)]]) == 0


def test_pace_point_starts_at_the_head_and_moves_at_the_speed(make_obs, dynamics):
    """With the head on the pace point (start = y_H - v_d t) the pace term is zero; a start 1 cm
    further ahead pulls forward by k_p x 1 cm."""
    q = standing_posture('bent_knees', 0.05, 0.0)[0]
    obs = make_obs(t=2.0, q=q, mode=3)
    head_y = dynamics.frame_placement(obs.contact(), q, 'head_top').translation[1]
    base = replace(BalanceParameters(), speed_gain=0.0)
    paced = replace(base, pace_gain=300.0)
    on_point = head_y - base.speed * obs.t
    np.testing.assert_allclose(_speed_joint_efforts(obs, dynamics, paced, on_point),
                               _speed_joint_efforts(obs, dynamics, base, on_point), atol=1e-12)
    ahead = (_speed_joint_efforts(obs, dynamics, paced, on_point + 0.01)
             - _speed_joint_efforts(obs, dynamics, base, on_point + 0.01))
    unit = (_speed_joint_efforts(obs, dynamics, replace(base, drive=1.0), on_point)
            - _speed_joint_efforts(obs, dynamics, base, on_point))  # J_com,y^T x 1 N
    np.testing.assert_allclose(ahead, 3.0 * unit, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize('lag', [-0.7, 0.002, 0.7])
def test_the_feedback_limit_bounds_the_speed_and_pace_terms_not_the_drive(make_obs, dynamics,
                                                                         lag):
    """With ``feedback_limit`` L the speed and pace terms together act within [-L, L] N (a
    pace lag of +-0.7 m asks k_p x 0.7 = 105 N; 2 mm asks 0.3 N, inside the bound), and the
    drive F_0 adds to them unbounded by L."""
    q = standing_posture('bent_knees', 0.05, 0.0)[0]
    obs = make_obs(t=2.0, q=q, mode=3)
    head_y = dynamics.frame_placement(obs.contact(), q, 'head_top').translation[1]
    base = replace(BalanceParameters(), speed_gain=0.0, max_force=1e3, max_brake=1e3)
    start = head_y - base.speed * obs.t + lag
    unit = (_speed_joint_efforts(obs, dynamics, replace(base, drive=1.0), start)
            - _speed_joint_efforts(obs, dynamics, base, start))  # J_com,y^T x 1 N
    limit, pace, drive = 20.0, 150.0, 12.0
    bounded = replace(base, pace_gain=pace, feedback_limit=limit, drive=drive)
    force = drive + min(max(pace * lag, -limit), limit)
    np.testing.assert_allclose(_speed_joint_efforts(obs, dynamics, bounded, start)
                               - _speed_joint_efforts(obs, dynamics, base, start),
                               force * unit, rtol=1e-9, atol=1e-12)


def test_the_glide_holds_the_lifted_foot_behind_the_hip_then_swings(make_obs):
    """With glide_time G the forward path is the plain one delayed by G: the foot, once lifted
    to the clearance, waits 0.15 m behind the hip until G."""
    plain = BalanceParameters(lift_fraction=0.2, descent_start=0.5)
    glide = BalanceParameters(lift_fraction=0.2, descent_start=0.5, glide_time=0.3)
    lifted = plain.lift_fraction * plain.swing_time
    for t in np.linspace(lifted, glide.glide_time, 7):
        y, z = swing_ankle_target(make_obs(t=t), glide, 1.0, 1.2, glide.speed)
        assert y == pytest.approx(1.0 - 0.15, abs=1e-12)
        assert z == pytest.approx(ANKLE_HEIGHT + glide.clearance, abs=1e-12)
    for t in np.linspace(lifted, plain.swing_time, 9):
        assert swing_ankle_target(make_obs(t=t + glide.glide_time), glide, 1.0, 1.2, 0.3) == \
            pytest.approx(swing_ankle_target(make_obs(t=t), plain, 1.0, 1.2, 0.3), abs=1e-12)


@pytest.mark.parametrize(('knee', 'step', 'reference'), [
    (-0.62, 0.0, -0.05), (-0.62, 0.25, -0.37), (-0.2, 0.25, -0.05), (0.4, 0.25, 0.15)])
def test_the_front_knee_reference_steps_at_most_front_knee_step(make_obs, dynamics, knee, step,
                                                                reference):
    """In double support the front knee is held near straight (-0.05 rad); with
    ``front_knee_step`` its reference lies at most that far from the current angle, so a knee
    bent by a short landing straightens with a bounded torque rather than vaulting the body."""
    q = standing_posture('bent_knees', 0.05, 0.0)[0]
    q[6] = knee
    obs = make_obs(t=2.0, q=q, mode=7, t_exchange=1.5, t_touchdown=1.9)
    cmd = balance_command(obs, dynamics, BalanceParameters(front_knee_step=step), 20.0, 2.0)
    assert cmd.reference[6] == pytest.approx(reference, abs=1e-12)
