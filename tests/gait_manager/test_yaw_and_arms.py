"""Torso-yaw input (eq. (10)) and the arm assist of steps 1-3 (docs/model.md §11.7-11.8), on the
C++ sources: sign rule, phase readings, anti-phase shoulders, the elbow and wrist PD, the cut-off
from the 4th step and the fading release brake."""

import math

import numpy as np
import pytest


@pytest.mark.parametrize('reading', ['A', 'B', 'B_clipped'])
def test_the_yaw_sign_flips_with_the_support_side(make_obs, torque, reading):
    right = torque('yaw', make_obs(t=2.4, t_exchange=2.0, side='right'), yaw={'phase': reading})
    left = torque('yaw', make_obs(t=2.4, t_exchange=2.0, side='left'), yaw={'phase': reading})
    assert right[8] > 1.0
    assert left[8] == -right[8]
    others = [j for j in range(18) if j != 8]
    assert np.all(right[others] == 0.0) and np.all(left[others] == 0.0)


def test_the_yaw_phase_readings_differ_as_defined(make_obs, torque):
    dt, period = 0.4, 1.85
    obs = make_obs(t=3.0 + dt, t_exchange=3.0)
    b = torque('yaw', obs)[8]
    a = torque('yaw', obs, yaw={'phase': 'A'})[8]
    assert b == pytest.approx(30.0 * math.sin(2.0 * math.pi * dt / period))
    assert a == pytest.approx(30.0 * math.sin(2.0 * dt / period))
    assert a < b
    late = make_obs(t=3.0 + 1.2, t_exchange=3.0)  # Phi_B = 4.08 rad > pi
    assert torque('yaw', late)[8] < -10.0
    assert torque('yaw', late, yaw={'phase': 'B_clipped'})[8] == pytest.approx(0.0, abs=1e-12)
    assert torque('yaw', obs, yaw={'phase': 'B_clipped'})[8] == pytest.approx(b)
    other = torque('yaw', obs, yaw={'amplitude': 12.0, 'period': 1.2})[8]
    assert other == pytest.approx(12.0 * math.sin(2.0 * math.pi * dt / 1.2))


def test_yaw_is_zero_at_the_exchange_and_a_half_wave_per_half_period(make_obs, torque):
    assert torque('yaw', make_obs(t=5.0, t_exchange=5.0))[8] == 0.0
    half = [torque('yaw', make_obs(t=5.0 + s, t_exchange=5.0))[8]
            for s in np.linspace(0.0125, 0.9125, 37)]  # the peak at T/4 = 0.4625 s among them
    assert min(half) > 0.0 and max(half) == pytest.approx(30.0, rel=1e-3)


def test_the_arm_assist_is_anti_phase_before_the_fourth_step(make_obs, torque):
    for step_index in (0, 1, 2):
        for side, sign in (('right', 1.0), ('left', -1.0)):
            tau = torque('arm_assist', make_obs(t=1.3, t_exchange=1.0, side=side,
                                                step_index=step_index))
            assert tau[11] == pytest.approx(sign * 2.0 * math.sin(2.0 * math.pi * 0.3 / 1.85))
            assert tau[14] == -tau[11]


def test_the_elbow_and_wrist_pd(make_obs, torque):
    q = np.zeros(18)
    v = np.zeros(18)
    q[[12, 13, 15, 16]] = (0.3, -0.2, 0.1, 0.05)
    v[[12, 13, 15, 16]] = (1.0, 0.0, -2.0, 0.0)
    tau = torque('arm_assist', make_obs(q=q, v=v))
    np.testing.assert_allclose(tau[[12, 13, 15, 16]], [-3.0 - 1.0, 2.0, -1.0 + 2.0, -0.5])
    assert np.all(tau[:11] == 0.0) and tau[17] == 0.0


@pytest.mark.parametrize('step_index', [3, 4, 10])
def test_without_release_no_arm_torque_from_the_fourth_step_on(make_obs, torque, step_index):
    q = np.zeros(18)
    q[11:17] = 0.3
    v = np.full(18, 0.5)
    obs = make_obs(t=1.3, t_exchange=1.0, q=q, v=v, step_index=step_index)
    assert np.all(torque('arm_assist', obs) == 0.0)
    later_cut = torque('arm_assist', obs, arm_assist={'off_from_step_index': 11})
    assert later_cut[11] != 0.0


@pytest.mark.parametrize(('elapsed', 'fade'), [(0.0, 1.0), (0.2, 0.84375), (0.4, 0.5),
                                               (0.8, 0.0), (1.2, 0.0)])
def test_the_release_brakes_the_shoulders_and_fades_out(make_obs, torque, elapsed, fade):
    """From the exchange of the 4th step on, joints 11 and 14 get -b (1 - S(t'/T_r)) v over T_r
    (S the smoothstep: 0.84375 at a quarter, 1/2 at half); nothing else moves, and the next step
    gets no brake."""
    v = np.linspace(-1.0, 1.0, 18)
    block = {'release_time': 0.8, 'release_damping': 4.0}
    tau = torque('arm_assist', make_obs(t=2.0 + elapsed, t_exchange=2.0, v=v, step_index=3),
                 arm_assist=block)
    np.testing.assert_allclose(tau[[11, 14]], -4.0 * fade * v[[11, 14]], rtol=1e-12, atol=1e-15)
    assert np.count_nonzero(tau[[*range(11), 12, 13, 15, 16, 17]]) == 0
    later = torque('arm_assist', make_obs(t=2.0 + elapsed, t_exchange=2.0, v=v, step_index=4),
                   arm_assist=block)
    assert np.all(later == 0.0)
