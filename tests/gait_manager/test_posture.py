"""Posture stabiliser and its moving stance reference (docs/model.md, posture stabiliser)."""

import numpy as np
import pytest

from gait_manager.errors import GaitManagerError
from gait_manager.posture import (
    PostureParameters,
    hip_target,
    posture_torque,
    stance_reference,
    standing_posture,
)
from iceskate_sim.scene import standing_posture as scene_posture

BENT = scene_posture('bent_knees', 0.05, 0.0)[0]  # the bent-knee standing posture, a = 0.05 rad
STANCE_AND_TORSO = [2, 3, 4, 9, 10]


def _standing_hip(dynamics, obs):
    """Pelvis-centre (y, z) of the standing posture over the flat support foot (core FK)."""
    q = BENT.copy()
    q[0] = obs.q[0]
    return dynamics.frame_placement(obs.contact(), q, 'pelvis_centre').translation[1:]


CASES = [  # (mode, side, pivot, y0, q1)
    (1, 'right', 'toe', 0.0, 0.0),
    (3, 'left', 'toe', 0.35, 0.0),  # gliding support: y0 != 0
    (2, 'right', 'toe', 0.0, -0.12),  # heel up on the toe pivot
    (12, 'left', 'heel', 0.2, 0.08),  # toe up on the heel pivot, gliding
]


@pytest.mark.parametrize(('mode', 'side', 'pivot', 'y0', 'q1'), CASES)
@pytest.mark.parametrize(('t', 't_touchdown'), [(1.0, np.nan), (1.3, np.nan), (1.6, np.nan),
                                                (2.0, 1.7), (3.0, 1.7)])
def test_ik_puts_the_pelvis_on_the_target(make_obs, dynamics, mode, side, pivot, y0, q1, t,
                                          t_touchdown):
    q = BENT.copy()
    q[0], q[1] = y0, q1
    q[[3, 9, 11]] = (0.4, 0.1, 0.3)  # the current posture must not matter
    obs = make_obs(t=t, q=q, mode=mode, side=side, pivot=pivot, t_exchange=1.0,
                   t_touchdown=t_touchdown)
    params = PostureParameters()
    target = hip_target(obs, dynamics, params)
    q_ref, offset = stance_reference(obs, dynamics, params)
    reached = dynamics.frame_placement(obs.contact(), q_ref, 'pelvis_centre').translation
    np.testing.assert_allclose(reached[1:], target, rtol=0, atol=1e-9)
    assert q_ref[1:5].sum() == pytest.approx(0.0, abs=1e-12)  # pelvis pitch phi_4 kept at 0
    assert q_ref[3] > 0.0  # knee forward (flexion)
    np.testing.assert_array_equal(q_ref[5:], BENT[5:])  # swing leg, torso, arms, neck
    assert q_ref[0] == y0 and q_ref[1] == q1
    # the target itself: the standing hip shifted by (dy, dz), checked against the core's FK
    np.testing.assert_allclose(target, _standing_hip(dynamics, obs) + offset, atol=1e-12)


