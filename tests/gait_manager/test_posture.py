"""Posture stabiliser and its moving stance reference (docs/model.md §11.2), on the C++ source:
the reference posture it sends puts the pelvis on the stance target (the core's forward
kinematics), gravity compensation, PD and yaw-spring signs, the null-space projection."""

import numpy as np
import pytest

STANCE_AND_TORSO = [2, 3, 4, 9, 10]
EVERY_JOINT = tuple(range(2, 18))  # the reference of every joint the PD may drive


def _standing_hip(dynamics, obs, bent):
    """Pelvis-centre (y, z) of the standing posture over the flat support foot (core FK)."""
    q = bent.copy()
    q[0] = obs.q[0]
    return dynamics.frame_placement(obs.contact(), q, 'pelvis_centre').translation[1:]


def _reference(obs, command, parameters, **posture):
    """The posture source's reference q_ref (entries 0 and 1 from obs: they are not driven)."""
    cmd = command(obs, parameters(('posture',), posture={'joints': EVERY_JOINT, **posture}))
    q_ref = cmd.command.reference.copy()
    q_ref[0] = obs.q[0]
    q_ref[1] = obs.q[1] if obs.gait_mode.q1_active else 0.0
    return q_ref


CASES = [  # (mode, side, pivot, y0, q1)
    (1, 'right', 'toe', 0.0, 0.0),
    (3, 'left', 'toe', 0.35, 0.0),  # gliding support: y0 != 0
    (2, 'right', 'toe', 0.0, -0.12),  # heel up on the toe pivot
    (12, 'left', 'heel', 0.2, 0.08),  # toe up on the heel pivot, gliding
]


@pytest.mark.parametrize(('mode', 'side', 'pivot', 'y0', 'q1'), CASES)
@pytest.mark.parametrize(('t', 't_touchdown', 'shift'), [
    (1.0, np.nan, (0.0, 0.0)), (1.3, np.nan, (0.05, -0.015)), (1.6, np.nan, (0.10, -0.03)),
    (2.0, 1.75, (0.15, -0.03)), (3.0, 1.75, (0.20, -0.03))])
def test_the_reference_puts_the_pelvis_on_the_moving_stance(make_obs, dynamics, command,
                                                            parameters, bent, mode, side, pivot,
                                                            y0, q1, t, t_touchdown, shift):
    """Forward kinematics of the sent reference puts the pelvis centre at the standing hip
    shifted by the stance schedule (dy1 = 0.1 m, dz1 = 0.03 m over 0.6 s after t_e = 1 s,
    smoothstep; dy2 = 0.1 m over 0.5 s after the heel strike), with the pelvis pitch phi_4 at
    0, the knee forward and the rest of the body at the standing posture."""
    q = bent.copy()
    q[0], q[1] = y0, q1
    q[[3, 9, 11]] = (0.4, 0.1, 0.3)  # the current posture must not matter
    obs = make_obs(t=t, q=q, mode=mode, side=side, pivot=pivot, t_exchange=1.0,
                   t_touchdown=t_touchdown)
    q_ref = _reference(obs, command, parameters)
    reached = dynamics.frame_placement(obs.contact(), q_ref, 'pelvis_centre').translation[1:]
    np.testing.assert_allclose(reached, _standing_hip(dynamics, obs, bent) + shift, atol=1e-9)
    assert q_ref[1:5].sum() == pytest.approx(0.0, abs=1e-12)  # pelvis pitch phi_4 kept at 0
    assert q_ref[3] > 0.0  # knee forward (flexion)
    np.testing.assert_array_equal(q_ref[5:], bent[5:])  # swing leg, torso, arms, neck


def test_the_pelvis_pitch_is_held_at_its_setting(make_obs, dynamics, command, parameters, bent):
    obs = make_obs(t=2.0, t_exchange=1.0, mode=2, q=bent)
    q_ref = _reference(obs, command, parameters, pelvis_pitch=0.1)
    assert q_ref[1:5].sum() == pytest.approx(0.1, abs=1e-12)
    target = _standing_hip(dynamics, obs, bent) + (0.1, -0.03)
    reached = dynamics.frame_placement(obs.contact(), q_ref, 'pelvis_centre').translation[1:]
    np.testing.assert_allclose(reached, target, atol=1e-9)


def test_stance_steps_with_zero_ramp_times(make_obs, dynamics, command, parameters, bent):
    """With T1 = T2 = 0 the shifts are steps at t_e and at the heel strike."""
    obs = make_obs(t=1.0 + 1e-9, t_exchange=1.0, q=bent)
    q_ref = _reference(obs, command, parameters, shift_time1=0.0, shift_time2=0.0)
    reached = dynamics.frame_placement(obs.contact(), q_ref, 'pelvis_centre').translation[1:]
    np.testing.assert_allclose(reached, _standing_hip(dynamics, obs, bent) + (0.1, -0.03),
                               atol=1e-9)


