"""Walking stabiliser (posture reference 'balance', docs/model.md §11.3) and the 'com'
weight-transfer rule (§11.5), on the C++ sources: the swing-ankle path its references reach
(the core's forward kinematics), the blend after an exchange, the virtual forward force against
the core's centre-of-mass Jacobian, the ankle strategy, the front knee bound, the push-off, and
the capture-point split of the weight."""

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from iceskate_bringup.runner import run
from iceskate_bringup.scene import load_scene
from iceskate_sim.model.robot import GRAVITY, SOLE_HEEL_Y
from iceskate_sim.run.scene import standing_posture

ANKLE_HEIGHT = 0.07  # m, ankle above the sole (docs/model.md §2.4)
BALANCE = {'reference': 'balance'}


def _balance(command, parameters, obs, start=None, **balance):
    """The walking stabiliser's joint command at ``obs`` (the posture source alone)."""
    return command(obs, parameters(('posture',), posture=BALANCE, balance=balance),
                   start).command


def _joint_yz(dynamics, obs, q, joint):
    """World (y, z) of joint ``joint``'s origin (the core's model of obs's support)."""
    sm = dynamics.robot.support_model(obs.side, obs.pivot)
    data = sm.new_data()
    pin.forwardKinematics(sm.model, data, q)
    return data.oMi[sm.model.getJointId(joint)].translation[1:].copy()


def _swing_ankle(dynamics, command, parameters, obs, **balance):
    """Where the swing ankle is with the swing hip and knee at their references."""
    cmd = _balance(command, parameters, obs, **balance)
    q = obs.q.copy()
    q[[5, 6]] = cmd.reference[[5, 6]]
    return _joint_yz(dynamics, obs, q, 'q7')


@pytest.fixture
def flying(make_obs, bent):
    """Right support on a knee bent 0.6 rad (the whole path within the swing leg's reach),
    left foot in the air since the exchange at t = 1 s, at rest."""
    q = bent.copy()
    q[2:5] = (-0.3, 0.6, -0.3)

    def obs(elapsed: float):
        return make_obs(t=1.0 + elapsed, t_exchange=1.0, q=q, mode=1)
    return obs


def test_the_swing_path_rises_waits_behind_the_hip_and_presses_below_the_floor(
        dynamics, command, parameters, flying):
    """The swing hip and knee references put the ankle on the path: at the exchange 0.15 m
    behind the hip at ankle height; lifted by the clearance over the lift fraction of
    swing_time; with a glide, waiting there until glide_time; at the end press below the floor
    at the landing point y_com + step_length/2 (+ placement_gain (v_com - v_d)), v_com = 0."""
    balance = {'glide_time': 0.3, 'lift_fraction': 0.2, 'descent_start': 0.5}
    swing_time, clearance, press, step, gain, speed = 0.45, 0.04, 0.02, 0.3, 0.2, 0.4
    obs0 = flying(0.0)
    hip_y = _joint_yz(dynamics, obs0, obs0.q, 'q5')[0]
    com_y = dynamics.center_of_mass(obs0.contact(), obs0.q)[1]
    land = com_y + step / 2.0 + gain * (0.0 - speed)
    start = np.array([hip_y - 0.15, ANKLE_HEIGHT])
    np.testing.assert_allclose(_swing_ankle(dynamics, command, parameters, obs0, **balance),
                               start, atol=1e-9)
    for elapsed in np.linspace(0.2 * swing_time, 0.3, 5):  # lifted, waiting behind the hip
        np.testing.assert_allclose(
            _swing_ankle(dynamics, command, parameters, flying(elapsed), **balance),
            start + (0.0, clearance), atol=1e-9)
    end = _swing_ankle(dynamics, command, parameters, flying(0.3 + swing_time), **balance)
    np.testing.assert_allclose(end, (land, ANKLE_HEIGHT - press), atol=1e-9)
    path = np.array([_swing_ankle(dynamics, command, parameters, flying(e), **balance)
                     for e in np.linspace(0.3, 0.3 + swing_time, 19)])
    assert np.all(np.diff(path[:, 0]) > 0.0)  # forward all the way
    assert np.all(np.diff(path[:, 1]) <= 1e-12)  # and down from the clearance
    plain = _swing_ankle(dynamics, command, parameters, flying(0.2),
                         lift_fraction=0.2, descent_start=0.5)
    delayed = _swing_ankle(dynamics, command, parameters, flying(0.5), **balance)
    np.testing.assert_allclose(delayed, plain, atol=1e-9)  # the glide delays the same path


