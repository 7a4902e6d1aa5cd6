"""The visual-lifting law of eq. (9) on the shipped C++ (docs/model.md §10): the torque against
a finite-difference virtual-work gradient of the core's head pose, the joint masks and the
joint-1 switch, the delta-y saturation, the head target of every option and the moving stance,
the origin psi(0)."""

import numpy as np
import pytest

from iceskate_bringup.scene import load_scene, node_parameters
from iceskate_sim.physics.native_control import native_observation
from oracle.commands import native_command
from visual_lifting.native import VisualLiftingController
from visual_lifting.parameters import VisualLiftingParameters

KP = np.array([20.0, 290.0, 1100.0])
LISTED = [1, 2, 3, 4, 8, 9, 10, 17]
ERROR = (0.05, -0.04, 0.03)


def _posture(q1: float = 0.0, yaw: float = 0.0, y0: float = 0.0) -> np.ndarray:
    q = np.zeros(18)
    q[0] = y0
    q[1] = q1
    q[2:8] = (-0.12, 0.30, -0.15, 0.20, -0.35, 0.10)
    q[8], q[9], q[10], q[17] = yaw, 0.07, -0.05, 0.12
    q[11], q[14] = 0.2, -0.1
    return q


def _virtual_work_gradient(dynamics, contact, q, psi_d, step=1e-6):
    """tau_j = d/dq_j of -1/2 dpsi^T K dpsi (psi_d fixed), central differences, all 18 j: an
    independent formulation of J_H^T K dpsi."""
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
def test_the_torque_is_the_virtual_work_gradient(make_obs, dynamics, pulled, mode, side, pivot,
                                                 q1, yaw, y0):
    obs = make_obs(t=1.0, q=_posture(q1, yaw, y0), mode=mode, side=side, pivot=pivot)
    contact = obs.contact()
    psi, _ = dynamics.head_pose(contact, obs.q)
    tau, target = pulled(obs, ERROR)
    np.testing.assert_allclose(target, psi + ERROR, rtol=0, atol=1e-12)
    fd = _virtual_work_gradient(dynamics, contact, obs.q, psi + ERROR)
    active = set(obs.gait_mode.active.tolist())
    for j in range(18):
        if j in LISTED and j in active:
            assert tau[j] == pytest.approx(fd[j], rel=1e-6, abs=1e-6), f'joint {j}'
        else:
            assert tau[j] == 0.0, f'coordinate {j} must get no torque'
    assert np.any(np.abs(tau[LISTED]) > 1e-3)
    if yaw != 0.0:
        assert abs(fd[8]) > 1e-4  # the yaw column is exercised
    if mode in (2, 4, 10):
        assert abs(tau[1]) > 1e-3  # q1 active: the floor-pivot entry is exercised


def test_the_gains_scale_each_row(make_obs, pulled):
    obs = make_obs(t=1.0, q=_posture(-0.1, 0.2), mode=2)
    tau, _ = pulled(obs, ERROR)
    rows = [pulled(obs, tuple(e if i == k else 0.0 for i, e in enumerate(ERROR)))[0]
            for k in range(3)]
    np.testing.assert_allclose(sum(rows), tau, rtol=1e-12, atol=1e-12)  # linear in the error
    scaled = pulled(obs, ERROR, kp=[40.0, 290.0, 0.0])[0]
    np.testing.assert_allclose(scaled, 2.0 * rows[0] + rows[1], rtol=1e-12, atol=1e-12)


def test_a_head_below_its_target_is_lifted(make_obs, dynamics, pulled):
    """A target above the head pulls it up: the torque does positive virtual work on a head
    moving up (J_H^T K dpsi . dq > 0 for the z row's direction)."""
    obs = make_obs(t=1.0, q=_posture())
    tau, _ = pulled(obs, (0.0, 0.02, 0.0))
    _psi, jac = dynamics.head_pose(obs.contact(), obs.q)
    assert tau @ jac[1] > 0.0
    assert tau @ jac[1] == pytest.approx(290.0 * 0.02 * jac[1][LISTED] @ jac[1][LISTED],
                                         rel=1e-9)


def test_the_y0_entry_is_discarded_although_its_virtual_work_is_not_zero(make_obs, dynamics,
                                                                          pulled):
    obs = make_obs(t=1.0, q=_posture(-0.1, 0.2, 0.25), mode=4)
    psi, _ = dynamics.head_pose(obs.contact(), obs.q)
    fd = _virtual_work_gradient(dynamics, obs.contact(), obs.q, psi + ERROR)
    assert abs(fd[0]) > 0.5
    assert pulled(obs, ERROR)[0][0] == 0.0


