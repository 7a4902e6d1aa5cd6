"""Heel-first landing input on the swing ankle (docs/model.md §11.6), on the C++ source."""

import numpy as np
import pytest


def _with_sole_pitch(theta: float, rate: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Bent stance whose swing-sole pitch q2 + ... + q7 is ``theta`` (set through q7)."""
    q = np.zeros(18)
    q[2:8] = (-0.05, 0.10, -0.05, 0.30, -0.40, 0.0)
    q[7] = theta - q[2:7].sum()
    v = np.zeros(18)
    v[5] = rate
    return q, v


def test_toe_down_swing_foot_gets_a_toe_up_torque(make_obs, torque):
    q, v = _with_sole_pitch(-0.2)
    tau = torque('heel', make_obs(t=1.0, q=q, v=v, mode=1))
    assert tau[7] > 0.0  # positive pitch lifts the toe (docs/model.md §1.2)
    assert tau[7] == pytest.approx(150.0 * (0.15 + 0.2))
    assert np.all(np.delete(tau, 7) == 0.0)


def test_toe_up_beyond_the_landing_pitch_gets_a_toe_down_torque(make_obs, torque):
    q, v = _with_sole_pitch(0.4, rate=0.5)
    tau = torque('heel', make_obs(t=1.0, q=q, v=v, mode=1))
    assert tau[7] == pytest.approx(150.0 * (0.15 - 0.4) - 6.0 * 0.5)


@pytest.mark.parametrize(('elapsed', 'pitch'), [(0.0, 0.0), (0.075, 0.075), (0.15, 0.15),
                                                (0.5, 0.15)])
def test_the_landing_pitch_ramps_after_the_exchange(make_obs, torque, elapsed, pitch):
    """theta_land rises linearly from 0 at t_e to 0.15 rad over 0.15 s: with a flat sole at
    rest the torque is K7 theta_land; a 0 s ramp is a step."""
    q, v = _with_sole_pitch(0.0)
    obs = make_obs(t=2.0 + elapsed, t_exchange=2.0, q=q, v=v)
    assert torque('heel', obs)[7] == pytest.approx(150.0 * pitch, abs=1e-12)
    stepped = torque('heel', make_obs(t=2.0, t_exchange=2.0, q=q, v=v), heel={'ramp_time': 0.0})
    assert stepped[7] == pytest.approx(150.0 * 0.15)


@pytest.mark.parametrize('mode', [5, 9, 10])  # Hs, Hp, Hp with q1 active
def test_heel_contact_lowers_the_sole_to_flat(make_obs, torque, mode):
    q, v = _with_sole_pitch(0.1, rate=0.2)
    tau = torque('heel', make_obs(t=1.0, q=q, v=v, mode=mode))
    assert tau[7] == pytest.approx(-30.0 * 0.1 - 3.0 * 0.2)
    assert np.all(np.delete(tau, 7) == 0.0)


def test_the_sole_pitch_includes_q1_only_while_active(make_obs, torque):
    q, v = _with_sole_pitch(0.0)
    q[1] = -0.1  # a held (locked) q1 must not count; an active one must
    locked = torque('heel', make_obs(t=1.0, q=q, v=v, mode=1))
    active = torque('heel', make_obs(t=1.0, q=q, v=v, mode=2))
    assert locked[7] == pytest.approx(150.0 * 0.15)
    assert active[7] == pytest.approx(150.0 * 0.25)


@pytest.mark.parametrize('mode', [13, 14, 17, 18])  # Fs, Fp
def test_a_flat_sole_gets_no_heel_input(make_obs, torque, mode):
    q, v = _with_sole_pitch(0.1, rate=0.2)
    assert np.all(torque('heel', make_obs(t=1.0, q=q, v=v, mode=mode)) == 0.0)