def test_the_swing_knee_bends_forward_and_an_unreachable_point_straightens_the_leg(
        make_obs, dynamics, command, parameters, bent, flying):
    """Along the path the swing knee flexes forward (q6 <= 0); on the straight-kneed stance the
    path's start, 0.79 m below and behind the hip, is out of the leg's 0.78 m reach: the leg is
    straight (q6 = 0) and points at it."""
    for elapsed in np.linspace(0.0, 0.45, 10):
        assert _balance(command, parameters, flying(elapsed)).reference[6] <= 0.0
    obs = make_obs(t=1.0, t_exchange=1.0, q=bent, mode=1)
    reference = _balance(command, parameters, obs).reference
    assert reference[6] == pytest.approx(0.0, abs=1e-3)
    hip = _joint_yz(dynamics, obs, obs.q, 'q5')
    target = np.array([hip[0] - 0.15, ANKLE_HEIGHT])
    assert np.linalg.norm(target - hip) > 0.78
    q = obs.q.copy()
    q[[5, 6]] = reference[[5, 6]]
    reached = _joint_yz(dynamics, obs, q, 'q7') - hip
    direction = (target - hip) / np.linalg.norm(target - hip)
    assert reached @ direction == pytest.approx(0.78, abs=1e-6)
    assert abs(reached[0] * direction[1] - reached[1] * direction[0]) < 1e-6  # along the line


def test_the_landing_point_moves_with_the_speed_error(dynamics, command, parameters, make_obs,
                                                      flying, central_difference):
    """A CoM faster by dv lands placement_gain x dv further (v_com of the core)."""
    v = np.zeros(18)
    v[[2, 3, 4]] = (0.3, -0.2, 0.4)
    still = flying(1.0)
    moving = make_obs(t=2.0, t_exchange=1.0, q=still.q, v=v, mode=1)
    contact = still.contact()
    com_vy = central_difference(lambda x: dynamics.center_of_mass(contact, x)[1], still.q, v)
    shift = (_swing_ankle(dynamics, command, parameters, moving)
             - _swing_ankle(dynamics, command, parameters, still))
    assert shift[0] == pytest.approx(0.2 * com_vy, rel=1e-6) and abs(com_vy) > 0.01
    assert shift[1] == pytest.approx(0.0, abs=1e-12)


def test_no_reference_jump_at_an_exchange(make_obs, command, parameters, bent):
    """Right after an exchange the support knee and ankle references equal the current angles
    (blend 0), so the PD gives no step torque; after the blend they are nominal."""
    q = bent.copy()
    q[2], q[3] = -0.2, 0.4
    now = _balance(command, parameters, make_obs(t=2.0, q=q, t_exchange=2.0))
    assert now.reference[2] == q[2] and now.reference[3] == q[3]
    soon = _balance(command, parameters, make_obs(t=2.0 + 1e-6, q=q, t_exchange=2.0))
    assert soon.reference[3] == pytest.approx(q[3], abs=1e-9)
    later = _balance(command, parameters, make_obs(t=3.0, q=q, t_exchange=2.0))
    assert later.reference[3] == pytest.approx(0.1) and later.reference[2] == pytest.approx(-0.05)
    at_once = _balance(command, parameters, make_obs(t=2.0, q=q, t_exchange=2.0), blend=0.0)
    assert at_once.reference[3] == pytest.approx(0.1)


def test_the_trunk_and_yaw_references(make_obs, command, parameters, bent):
    """q4 holds the pelvis world pitch q1..q4 (+ q9 + q10) at ``trunk``; 9, 10 at 0; the yaw
    spring of the posture block on 8."""
    q = bent.copy()
    q[[9, 10]] = (0.1, -0.04)
    cmd = _balance(command, parameters, make_obs(t=3.0, q=q, t_exchange=2.0), trunk=0.2)
    assert q[1:4].sum() + cmd.reference[4] + q[9] + q[10] == pytest.approx(0.2, abs=1e-12)
    assert cmd.reference[9] == 0.0 and cmd.reference[10] == 0.0
    assert (cmd.stiffness[8], cmd.damping[8], cmd.reference[8]) == (20.0, 2.0, 0.0)


def _com_row(dynamics, obs, central_difference):
    """d y_com / d q_j for j = 2, 3, 4 (the core's centre of mass, central differences)."""
    contact = obs.contact()
    return np.array([central_difference(lambda x: dynamics.center_of_mass(contact, x)[1],
                                        obs.q, np.eye(18)[j]) for j in (2, 3, 4)])