def test_only_the_listed_joints_receive_torque(make_obs, pulled):
    obs = make_obs(t=1.0, q=_posture(-0.1, 0.3), mode=2)
    full, _ = pulled(obs, ERROR)
    part, _ = pulled(obs, ERROR, joints=[2, 9])
    assert part[2] == full[2] and part[9] == full[9]
    others = [j for j in range(18) if j not in (2, 9)]
    assert np.all(part[others] == 0.0)
    assert np.any(full[others] != 0.0)


def test_the_joint1_switch(make_obs, pulled):
    obs = make_obs(t=1.0, q=_posture(-0.1), mode=2)
    on, _ = pulled(obs, ERROR)
    off, _ = pulled(obs, ERROR, joint1_torque=False)
    assert abs(on[1]) > 1e-3 and off[1] == 0.0
    np.testing.assert_array_equal(on[2:], off[2:])
    flat, _ = pulled(make_obs(t=1.0, q=_posture(0.0), mode=1), ERROR)  # q1 locked
    assert flat[0] == 0.0 and flat[1] == 0.0


@pytest.mark.parametrize(('dy', 'clipped'), [(5.0, 0.3), (-2.0, -0.3), (0.1, 0.1)])
def test_delta_y_is_saturated_at_max_dy(make_obs, dynamics, pulled, dy, clipped):
    """|y_d - y| acts at most max_dy = 0.3 m (the target itself is not moved); unset, it acts
    whole."""
    obs = make_obs(t=1.0, q=_posture())
    psi, jac = dynamics.head_pose(obs.contact(), obs.q)
    tau, target = pulled(obs, (dy, 0.0, 0.0), max_dy=0.3)
    assert target[0] == pytest.approx(psi[0] + dy, abs=1e-12)
    expected = jac.T @ (KP * [clipped, 0.0, 0.0])
    np.testing.assert_allclose(tau[LISTED[1:]], expected[LISTED[1:]], rtol=1e-9, atol=1e-9)
    free, _ = pulled(obs, (dy, 0.0, 0.0))
    np.testing.assert_allclose(free[LISTED[1:]], (jac.T @ (KP * [dy, 0.0, 0.0]))[LISTED[1:]],
                               rtol=1e-9, atol=1e-9)


