"""Torso-yaw input (eq. 10) and the arm assist of steps 1-3."""

import math

import numpy as np
import pytest

from gait_manager.arm_assist import ArmAssistParameters, arm_assist_torque
from gait_manager.errors import GaitManagerError
from gait_manager.yaw import YawParameters, yaw_torque


@pytest.mark.parametrize('reading', ['A', 'B', 'B_clipped'])
def test_yaw_sign_flips_with_the_support_side(make_obs, reading):
    params = YawParameters(phase=reading)
    right = yaw_torque(make_obs(t=2.4, t_exchange=2.0, side='right'), params)
    left = yaw_torque(make_obs(t=2.4, t_exchange=2.0, side='left'), params)
    assert right[8] > 1.0
    assert left[8] == -right[8]
    others = [j for j in range(18) if j != 8]
    assert np.all(right[others] == 0.0) and np.all(left[others] == 0.0)


def test_yaw_phase_readings_differ_as_defined(make_obs):
    dt, period = 0.4, 1.85
    obs = make_obs(t=3.0 + dt, t_exchange=3.0)
    b = yaw_torque(obs, YawParameters())[8]
    a = yaw_torque(obs, YawParameters(phase='A'))[8]
    assert b == pytest.approx(30.0 * math.sin(2.0 * math.pi * dt / period))
    assert a == pytest.approx(30.0 * math.sin(2.0 * dt / period))
    assert a < b
    late = make_obs(t=3.0 + 1.2, t_exchange=3.0)  # Phi_B = 4.08 rad > pi
    assert yaw_torque(late, YawParameters())[8] < -10.0
    assert yaw_torque(late, YawParameters(phase='B_clipped'))[8] == pytest.approx(0.0, abs=1e-12)
    early = make_obs(t=3.0 + dt, t_exchange=3.0)
    assert yaw_torque(early, YawParameters(phase='B_clipped'))[8] == pytest.approx(b)


def test_yaw_is_zero_at_the_exchange(make_obs):
    assert yaw_torque(make_obs(t=5.0, t_exchange=5.0), YawParameters())[8] == 0.0


def test_arm_assist_is_anti_phase_before_the_fourth_step(make_obs):
    for step_index in (0, 1, 2):
        for side, sign in (('right', 1.0), ('left', -1.0)):
            tau = arm_assist_torque(make_obs(t=1.3, t_exchange=1.0, side=side,
                                             step_index=step_index), ArmAssistParameters())
            expected = sign * 2.0 * math.sin(2.0 * math.pi * 0.3 / 1.85)
            assert tau[11] == pytest.approx(expected)
            assert tau[14] == -tau[11]


def test_arm_assist_elbow_and_wrist_pd(make_obs):
    q = np.zeros(18)
    v = np.zeros(18)
    q[[12, 13, 15, 16]] = (0.3, -0.2, 0.1, 0.05)
    v[[12, 13, 15, 16]] = (1.0, 0.0, -2.0, 0.0)
    tau = arm_assist_torque(make_obs(q=q, v=v), ArmAssistParameters())
    np.testing.assert_allclose(tau[[12, 13, 15, 16]], [-3.0 - 1.0, 2.0, -1.0 + 2.0, -0.5])
    assert np.all(tau[:11] == 0.0) and tau[17] == 0.0


@pytest.mark.parametrize('step_index', [3, 4, 10])
def test_arm_assist_without_release_is_zero_from_the_fourth_step_on(make_obs, step_index):
    q = np.zeros(18)
    q[11:17] = 0.3
    v = np.full(18, 0.5)
    tau = arm_assist_torque(make_obs(t=1.3, t_exchange=1.0, q=q, v=v, step_index=step_index),
                            ArmAssistParameters())
    assert np.all(tau == 0.0)


@pytest.mark.parametrize(('elapsed', 'fade'), [(0.0, 1.0), (0.2, 0.84375), (0.4, 0.5),
                                               (0.8, 0.0), (1.2, 0.0)])
def test_the_release_brakes_the_shoulders_and_fades_out(make_obs, elapsed, fade):
    """From the exchange of the 4th step on, joints 11 and 14 get -b (1 - S(t'/T_r)) v over T_r
    (S the smoothstep 3x^2 - 2x^3: 0.84375 at a quarter, 1/2 at half); nothing else moves, and
    the next step gets no brake."""
    v = np.linspace(-1.0, 1.0, 18)
    params = ArmAssistParameters(release_time=0.8, release_damping=4.0)
    tau = arm_assist_torque(make_obs(t=2.0 + elapsed, t_exchange=2.0, v=v, step_index=3),
                            params)
    np.testing.assert_allclose(tau[[11, 14]], -4.0 * fade * v[[11, 14]], rtol=1e-12, atol=1e-15)
    assert np.count_nonzero(tau[[*range(11), 12, 13, 15, 16, 17]]) == 0
    later = arm_assist_torque(make_obs(t=2.0 + elapsed, t_exchange=2.0, v=v, step_index=4),
                              params)
    assert np.all(later == 0.0)


@pytest.mark.parametrize(('cls', 'key', 'value'), [
    (YawParameters, 'amplitude', -1.0), (YawParameters, 'period', 0.0),
    (YawParameters, 'phase', 'C'), (YawParameters, 'amplitude', '30'),
    (ArmAssistParameters, 'off_from_step_index', 2.5),
    (ArmAssistParameters, 'off_from_step_index', -1), (ArmAssistParameters, 'stiffness', -1),
    (ArmAssistParameters, 'phase', None),
])
def test_from_dict_rejects_bad_values_naming_the_key(cls, key, value):
    with pytest.raises(GaitManagerError, match=key):
        cls.from_dict({key: value})


@pytest.mark.parametrize('cls', [YawParameters, ArmAssistParameters])
def test_from_dict_rejects_unknown_keys(cls):
    with pytest.raises(GaitManagerError, match='gain'):
        cls.from_dict({'gain': 1.0})
    assert cls.from_dict({}) == cls()
