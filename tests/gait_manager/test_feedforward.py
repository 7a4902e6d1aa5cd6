"""Feed-forward leg torques (docs/model.md §11.4) and weight transfer (§11.5) on the C++
sources: pulse windows and signs, push-off on the toe pivot, the joint-1 switch, and
tau_wt = -J_c^T f_des against the core's heel kinematics and its constrained dynamics."""

import math

import numpy as np
import pytest

from iceskate_sim.model.robot import GRAVITY


def test_swing_hip_pulse_only_in_its_window_and_in_the_air(make_obs, torque):
    def tau5(t, mode=1):
        return torque('feedforward', make_obs(t=t, t_exchange=1.0, mode=mode))[5]

    assert tau5(1.175) == pytest.approx(40.0)
    assert tau5(1.1) == pytest.approx(40.0 * math.sin(math.pi * 0.1 / 0.35))
    assert tau5(1.0) == 0.0 and tau5(1.36) == 0.0 and tau5(0.99) == 0.0
    for mode in (5, 9, 17):  # heel or sole on the floor: no swing pulse
        assert tau5(1.175, mode) == 0.0
    # continuous at both ends of the window
    assert abs(tau5(1.0 + 1e-6)) < 1e-3 and abs(tau5(1.35 - 1e-6)) < 1e-3


def test_swing_knee_pulse_then_extension_pd(make_obs, torque, bent):
    assert torque('feedforward', make_obs(t=1.125, t_exchange=1.0))[6] == pytest.approx(-20.0)
    q = bent.copy()
    q[6] = -0.6
    v = np.zeros(18)
    v[6] = -1.0
    pd = torque('feedforward', make_obs(t=1.4, t_exchange=1.0, q=q, v=v))
    assert pd[6] == pytest.approx(50.0 * (-0.05 + 0.6) + 5.0)
    on_floor = torque('feedforward', make_obs(t=1.4, t_exchange=1.0, q=q, v=v, mode=9))
    assert on_floor[6] == 0.0


def test_push_off_only_on_the_toe_pivot(make_obs, torque):
    late = 5.0  # outside the swing pulses
    toe = torque('feedforward', make_obs(t=late, mode=10, pivot='toe'))
    assert (toe[1], toe[2], toe[3]) == (-10.0, 20.0, -10.0)
    for mode, pivot in ((10, 'heel'), (17, 'toe'), (1, 'toe')):
        tau = torque('feedforward', make_obs(t=late, mode=mode, pivot=pivot))
        assert np.all(tau[:5] == 0.0), (mode, pivot)


def test_the_joint1_switch_and_untouched_joints(make_obs, torque):
    off = torque('feedforward', make_obs(t=5.0, mode=2), feedforward={'joint1_torque': False})
    assert off[1] == 0.0 and off[2] == 20.0
    tau = torque('feedforward', make_obs(t=1.1, t_exchange=1.0, mode=4))
    assert tau[0] == 0.0
    assert np.all(tau[[4, 7, *range(8, 18)]] == 0.0)


def _heel_z_row(dynamics, obs, central_difference):
    """d z_swing_heel / d q by central differences of the core's frame placement (columns of
    locked coordinates 0)."""
    contact = obs.contact()

    def heel_z(x):
        return dynamics.frame_placement(contact, x, 'swing_heel').translation[2]

    row = np.array([central_difference(heel_z, obs.q, e) for e in np.eye(18)])
    locked = [j for j in range(18) if j not in set(obs.gait_mode.active.tolist())]
    row[locked] = 0.0
    return row


def _heel_force(tau, row):
    """f_des of tau = -f J_c (least squares over the coordinates 2-17)."""
    return -float(tau[2:] @ row[2:]) / float(row[2:] @ row[2:])


@pytest.mark.parametrize(('mode', 'q1'), [(9, 0.0), (10, -0.08), (6, -0.08)])
def test_weight_transfer_is_minus_jc_transpose_f(make_obs, dynamics, torque, bent,
                                                 central_difference, mode, q1):
    """Heel on the floor (no moment: Hs, Hp) and f_des = share m g (t - t_td)/ramp_time =
    0.2 m g: tau = -J_c^T f_des, J_c from the core's heel frame; no y0 entry; q1 only while
    active and switched on."""
    q = bent.copy()
    q[1] = q1
    q[7] -= q1  # keep the swing sole flat
    obs = make_obs(t=2.0, q=q, mode=mode, t_touchdown=1.9, side='left')
    tau = torque('weight_transfer', obs)
    row = _heel_z_row(dynamics, obs, central_difference)
    force = 0.2 * dynamics.robot.total_mass * GRAVITY
    expected = -force * row
    expected[0] = 0.0
    np.testing.assert_allclose(tau, expected, rtol=1e-6, atol=1e-5)
    assert abs(tau[2]) > 1.0
    if q1:
        assert abs(tau[1]) > 1.0
        off = torque('weight_transfer', obs, weight_transfer={'joint1_torque': False})
        assert off[1] == 0.0
        np.testing.assert_array_equal(off[2:], tau[2:])


