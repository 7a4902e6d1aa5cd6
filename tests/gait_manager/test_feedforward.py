"""Feed-forward leg torques (docs/model.md §11.4) and weight transfer (§11.5)."""

import math

import numpy as np
import pytest

from gait_manager.errors import GaitManagerError
from gait_manager.feedforward import (
    FeedforwardParameters,
    WeightTransferParameters,
    desired_heel_force,
    feedforward_torque,
    weight_transfer_torque,
)
from iceskate_sim.robot import GRAVITY
from iceskate_sim.scene import standing_posture

BENT = standing_posture('bent_knees', 0.05, 0.0)[0]  # docs/model.md §12, a = 0.05 rad


def test_swing_hip_pulse_only_in_its_window_and_in_the_air(make_obs):
    params = FeedforwardParameters()
    mid = feedforward_torque(make_obs(t=1.175, t_exchange=1.0, mode=1), params)
    assert mid[5] == pytest.approx(40.0)
    assert feedforward_torque(make_obs(t=1.1, t_exchange=1.0), params)[5] == pytest.approx(
        40.0 * math.sin(math.pi * 0.1 / 0.35))
    assert feedforward_torque(make_obs(t=1.36, t_exchange=1.0), params)[5] == 0.0
    for mode in (5, 9, 17):  # heel or sole on the floor: no swing pulse
        assert feedforward_torque(make_obs(t=1.175, t_exchange=1.0, mode=mode), params)[5] == 0.0


def test_swing_knee_pulse_then_extension_pd(make_obs):
    params = FeedforwardParameters()
    pulse = feedforward_torque(make_obs(t=1.125, t_exchange=1.0), params)
    assert pulse[6] == pytest.approx(-20.0)  # flexion (q6 <= 0 is flexion)
    q = BENT.copy()
    q[6] = -0.6
    v = np.zeros(18)
    v[6] = -1.0
    pd = feedforward_torque(make_obs(t=1.4, t_exchange=1.0, q=q, v=v), params)
    assert pd[6] == pytest.approx(50.0 * (-0.05 + 0.6) + 5.0)
    assert feedforward_torque(make_obs(t=1.4, t_exchange=1.0, q=q, v=v, mode=9), params)[6] == 0


def test_push_off_only_on_the_toe_pivot(make_obs):
    params = FeedforwardParameters()
    late = 5.0  # outside the swing pulses
    toe = feedforward_torque(make_obs(t=late, mode=10, pivot='toe'), params)
    assert (toe[1], toe[2], toe[3]) == (-10.0, 20.0, -10.0)
    for mode, pivot in ((10, 'heel'), (17, 'toe'), (1, 'toe')):
        tau = feedforward_torque(make_obs(t=late, mode=mode, pivot=pivot), params)
        assert np.all(tau[:5] == 0.0), (mode, pivot)


def test_joint1_switch(make_obs):
    off = feedforward_torque(make_obs(t=5.0, mode=2), FeedforwardParameters(joint1_torque=False))
    assert off[1] == 0.0 and off[2] == 20.0


def test_feedforward_never_touches_y0_or_other_joints(make_obs):
    tau = feedforward_torque(make_obs(t=1.1, t_exchange=1.0, mode=4), FeedforwardParameters())
    assert tau[0] == 0.0
    assert np.all(tau[[4, 7, *range(8, 18)]] == 0.0)


def _double_support(dynamics, make_obs, mode, t, t_touchdown, side='right'):
    obs = make_obs(t=t, mode=mode, side=side, t_touchdown=t_touchdown)
    heel_y = dynamics.frame_placement(obs.contact(), obs.q, 'swing_heel').translation[1]
    return make_obs(t=t, mode=mode, side=side, t_touchdown=t_touchdown, heel_anchor_y=heel_y)


def test_desired_force_ramps_after_touchdown(make_obs, dynamics):
    params = WeightTransferParameters()
    weight = dynamics.robot.total_mass * GRAVITY
    assert desired_heel_force(make_obs(t=2.0, mode=9), params, 64.2) == 0.0  # no touchdown
    assert desired_heel_force(make_obs(t=2.0, t_touchdown=1.5), params, 64.2) == 0.0  # air
    half = make_obs(t=2.0, mode=9, t_touchdown=1.75)
    assert desired_heel_force(half, params, dynamics.robot.total_mass) == pytest.approx(
        0.5 * weight)
    done = make_obs(t=3.0, mode=17, t_touchdown=1.75)
    share = WeightTransferParameters(share=0.3)
    assert desired_heel_force(done, share, dynamics.robot.total_mass) == pytest.approx(
        0.3 * weight)
    assert np.all(weight_transfer_torque(make_obs(t=2.0, mode=1, t_touchdown=1.5), dynamics,
                                         params) == 0.0)


