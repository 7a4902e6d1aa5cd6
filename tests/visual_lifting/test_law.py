"""Visual-lifting law: eq. (9) against a finite-difference virtual-work computation, joint
masks, the joint-1 switch, the delta-y saturation, the desired pose and parameter validation."""

import math

import numpy as np
import pytest

from visual_lifting.errors import VisualLiftingError
from visual_lifting.law import (
    VisualLiftingParameters,
    desired_head_pose,
    head_error,
    visual_lifting,
    visual_lifting_torque,
)

KP = np.array([20.0, 290.0, 1100.0])


def _posture(q1: float = 0.0, yaw: float = 0.0, y0: float = 0.0) -> np.ndarray:
    q = np.zeros(18)
    q[0] = y0
    q[1] = q1
    q[2:8] = (-0.12, 0.30, -0.15, 0.20, -0.35, 0.10)
    q[8], q[9], q[10], q[17] = yaw, 0.07, -0.05, 0.12
    q[11], q[14] = 0.2, -0.1
    return q


def _virtual_work_gradient(dynamics, contact, q, psi_d, step=1e-6):
    """tau_j = d/dq_j of -1/2 dpsi^T K dpsi (psi_d fixed), central differences, all 18 j."""
    def potential(x):
        psi, _ = dynamics.head_pose(contact, x)
        err = psi_d - psi
        return -0.5 * err @ (KP * err)

    grad = np.zeros(18)
    for j in range(18):
        e = np.zeros(18)
        e[j] = step
        grad[j] = (potential(q + e) - potential(q - e)) / (2.0 * step)
    return grad


CASES = [  # (mode, side, pivot, q1, torso yaw, y0)
    (1, 'right', 'toe', 0.0, 0.0, 0.0),  # F-S, A
    (1, 'left', 'toe', 0.0, 0.4, 0.0),  # torso yaw != 0
    (2, 'right', 'toe', -0.15, 0.3, 0.0),  # R-S: q1 active, toe pivot
    (10, 'left', 'heel', 0.12, -0.5, 0.0),  # R-S + Hp, heel pivot
    (4, 'right', 'toe', -0.1, 0.2, 0.25),  # R-G: y0 and q1 active
]


@pytest.mark.parametrize(('mode', 'side', 'pivot', 'q1', 'yaw', 'y0'), CASES)
def test_torque_equals_finite_difference_virtual_work(make_obs, dynamics, mode, side, pivot,
                                                      q1, yaw, y0):
    obs = make_obs(q=_posture(q1, yaw, y0), mode=mode, side=side, pivot=pivot)
    contact = obs.contact()
    psi, _ = dynamics.head_pose(contact, obs.q)
    psi_d = psi + np.array([0.05, -0.04, 0.03])
    params = VisualLiftingParameters()
    tau = visual_lifting_torque(obs, dynamics, params, psi_d)
    fd = _virtual_work_gradient(dynamics, contact, obs.q, psi_d)
    listed = [1, 2, 3, 4, 8, 9, 10, 17]
    active = set(obs.gait_mode.active.tolist())
    for j in range(18):
        if j in listed and j in active:
            assert tau[j] == pytest.approx(fd[j], rel=1e-6, abs=1e-6), f'joint {j}'
        else:
            assert tau[j] == 0.0, f'coordinate {j} must get no torque'
    assert np.any(np.abs(tau[listed]) > 1e-3)
    if yaw != 0.0:
        assert abs(fd[8]) > 1e-4  # the yaw column is exercised
    if mode in (2, 4, 10):
        assert abs(tau[1]) > 1e-3  # q1 active: the floor-pivot entry is exercised


def test_y0_entry_is_discarded_although_its_virtual_work_is_not_zero(make_obs, dynamics):
    obs = make_obs(q=_posture(-0.1, 0.2, 0.25), mode=4)
    psi, _ = dynamics.head_pose(obs.contact(), obs.q)
    psi_d = psi + np.array([0.05, -0.04, 0.03])
    fd = _virtual_work_gradient(dynamics, obs.contact(), obs.q, psi_d)
    assert abs(fd[0]) > 0.5
    assert visual_lifting_torque(obs, dynamics, VisualLiftingParameters(), psi_d)[0] == 0.0


def test_only_listed_joints_receive_torque(make_obs, dynamics):
    obs = make_obs(q=_posture(-0.1, 0.3), mode=2)
    psi, _ = dynamics.head_pose(obs.contact(), obs.q)
    psi_d = psi + np.array([0.05, -0.04, 0.03])
    full = visual_lifting_torque(obs, dynamics, VisualLiftingParameters(), psi_d)
    part = visual_lifting_torque(obs, dynamics, VisualLiftingParameters(joints=(2, 9)), psi_d)
    assert part[2] == full[2] and part[9] == full[9]
    others = [j for j in range(18) if j not in (2, 9)]
    assert np.all(part[others] == 0.0)
    assert np.any(full[others] != 0.0)


def test_joint1_switch(make_obs, dynamics):
    obs = make_obs(q=_posture(-0.1), mode=2)
    psi, _ = dynamics.head_pose(obs.contact(), obs.q)
    psi_d = psi + np.array([0.05, -0.04, 0.03])
    on = visual_lifting_torque(obs, dynamics, VisualLiftingParameters(joint1_torque=True), psi_d)
    off = visual_lifting_torque(obs, dynamics, VisualLiftingParameters(joint1_torque=False),
                                psi_d)
    assert abs(on[1]) > 1e-3 and off[1] == 0.0
    np.testing.assert_array_equal(on[2:], off[2:])
    flat = make_obs(q=_posture(0.0), mode=1)  # q1 locked: no joint-1 torque even when on
    psi, _ = dynamics.head_pose(flat.contact(), flat.q)
    tau = visual_lifting_torque(flat, dynamics, VisualLiftingParameters(), psi + 0.05)
    assert tau[0] == 0.0 and tau[1] == 0.0


