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
from iceskate_sim.robot import GRAVITY
from iceskate_sim.runner import run
from iceskate_sim.scene import load_scene, standing_posture


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


def test_walk_scene_walks(tmp_path):
    """The shipped walk scene: several clean support exchanges in 3 s, moving forward."""
    scene = replace(load_scene('walk'), duration=3.0, record_bag=False)
    metrics = run(scene, tmp_path, progress=False)
    assert not metrics['fell'], metrics['failure']
    assert metrics['steps'] >= 4
    assert metrics['forward_distance_m'] > 0.5