@pytest.mark.parametrize(('mode', 'q1'), [(9, 0.0), (10, -0.08), (6, -0.08)])
def test_weight_transfer_is_minus_jc_transpose_f(make_obs, dynamics, mode, q1):
    q = BENT.copy()
    q[1] = q1
    q[7] -= q1  # keep the swing sole flat
    obs = make_obs(t=2.0, q=q, mode=mode, t_touchdown=1.9, side='left')
    params = WeightTransferParameters()
    force = desired_heel_force(obs, params, dynamics.robot.total_mass)
    tau = weight_transfer_torque(obs, dynamics, params)
    contact = obs.contact()
    step = 1e-6
    active = set(obs.gait_mode.active.tolist())
    for j in range(1, 18):
        e = np.zeros(18)
        e[j] = step
        dz = (dynamics.frame_placement(contact, q + e, 'swing_heel').translation[2]
              - dynamics.frame_placement(contact, q - e, 'swing_heel').translation[2]) / (2 * step)
        expected = -force * dz if j in active else 0.0
        assert tau[j] == pytest.approx(expected, rel=1e-6, abs=1e-5), f'joint {j}'
    assert tau[0] == 0.0
    assert abs(tau[2]) > 1.0
    if q1:
        assert abs(tau[1]) > 1.0
        off = weight_transfer_torque(obs, dynamics, WeightTransferParameters(joint1_torque=False))
        assert off[1] == 0.0
        np.testing.assert_array_equal(off[2:], tau[2:])


@pytest.mark.parametrize('mode', [9, 17, 18])
def test_weight_transfer_moves_the_contact_force_not_the_motion(make_obs, dynamics, mode):
    """In a pinned mode the torques change f_nz by f_des (and tau_n by arm f_des) exactly and
    leave the accelerations unchanged: a joint-torque realisation of a contact force."""
    obs = _double_support(dynamics, make_obs, mode, t=2.0, t_touchdown=1.8)
    params = WeightTransferParameters()
    tau = weight_transfer_torque(obs, dynamics, params)
    force = desired_heel_force(obs, params, dynamics.robot.total_mass)
    assert force > 100.0
    contact = obs.contact()
    base = dynamics.evaluate(contact, obs.q, obs.v, np.zeros(18))
    moved = dynamics.evaluate(contact, obs.q, obs.v, tau)
    np.testing.assert_allclose(moved.qdd, base.qdd, atol=1e-7)
    assert moved.multiplier('f_nz') - base.multiplier('f_nz') == pytest.approx(force, rel=1e-9)
    flat = obs.gait_mode.swing in ('Fs', 'Fp')
    expected_tau_n = 0.05 * force if flat else 0.0
    assert moved.multiplier('tau_n') - base.multiplier('tau_n') == pytest.approx(
        expected_tau_n, abs=1e-6)
    assert moved.support_normal == pytest.approx(base.support_normal - force, rel=1e-6)


@pytest.mark.parametrize(('cls', 'key', 'value'), [
    (FeedforwardParameters, 'hip_amplitude', -40.0), (FeedforwardParameters, 'hip_duration', 0),
    (FeedforwardParameters, 'knee_reference', 0.3), (FeedforwardParameters, 'joint1_torque', 1),
    (FeedforwardParameters, 'ankle_push', [20.0]),
    (WeightTransferParameters, 'share', -0.1), (WeightTransferParameters, 'ramp_time', 'x'),
    (WeightTransferParameters, 'moment_arm', 1.0),
])
def test_from_dict_rejects_bad_values_naming_the_key(cls, key, value):
    with pytest.raises(GaitManagerError, match=key):
        cls.from_dict({key: value})


@pytest.mark.parametrize('cls', [FeedforwardParameters, WeightTransferParameters])
def test_from_dict_rejects_unknown_keys(cls):
    with pytest.raises(GaitManagerError, match='A5'):
        cls.from_dict({'A5': 40.0})
    assert cls.from_dict({}) == cls()