def test_braking_force_is_bounded_by_max_brake(make_obs, dynamics, command, parameters, bent,
                                               central_difference):
    """Far above the desired speed the virtual force is -max_brake: the effort on joints 2-4
    moves by -max_brake times the CoM Jacobian row y."""
    v = np.zeros(18)
    v[0] = 2.0  # gliding much faster than the desired speed
    obs = make_obs(t=1.0, q=bent, v=v, mode=3)
    free = _balance(command, parameters, obs, max_brake=0.0).effort
    braked = _balance(command, parameters, obs, max_brake=25.0).effort
    np.testing.assert_allclose(braked[[2, 3, 4]] - free[[2, 3, 4]],
                               -25.0 * _com_row(dynamics, obs, central_difference), rtol=1e-6)
    assert np.count_nonzero((braked - free)[[0, 1, *range(5, 18)]]) == 0


@pytest.mark.parametrize('t', [0.2, 1.0, 3.5])
def test_drive_and_pace_add_to_the_virtual_force(make_obs, dynamics, command, parameters, bent,
                                                 central_difference, t):
    """drive F_0 (ramped in over 0.5 s) and pace_gain k_p (y_H(0) + v_d t - y_H) add to the
    virtual force; y_H(0) is the head of the first observation (t = 0, here 0.7 m behind)."""
    q = bent.copy()
    q[0] = 0.7
    start, obs = make_obs(t=0.0, q=bent, mode=3), make_obs(t=t, q=q, mode=3)
    base = {'speed_gain': 0.0, 'max_force': 1e3, 'max_brake': 1e3}
    lag = -0.7 + 0.4 * t
    force = 12.0 * min(t / 0.5, 1.0) + 150.0 * lag
    driven = _balance(command, parameters, obs, start, drive=12.0, pace_gain=150.0, **base)
    plain = _balance(command, parameters, obs, start, **base)
    difference = driven.effort - plain.effort
    np.testing.assert_allclose(difference[[2, 3, 4]],
                               force * _com_row(dynamics, obs, central_difference), rtol=1e-6)
    assert np.count_nonzero(difference[[0, 1, *range(5, 18)]]) == 0


@pytest.mark.parametrize('lag', [-0.7, 0.002, 0.7])
def test_the_feedback_limit_bounds_the_speed_and_pace_terms_not_the_drive(
        make_obs, command, parameters, bent, lag):
    """With ``feedback_limit`` L the speed and pace terms together act within [-L, L] N (a lag
    of 0.7 m asks k_p x 0.7 = 105 N, 2 mm asks 0.3 N), and the drive F_0 adds unbounded."""
    q = bent.copy()
    q[0] = 0.4 * 2.0 - lag  # the head lags the pace point by ``lag`` at t = 2 s
    start, obs = make_obs(t=0.0, q=bent, mode=3), make_obs(t=2.0, q=q, mode=3)
    base = {'speed_gain': 0.0, 'max_force': 1e3, 'max_brake': 1e3}
    plain = _balance(command, parameters, obs, start, **base).effort
    unit = _balance(command, parameters, obs, start, drive=1.0, **base).effort - plain
    bounded = _balance(command, parameters, obs, start, pace_gain=150.0, feedback_limit=20.0,
                       drive=12.0, **base).effort
    force = 12.0 + min(max(150.0 * lag, -20.0), 20.0)
    np.testing.assert_allclose(bounded - plain, force * unit, rtol=1e-9, atol=1e-12)


def test_the_ankle_strategy_is_the_com_offset_from_the_ankle(make_obs, dynamics, command,
                                                             parameters, bent,
                                                             central_difference):
    """The com_* terms add k (y_com - y_ankle - offset) + b (v_com - v_ankle) to the support
    ankle; y_ankle from the heel frame (flat sole), velocities by central differences."""
    q = bent.copy()
    q[4] += 0.1  # lean the torso forward: CoM ahead of the ankle
    v = np.zeros(18)
    v[[0, 2, 3, 4, 9]] = [0.3, 0.2, -0.4, 0.5, 0.1]
    obs = make_obs(t=1.0, q=q, v=v, mode=3)  # flat sole gliding at 0.3 m/s
    contact = obs.contact()

    def com_y(x):
        return dynamics.center_of_mass(contact, x)[1]

    def ankle_y(x):
        return dynamics.frame_placement(contact, x, 'support_heel').translation[1] - SOLE_HEEL_Y

    k, b, offset = 150.0, 30.0, 0.02
    expected = (k * (com_y(q) - ankle_y(q) - offset)
                + b * (central_difference(com_y, q, v) - central_difference(ankle_y, q, v)))
    assert abs(com_y(q) - ankle_y(q) - offset) > 0.01  # the position term is not trivial
    difference = (_balance(command, parameters, obs, com_stiffness=k, com_damping=b,
                           com_offset=offset).effort
                  - _balance(command, parameters, obs).effort)
    assert difference[2] == pytest.approx(expected, rel=1e-6)
    assert np.count_nonzero(difference) == 1