def test_the_desired_force_ramps_after_the_heel_strike(make_obs, dynamics, torque, bent,
                                                       central_difference):
    """0 in the air and before any touchdown; linear to share m g over ramp_time after it
    (continuous), then held; a 0 s ramp is a step."""
    weight = dynamics.robot.total_mass * GRAVITY
    assert not np.any(torque('weight_transfer', make_obs(t=2.0, mode=9, step_index=2)))
    assert not np.any(torque('weight_transfer', make_obs(t=2.0, t_touchdown=1.5)))  # air
    row = _heel_z_row(dynamics, make_obs(mode=17), central_difference)

    def force(t, **block):
        obs = make_obs(t=t, mode=17, t_touchdown=1.75, t_exchange=1.0, step_index=2)
        return _heel_force(torque('weight_transfer', obs, weight_transfer={
            'moment_arm': 0.0, **block}), row)

    assert force(2.0) == pytest.approx(0.5 * weight, rel=1e-6)
    assert force(1.75 + 1e-6) == pytest.approx(0.0, abs=1e-3 * weight)
    assert force(2.25 - 1e-6) == pytest.approx(weight, rel=1e-5)
    assert force(3.0, share=0.3) == pytest.approx(0.3 * weight, rel=1e-6)
    assert force(1.8, ramp_time=0.0) == pytest.approx(weight, rel=1e-6)


def test_the_starting_double_support_unloads_the_second_foot(make_obs, dynamics, torque,
                                                            central_difference):
    """Step 0, second foot down since the start: start_share m g falling linearly to 0 over
    start_ramp; a 0 s start_ramp holds it (standing)."""
    weight = dynamics.robot.total_mass * GRAVITY
    row = _heel_z_row(dynamics, make_obs(mode=17), central_difference)

    def force(t, **block):
        obs = make_obs(t=t, mode=17, t_touchdown=0.0, t_exchange=0.0)
        return _heel_force(torque('weight_transfer', obs, weight_transfer={
            'moment_arm': 0.0, **block}), row)

    assert force(0.0) == pytest.approx(0.5 * weight, rel=1e-6)
    assert force(0.25) == pytest.approx(0.25 * weight, rel=1e-6)
    assert force(0.6) == 0.0
    assert force(3.0, start_ramp=0.0) == pytest.approx(0.5 * weight, rel=1e-6)


@pytest.mark.parametrize('mode', [9, 17, 18])
def test_weight_transfer_moves_the_contact_force_not_the_motion(make_obs, dynamics, torque,
                                                                mode):
    """In a pinned mode the torques change f_nz by f_des (and tau_n by arm f_des with the sole
    flat) exactly and leave the accelerations unchanged (the core's eq. (7)): a joint-torque
    realisation of a contact force."""
    obs = make_obs(t=2.0, mode=mode, t_touchdown=1.8, step_index=2)
    heel_y = dynamics.frame_placement(obs.contact(), obs.q, 'swing_heel').translation[1]
    obs = make_obs(t=2.0, mode=mode, t_touchdown=1.8, step_index=2, heel_anchor_y=heel_y)
    tau = torque('weight_transfer', obs)
    force = 0.4 * dynamics.robot.total_mass * GRAVITY  # 0.2 s of the 0.5 s ramp to m g
    contact = obs.contact()
    base = dynamics.evaluate(contact, obs.q, obs.v, np.zeros(18))
    moved = dynamics.evaluate(contact, obs.q, obs.v, tau)
    np.testing.assert_allclose(moved.qdd, base.qdd, atol=1e-7)
    f_nz, tau_n = (moved.multipliers - base.multipliers)[[0, 2]]  # (f_nz, f_ny, tau_n)
    assert f_nz == pytest.approx(force, rel=1e-9)
    expected_tau_n = 0.05 * force if obs.gait_mode.swing in ('Fs', 'Fp') else 0.0
    assert tau_n == pytest.approx(expected_tau_n, abs=1e-6)
    assert moved.support_normal == pytest.approx(base.support_normal - force, rel=1e-6)