def test_delta_y_saturation():
    params = VisualLiftingParameters()
    psi = np.array([1.0, 1.6, 0.1])
    err = head_error(psi + np.array([0.8, -0.5, 0.4]), psi, params)
    np.testing.assert_allclose(err, [0.3, -0.5, 0.4])
    err = head_error(psi + np.array([-2.0, 0.5, -0.4]), psi, params)
    np.testing.assert_allclose(err, [-0.3, 0.5, -0.4])
    err = head_error(psi + np.array([0.1, 0.0, 0.0]), psi, params)
    np.testing.assert_allclose(err, [0.1, 0.0, 0.0])
    free = VisualLiftingParameters(max_dy=None)
    np.testing.assert_allclose(head_error(psi + np.array([2.0, 0, 0]), psi, free), [2.0, 0, 0])


def test_saturated_error_drives_the_torque(make_obs, dynamics):
    obs = make_obs(q=_posture())
    psi, jac = dynamics.head_pose(obs.contact(), obs.q)
    tau = visual_lifting_torque(obs, dynamics, VisualLiftingParameters(), psi + [5.0, 0, 0])
    np.testing.assert_allclose(tau[[2, 3, 4, 9, 10, 17]], (jac.T @ (KP * [0.3, 0, 0]))[
        [2, 3, 4, 9, 10, 17]])


def test_desired_head_pose_options():
    psi0 = np.array([0.01, 1.69, 0.0])
    psi = np.array([0.4, 1.6, 0.05])
    moving = desired_head_pose(VisualLiftingParameters(), 2.0, psi, psi0)
    np.testing.assert_allclose(moving, [0.01 + 0.6, 1.69, 0.0])
    shifted = desired_head_pose(VisualLiftingParameters(), 2.0, psi, psi0, (0.1, -0.03))
    np.testing.assert_allclose(shifted, [0.71, 1.66, 0.0])
    follow = desired_head_pose(VisualLiftingParameters(desired_y='follow'), 2.0, psi, psi0,
                               (0.1, -0.03))
    np.testing.assert_allclose(follow, [0.4, 1.66, 0.0])
    fixed = VisualLiftingParameters(desired_y='fixed', z_d=1.5, pitch_d=0.02)
    np.testing.assert_allclose(desired_head_pose(fixed, 2.0, psi, psi0), [0.01, 1.5, 0.02])


def test_visual_lifting_bundles_the_pieces(make_obs, dynamics):
    obs = make_obs(t=1.0, q=_posture(-0.1, 0.2), mode=2)
    psi0 = np.array([0.0, 1.69, 0.0])
    params = VisualLiftingParameters(shift_y1=0.05, shift_z1=0.01, shift_time1=0.0)
    task = visual_lifting(obs, dynamics, params, psi0)  # obs: t_e = 0, so the shift is whole
    psi, _ = dynamics.head_pose(obs.contact(), obs.q)
    psi_d = desired_head_pose(params, 1.0, psi, psi0, (0.05, -0.01))
    np.testing.assert_array_equal(task.psi, psi)
    np.testing.assert_array_equal(task.psi_d, psi_d)
    np.testing.assert_array_equal(task.error, head_error(psi_d, psi, params))
    np.testing.assert_array_equal(task.tau, visual_lifting_torque(obs, dynamics, params, psi_d))


def test_defaults_follow_the_spec():
    p = VisualLiftingParameters()
    assert p.kp == (20.0, 290.0, 1100.0)
    assert p.joints == (1, 2, 3, 4, 8, 9, 10, 17)
    assert p.joint1_torque is True and p.desired_y == 'moving'
    assert p.v_d == 0.3 and p.z_d is None and p.pitch_d == 0.0 and p.max_dy == 0.3


def test_from_dict_accepts_yaml_like_values():
    p = VisualLiftingParameters.from_dict({'kp': [10, 100, 500], 'joints': [2, 3], 'z_d': 1.6,
                                           'desired_y': 'follow', 'max_dy': None})
    assert p.kp == (10.0, 100.0, 500.0) and p.joints == (2, 3) and p.max_dy is None
    assert VisualLiftingParameters.from_dict({}) == VisualLiftingParameters()


@pytest.mark.parametrize(('key', 'value'), [
    ('kp', [1.0, 2.0]), ('kp', [1.0, -2.0, 3.0]), ('kp', 'abc'), ('kp', [1, 2, math.nan]),
    ('joints', [0, 2]), ('joints', [2, 2]), ('joints', [2.5]), ('joints', [True]),
    ('joint1_torque', 'yes'), ('desired_y', 'forward'), ('v_d', '0.3'), ('v_d', math.inf),
    ('z_d', 0.0), ('z_d', -1.0), ('pitch_d', None), ('max_dy', 0.0), ('max_dy', True),
])
def test_from_dict_rejects_bad_values_naming_the_key(key, value):
    with pytest.raises(VisualLiftingError, match=key):
        VisualLiftingParameters.from_dict({key: value})


def test_from_dict_rejects_unknown_keys():
    with pytest.raises(VisualLiftingError, match='kd'):
        VisualLiftingParameters.from_dict({'kd': [1, 2, 3]})
    with pytest.raises(VisualLiftingError):
        VisualLiftingParameters.from_dict([('kp', (1, 2, 3))])
    assert issubclass(VisualLiftingError, ValueError)