def test_the_head_target_of_each_option(make_obs, dynamics, lift):
    """y_d: 'moving' y_H(0) + v_d t, 'follow' y_H(t), 'fixed' y_H(0); z_d: z_H(0) or z_d;
    pitch_d."""
    start = make_obs(t=0.0, q=_posture(), mode=3)
    q = _posture(y0=0.4)
    q[3] += 0.1  # the head moved on and sank
    now = make_obs(t=2.0, q=q, mode=3)
    psi0, _ = dynamics.head_pose(start.contact(), start.q)
    psi, _ = dynamics.head_pose(now.contact(), now.q)
    moving = lift(now, start).head_target
    np.testing.assert_allclose(moving, [psi0[0] + 0.3 * 2.0, psi0[1], 0.0], atol=1e-12)
    follow = lift(now, start, desired_y='follow')
    np.testing.assert_allclose(follow.head_target, [psi[0], psi0[1], 0.0], atol=1e-12)
    fixed = lift(now, start, desired_y='fixed', z_d=1.5, pitch_d=0.02).head_target
    np.testing.assert_allclose(fixed, [psi0[0], 1.5, 0.02], atol=1e-12)
    slow = lift(now, start, v_d=-0.2).head_target
    assert slow[0] == pytest.approx(psi0[0] - 0.4, abs=1e-12)
    # 'follow' has no forward error: only the height and pitch rows act
    _psi, jac = dynamics.head_pose(now.contact(), now.q)
    error = np.array([0.0, psi0[1] - psi[1], -psi[2]])
    np.testing.assert_allclose(follow.source_efforts['visual_lifting'][LISTED[1:]],
                               (jac.T @ (KP * error))[LISTED[1:]], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize(('t', 't_touchdown', 'shift'), [
    (1.0, np.nan, (0.0, 0.0)), (1.3, np.nan, (0.05, -0.015)), (1.6, np.nan, (0.10, -0.03)),
    (2.0, 1.75, (0.15, -0.03)), (2.5, 1.75, (0.20, -0.03))])
def test_the_target_follows_the_moving_stance(make_obs, dynamics, lift, t, t_touchdown, shift):
    """With the gait manager's stance (dy1 0.1 m, dz1 0.03 m over 0.6 s after t_e, then dy2
    0.1 m over 0.5 s after the heel strike, smoothsteps) y_d and z_d move by (dy, -dz);
    'follow' keeps y_d = y_H."""
    stance = {'shift_y1': 0.1, 'shift_z1': 0.03, 'shift_time1': 0.6, 'shift_y2': 0.1,
              'shift_time2': 0.5}
    start = make_obs(t=0.0, q=_posture())
    obs = make_obs(t=t, q=_posture(), t_exchange=1.0, t_touchdown=t_touchdown)
    psi0, _ = dynamics.head_pose(start.contact(), start.q)
    target = lift(obs, start, **stance).head_target
    np.testing.assert_allclose(target, psi0 + (0.3 * t + shift[0], shift[1], -psi0[2]),
                               atol=1e-12)
    follow = lift(obs, start, desired_y='follow', **stance).head_target
    assert follow[0] == pytest.approx(psi0[0], abs=1e-12)
    assert follow[1] == pytest.approx(psi0[1] + shift[1], abs=1e-12)
    steps = lift(obs, start, **{**stance, 'shift_time1': 0.0, 'shift_time2': 0.0}).head_target
    whole = 0.2 if np.isfinite(t_touchdown) else 0.1
    np.testing.assert_allclose(steps[:2], psi0[:2] + (0.3 * t + whole, -0.03), atol=1e-12)
    np.testing.assert_allclose(lift(obs, start).head_target[:2], psi0[:2] + (0.3 * t, 0.0),
                               atol=1e-12)  # no stance by default


def test_the_origin_is_latched_at_t_0_or_the_first_state_and_kept(make_obs, dynamics,
                                                                   kinematics):
    start = make_obs(t=0.0, q=_posture(), mode=3)
    later = make_obs(t=1.5, q=_posture(y0=0.3), mode=3)

    def psi(obs):
        return dynamics.head_pose(obs.contact(), obs.q)[0]

    controller = VisualLiftingController(VisualLiftingParameters())
    assert controller.origin is None
    controller.compute(native_observation(later), kinematics)  # first state seen: not t = 0
    np.testing.assert_allclose(controller.origin, psi(later), atol=1e-12)
    controller.set_parameters(VisualLiftingParameters(v_d=0.1))
    controller.compute(native_observation(later), kinematics)
    np.testing.assert_allclose(controller.origin, psi(later), atol=1e-12)
    controller.compute(native_observation(start), kinematics)  # t = 0: again
    np.testing.assert_allclose(controller.origin, psi(start), atol=1e-12)
    controller.latch_origin(native_observation(later), kinematics)
    np.testing.assert_allclose(controller.origin, psi(later), atol=1e-12)


@pytest.mark.parametrize('scene', ['skate', 'skate_no_yaw', 'walk', 'stand'])
def test_on_real_runs_the_torque_is_jh_transpose_k_error(scene, scene_observations, dynamics,
                                                         kinematics):
    """On the states of the shipped scenes' runs (every mode they pass through), with each
    scene's own parameters: tau = J_H^T K_p sat(psi_d - psi) on the listed joints active in the
    mode, psi and J_H from the core's kinematics, psi_d the target the law reports."""
    params = node_parameters(load_scene(scene))['visual_lifting']
    controller = VisualLiftingController(params)
    kp = np.asarray(params.kp)
    for obs in scene_observations[scene]:
        cmd = native_command(controller, obs, kinematics)
        psi, jac = dynamics.head_pose(obs.contact(), obs.q)
        error = cmd.head_target - psi
        if params.max_dy is not None:
            error[0] = min(max(error[0], -params.max_dy), params.max_dy)
        expected = jac.T @ (kp * error)
        mask = np.zeros(18, dtype=bool)
        mask[list(params.joints)] = True
        mask[0] = False
        mask[1] &= obs.gait_mode.q1_active and params.joint1_torque
        expected[~mask] = 0.0
        np.testing.assert_allclose(cmd.source_efforts['visual_lifting'], expected, rtol=1e-9,
                                   atol=1e-9, err_msg=f't = {obs.t}, mode {obs.mode}')
        assert cmd.head_target[2] == params.pitch_d