@pytest.mark.parametrize(('knee', 'step', 'reference'), [
    (-0.62, 0.0, -0.05), (-0.62, 0.25, -0.37), (-0.2, 0.25, -0.05), (0.4, 0.25, 0.15)])
def test_the_front_knee_reference_steps_at_most_front_knee_step(make_obs, command, parameters,
                                                                bent, knee, step, reference):
    """In double support the front knee is held near straight (-0.05 rad), its reference at
    most ``front_knee_step`` from the current angle; the front hip is held where it is."""
    q = bent.copy()
    q[6] = knee
    obs = make_obs(t=2.0, q=q, mode=7, t_exchange=1.5, t_touchdown=1.9)
    cmd = _balance(command, parameters, obs, front_knee_step=step)
    assert cmd.reference[6] == pytest.approx(reference, abs=1e-12)
    assert cmd.reference[5] == q[5] and cmd.stiffness[5] == 300.0


@pytest.mark.parametrize(('since', 'r'), [(0.0, 0.0), (0.15, 0.5), (0.3, 1.0), (0.6, 1.0)])
def test_the_push_off_after_the_heel_strike(make_obs, command, parameters, bent, since, r):
    """Over push_ramp after the heel strike the rear ankle's stiffness fades to 0, a push-off
    effort ramps to ``push`` and the rear knee reference moves to toe_off_flex (linear)."""
    obs = make_obs(t=1.9 + since, q=bent, mode=17, t_exchange=1.0, t_touchdown=1.9)
    without = _balance(command, parameters, obs, push=0.0)
    cmd = _balance(command, parameters, obs)
    assert cmd.stiffness[2] == pytest.approx(30.0 * (1.0 - r), abs=1e-12)
    assert cmd.effort[2] - without.effort[2] == pytest.approx(20.0 * r, abs=1e-9)
    assert cmd.reference[3] == pytest.approx(0.1 + r * (0.5 - 0.1), abs=1e-12)


def test_the_com_rule_is_the_static_two_foot_split(make_obs, dynamics, command, parameters,
                                                   torque):
    """At rest (capture point = CoM) f_des = m g (y_com - y_rear_toe)/(y_front_heel -
    y_rear_toe), from the core's CoM and frames; tau = -J_c^T f_des, so the ratio of two
    settings' torques is the ratio of their forces."""
    q, pivot = standing_posture('staggered', 0.0, 0.7)
    q[2:8] = -q[2:8]  # swing (front) foot ahead of the support (rear) one
    obs = make_obs(t=1.0, q=q, mode=17, pivot=pivot, t_exchange=0.0, t_touchdown=0.5)
    contact = obs.contact()
    rear_toe = dynamics.frame_placement(contact, q, 'support_toe').translation[1]
    front_heel = dynamics.frame_placement(contact, q, 'swing_heel').translation[1]
    com = dynamics.center_of_mass(contact, q)[1]
    assert rear_toe < com < front_heel
    weight = dynamics.robot.total_mass * GRAVITY
    share = (com - rear_toe) / (front_heel - rear_toe)
    com_rule = {'rule': 'com', 'share': 1.5, 'share_min': 0.0}
    split = torque('weight_transfer', obs, weight_transfer=com_rule)
    full = torque('weight_transfer', obs, weight_transfer={'rule': 'com', 'share': 1.0,
                                                           'share_min': 1.0, 'ramp_time': 0.0})
    j = int(np.argmax(np.abs(full)))
    assert split[j] / full[j] == pytest.approx(share, rel=1e-9)
    np.testing.assert_allclose(split, share * full, rtol=1e-9, atol=1e-9)
    capped = torque('weight_transfer', obs, weight_transfer={**com_rule, 'share': 0.1})
    np.testing.assert_allclose(capped, 0.1 * full, rtol=1e-9, atol=1e-9)
    floor = torque('weight_transfer', obs, weight_transfer={**com_rule, 'share_min': 0.9,
                                                            'ramp_time': 1.0})
    np.testing.assert_allclose(floor, max(share, 0.45) * full, rtol=1e-9, atol=1e-9)
    in_the_air = make_obs(t=1.0, q=q, mode=1, t_exchange=0.0, t_touchdown=0.5)
    assert not np.any(torque('weight_transfer', in_the_air, weight_transfer=com_rule))
    assert weight > 500.0