def test_target_shift_profile(make_obs, dynamics):
    params = PostureParameters()
    base = _standing_hip(dynamics, make_obs())

    def shift(t, t_touchdown=np.nan):
        return hip_target(make_obs(t=t, t_exchange=1.0, t_touchdown=t_touchdown), dynamics,
                          params) - base

    np.testing.assert_allclose(shift(1.0), [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(shift(1.3), [0.05, -0.015], atol=1e-12)  # smoothstep midpoint
    np.testing.assert_allclose(shift(1.6), [0.10, -0.03], atol=1e-12)
    np.testing.assert_allclose(shift(2.0, 1.75), [0.15, -0.03], atol=1e-12)
    np.testing.assert_allclose(shift(2.5, 1.75), [0.20, -0.03], atol=1e-12)


def test_stance_reference_at_the_exchange_is_the_standing_reference(make_obs, dynamics):
    q = BENT.copy()
    q[[2, 3, 4]] = (0.1, 0.5, -0.3)
    for side in ('right', 'left'):
        obs = make_obs(t=2.0, q=q, t_exchange=2.0, side=side)
        moving = stance_reference(obs, dynamics, PostureParameters())
        standing = stance_reference(obs, dynamics, PostureParameters(reference='standing'))
        np.testing.assert_allclose(moving.q_ref, standing.q_ref, atol=1e-12)
        np.testing.assert_allclose(moving.head_offset, [0.0, 0.0], atol=1e-15)
        np.testing.assert_array_equal(standing.q_ref, standing_posture(PostureParameters()))


def test_standing_reference_is_fixed(make_obs, dynamics):
    params = PostureParameters(reference='standing')
    obs = make_obs(t=5.0, t_exchange=1.0, t_touchdown=2.0)
    q_ref, offset = stance_reference(obs, dynamics, params)
    np.testing.assert_array_equal(q_ref, BENT)
    np.testing.assert_array_equal(offset, [0.0, 0.0])
    moving = stance_reference(obs, dynamics, PostureParameters())
    np.testing.assert_allclose(moving.head_offset, [0.2, -0.03])
    np.testing.assert_array_equal(moving.head_offset, PostureParameters().stance.shift(obs))


def test_gravity_compensation_at_the_reference(make_obs, dynamics):
    obs = make_obs(mode=1)  # q = standing reference, at rest
    tau = posture_torque(obs, dynamics, PostureParameters(reference='standing'))
    g = np.zeros(18)
    g[obs.gait_mode.active] = dynamics.gravity_terms(obs.contact(), obs.q)
    np.testing.assert_allclose(tau[STANCE_AND_TORSO], g[STANCE_AND_TORSO], atol=1e-12)
    others = [j for j in range(18) if j not in STANCE_AND_TORSO]
    assert np.all(tau[others] == 0.0)
    assert abs(g[2]) > 1.0 and np.any(g[[5, 6, 7]] != 0.0)  # swing leg left uncompensated
    off = posture_torque(obs, dynamics, PostureParameters(reference='standing',
                                                          gravity_compensation=False))
    assert np.all(off == 0.0)


def test_pd_and_yaw_spring_signs(make_obs, dynamics):
    q = BENT.copy()
    q[3] += 0.1  # knee more flexed than the reference
    q[8] = 0.5  # torso yawed
    q[17] = 0.3  # neck is not driven
    v = np.zeros(18)
    v[9] = 1.0
    v[8] = -0.5
    obs = make_obs(q=q, v=v)
    tau = posture_torque(obs, dynamics, PostureParameters(reference='standing',
                                                          gravity_compensation=False))
    assert tau[3] == pytest.approx(-80.0)
    assert tau[9] == pytest.approx(-16.0)
    assert tau[8] == pytest.approx(-20.0 * 0.5 + 2.0 * 0.5)
    assert tau[17] == 0.0 and tau[0] == 0.0 and tau[1] == 0.0
    assert np.all(tau[[5, 6, 7, 11, 12, 13, 14, 15, 16]] == 0.0)


def test_null_space_projection_does_not_fight_the_head_task(make_obs, dynamics):
    q = BENT.copy()
    q[[2, 3, 4, 9, 10]] += (0.05, 0.2, -0.1, 0.1, -0.05)
    obs = make_obs(t=1.4, q=q, mode=2, t_exchange=1.0)
    params = PostureParameters(null_space=True, gravity_compensation=False)
    tau = posture_torque(obs, dynamics, params)
    plain = posture_torque(obs, dynamics, PostureParameters(gravity_compensation=False))
    _psi, jac = dynamics.head_pose(obs.contact(), obs.q)
    jd = jac[:, STANCE_AND_TORSO]
    # the projected torque produces no head-space force: (J_D^+)^T tau_D = 0
    np.testing.assert_allclose(np.linalg.pinv(jd).T @ tau[STANCE_AND_TORSO], 0.0, atol=1e-9)
    assert np.linalg.norm(tau[STANCE_AND_TORSO]) > 1.0
    assert not np.allclose(tau, plain)
    assert tau[8] == plain[8]  # the yaw spring is not projected


def test_defaults_follow_the_model():
    p = PostureParameters()
    assert p.joints == (2, 3, 4, 9, 10) and 17 not in p.joints
    assert (p.stiffness, p.damping, p.yaw_stiffness, p.yaw_damping) == (800, 16, 20, 2)
    assert p.gravity_compensation and not p.null_space and p.bend == 0.05
    assert (p.shift_y1, p.shift_z1, p.shift_time1, p.shift_y2, p.shift_time2) == (
        0.10, 0.03, 0.6, 0.10, 0.5)


@pytest.mark.parametrize(('key', 'value'), [
    ('reference', 'walking'), ('joints', [1, 2]), ('joints', [0]), ('joints', '234'),
    ('joints', [2, 2]), ('stiffness', -800.0), ('damping', 'high'), ('null_space', 'no'),
    ('gravity_joints', [18]), ('bend', 1.0), ('shift_y1', 2.0), ('shift_time2', -0.5),
])
def test_from_dict_rejects_bad_values_naming_the_key(key, value):
    with pytest.raises(GaitManagerError, match=key):
        PostureParameters.from_dict({key: value})


def test_from_dict():
    with pytest.raises(GaitManagerError, match='kq'):
        PostureParameters.from_dict({'kq': 800})
    p = PostureParameters.from_dict({'joints': [2, 3, 4, 9, 10, 17], 'stiffness': 400})
    assert p.joints == (2, 3, 4, 9, 10, 17) and p.stiffness == 400.0