def test_at_the_exchange_the_moving_reference_is_the_standing_one(make_obs, command,
                                                                  parameters, bent):
    q = bent.copy()
    q[[2, 3, 4]] = (0.1, 0.5, -0.3)
    for side in ('right', 'left'):
        obs = make_obs(t=2.0, q=q, t_exchange=2.0, side=side)
        moving = _reference(obs, command, parameters)
        standing = _reference(obs, command, parameters, reference='standing')
        np.testing.assert_allclose(moving, standing, atol=1e-12)
        np.testing.assert_array_equal(standing[2:], bent[2:])


def test_the_standing_reference_is_fixed(make_obs, command, parameters, bent):
    obs = make_obs(t=5.0, t_exchange=1.0, t_touchdown=2.0)
    np.testing.assert_array_equal(_reference(obs, command, parameters, reference='standing'),
                                  bent)
    bend = _reference(obs, command, parameters, reference='standing', bend=0.2)
    np.testing.assert_allclose(bend[2:8], [-0.2, 0.4, -0.2, 0.2, -0.4, 0.2], atol=1e-15)


def test_gravity_compensation_at_the_reference(make_obs, dynamics, torque):
    """At rest on the standing reference the source is g(q) (the core's) on the stance and
    torso joints and nothing else; the swing leg is left uncompensated."""
    obs = make_obs(mode=1)  # q = standing reference, at rest
    tau = torque('posture', obs, posture={'reference': 'standing'})
    g = np.zeros(18)
    g[obs.gait_mode.active] = dynamics.gravity_terms(obs.contact(), obs.q)
    np.testing.assert_allclose(tau[STANCE_AND_TORSO], g[STANCE_AND_TORSO], atol=1e-9)
    others = [j for j in range(18) if j not in STANCE_AND_TORSO]
    assert np.all(tau[others] == 0.0)
    assert abs(g[2]) > 1.0 and np.any(g[[5, 6, 7]] != 0.0)
    off = torque('posture', obs, posture={'reference': 'standing', 'gravity_compensation': False})
    assert np.all(off == 0.0)
    other = torque('posture', obs, posture={'reference': 'standing', 'gravity_joints': [2, 5]})
    np.testing.assert_allclose(other[[2, 5]], g[[2, 5]], atol=1e-9)
    assert np.all(other[[3, 4, 9, 10]] == 0.0)


def test_pd_and_yaw_spring_signs(make_obs, command, torque, parameters, bent):
    q = bent.copy()
    q[3] += 0.1  # knee more flexed than the reference
    q[8] = 0.5  # torso yawed
    q[17] = 0.3  # neck is not driven
    v = np.zeros(18)
    v[9] = 1.0
    v[8] = -0.5
    obs = make_obs(q=q, v=v)
    posture = {'reference': 'standing', 'gravity_compensation': False}
    tau = torque('posture', obs, posture=posture)
    assert tau[3] == pytest.approx(-80.0)
    assert tau[9] == pytest.approx(-16.0)
    assert tau[8] == pytest.approx(-20.0 * 0.5 + 2.0 * 0.5)
    assert tau[17] == 0.0 and tau[0] == 0.0 and tau[1] == 0.0
    assert np.all(tau[[5, 6, 7, 11, 12, 13, 14, 15, 16]] == 0.0)
    cmd = command(obs, parameters(('posture',), posture=posture)).command
    assert cmd.has_impedance  # sent as a joint impedance, run at the physics rate
    assert cmd.stiffness[3] == 800.0 and cmd.damping[3] == 16.0 and cmd.stiffness[8] == 20.0
    assert cmd.stiffness[17] == 0.0 and not np.any(cmd.effort)


def test_the_null_space_projection_does_not_fight_the_head_task(make_obs, dynamics, command,
                                                                parameters, bent):
    """(J_D^+)^T tau_D = 0 with J_D the core's head Jacobian over the driven joints: the
    projected PD makes no head-space force; it is sent as a torque; the yaw spring stays."""
    q = bent.copy()
    q[[2, 3, 4, 9, 10]] += (0.05, 0.2, -0.1, 0.1, -0.05)
    v = np.zeros(18)
    v[8] = 0.3
    obs = make_obs(t=1.4, q=q, v=v, mode=2, t_exchange=1.0)
    projected = command(obs, parameters(('posture',), posture={
        'null_space': True, 'gravity_compensation': False}))
    plain = command(obs, parameters(('posture',), posture={'gravity_compensation': False}))
    assert not projected.command.has_impedance
    tau, free = projected.source_efforts['posture'], plain.source_efforts['posture']
    _psi, jac = dynamics.head_pose(obs.contact(), obs.q)
    jd = jac[:, STANCE_AND_TORSO]
    np.testing.assert_allclose(np.linalg.pinv(jd).T @ tau[STANCE_AND_TORSO], 0.0, atol=1e-9)
    assert np.linalg.norm(tau[STANCE_AND_TORSO]) > 1.0
    assert not np.allclose(tau, free)
    assert tau[8] == pytest.approx(free[8], abs=1e-12) and tau[8] != 0.0
    # the PD minus its head-space part: tau_D = (I - J_D^+ J_D) pd
    pd = free[STANCE_AND_TORSO]
    np.testing.assert_allclose(tau[STANCE_AND_TORSO],
                               pd - jd.T @ (np.linalg.pinv(jd).T @ pd), atol=1e-8)