def test_the_com_rule_puts_no_load_on_a_swing_foot_behind_the_support(make_obs, dynamics,
                                                                       torque):
    """The old support foot touching again behind the new support after an exchange gets
    f_des = 0 whatever the capture point; the same feet the other way round get the floor."""
    q, pivot = standing_posture('staggered', 0.0, 0.7)
    block = {'rule': 'com', 'share': 1.0, 'share_min': 0.5, 'ramp_time': 0.0}
    for sign in (1.0, -1.0):
        feet = q.copy()
        feet[2:8] = sign * q[2:8]
        obs = make_obs(t=1.0, q=feet, v=np.full(18, 0.5), mode=17, pivot=pivot,
                       t_exchange=0.0, t_touchdown=0.5)
        contact = obs.contact()
        behind = (dynamics.frame_placement(contact, feet, 'swing_heel').translation[1]
                  < dynamics.frame_placement(contact, feet, 'support_heel').translation[1])
        assert behind == (sign > 0.0)
        tau = torque('weight_transfer', obs, weight_transfer=block)
        assert np.any(tau) != behind


def test_the_com_rule_bounds_the_share_while_only_the_front_heel_touches(make_obs, torque):
    """heel_share caps f_des / (m g) in the heel modes (Hs, Hp) only; a flat front sole (Fs,
    Fp) gets the whole share."""
    q, pivot = standing_posture('staggered', 0.0, 0.7)
    q[2:8] = -q[2:8]
    block = {'rule': 'com', 'share': 1.0, 'share_min': 0.8, 'ramp_time': 0.0}

    def tau(mode, **changes):
        obs = make_obs(t=1.0, q=q, mode=mode, pivot=pivot, t_exchange=0.0, t_touchdown=0.5)
        return torque('weight_transfer', obs, weight_transfer={**block, **changes})

    for mode, flat_mode in ((9, 17), (5, 13)):  # Hp / Fp, Hs / Fs: the same heel row
        np.testing.assert_allclose(tau(mode, heel_share=0.3), 0.3 / 0.8 * tau(mode),
                                   rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(tau(flat_mode, heel_share=0.3), tau(flat_mode), rtol=1e-12)


def test_the_heel_share_bound_rises_to_the_share_from_heel_time_on(make_obs, torque):
    """heel_time: the bound holds for heel_time s after the heel strike, then rises linearly
    to the share over ramp_time, so a front sole that stays up takes the load on its heel."""
    q, pivot = standing_posture('staggered', 0.0, 0.7)
    q[2:8] = -q[2:8]
    block = {'rule': 'com', 'share': 1.0, 'share_min': 0.8, 'ramp_time': 0.2,
             'heel_share': 0.3}

    def tau(since, **changes):
        obs = make_obs(t=0.5 + since, q=q, mode=9, pivot=pivot, t_exchange=0.0,
                       t_touchdown=0.5)
        return torque('weight_transfer', obs, weight_transfer={**block, **changes})

    assert np.any(tau(0.1))
    np.testing.assert_array_equal(tau(0.1, heel_time=0.2), tau(0.1))  # the bound holds
    np.testing.assert_allclose(tau(0.3, heel_time=0.2), tau(0.3, heel_share=0.65),
                               rtol=1e-12)  # half-way up: 0.3 + (1 - 0.3) / 2
    np.testing.assert_allclose(tau(0.5, heel_time=0.2), tau(0.5, heel_share=2.0),
                               rtol=1e-12)  # risen: the share's own rule
    assert np.linalg.norm(tau(0.5, heel_time=0.2)) > np.linalg.norm(tau(0.5)) * 2.0


def test_the_walk_scene_walks(tmp_path):
    """The shipped walk scene: several clean support exchanges in 3 s, moving forward."""
    scene = replace(load_scene('walk'), duration=3.0, record_bag=False)
    metrics = run(scene, tmp_path, progress=False)
    assert not metrics['fell'], metrics['failure']
    assert metrics['steps'] >= 4
    assert metrics['forward_distance_m'] > 0.5
