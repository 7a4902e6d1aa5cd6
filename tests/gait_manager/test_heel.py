"""Heel-first landing input on the swing ankle (docs/model.md §11.6)."""

import numpy as np
import pytest

from gait_manager.errors import GaitManagerError
from gait_manager.heel import HeelParameters, heel_torque, landing_pitch


def _with_sole_pitch(theta: float, rate: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Bent stance whose swing-sole pitch q2 + ... + q7 is ``theta`` (set through q7)."""
    q = np.zeros(18)
    q[2:8] = (-0.05, 0.10, -0.05, 0.30, -0.40, 0.0)
    q[7] = theta - q[2:7].sum()
    v = np.zeros(18)
    v[5] = rate
    return q, v


def test_toe_down_swing_foot_gets_a_toe_up_torque(make_obs):
    q, v = _with_sole_pitch(-0.2)
    tau = heel_torque(make_obs(t=1.0, q=q, v=v, mode=1), HeelParameters())
    assert tau[7] > 0.0  # positive pitch lifts the toe (docs/model.md §1.2)
    assert tau[7] == pytest.approx(150.0 * (0.15 + 0.2))
    assert np.all(np.delete(tau, 7) == 0.0)


def test_toe_up_beyond_the_landing_pitch_gets_a_toe_down_torque(make_obs):
    q, v = _with_sole_pitch(0.4, rate=0.5)
    tau = heel_torque(make_obs(t=1.0, q=q, v=v, mode=1), HeelParameters())
    assert tau[7] == pytest.approx(150.0 * (0.15 - 0.4) - 6.0 * 0.5)


def test_landing_pitch_ramps_after_the_exchange(make_obs):
    params = HeelParameters()
    assert landing_pitch(make_obs(t=2.0, t_exchange=2.0), params) == 0.0
    assert landing_pitch(make_obs(t=2.075, t_exchange=2.0), params) == pytest.approx(0.075)
    assert landing_pitch(make_obs(t=2.5, t_exchange=2.0), params) == pytest.approx(0.15)


@pytest.mark.parametrize('mode', [5, 9, 10])  # Hs, Hp, Hp with q1 active
def test_heel_contact_lowers_the_sole_to_flat(make_obs, mode):
    q, v = _with_sole_pitch(0.1, rate=0.2)
    tau = heel_torque(make_obs(t=1.0, q=q, v=v, mode=mode), HeelParameters())
    assert tau[7] == pytest.approx(-30.0 * 0.1 - 3.0 * 0.2)


def test_sole_pitch_includes_q1_only_while_active(make_obs):
    q, v = _with_sole_pitch(0.0)
    q[1] = -0.1  # a held (locked) q1 must not count; an active one must
    locked = heel_torque(make_obs(t=1.0, q=q, v=v, mode=1), HeelParameters())
    active = heel_torque(make_obs(t=1.0, q=q, v=v, mode=2), HeelParameters())
    assert locked[7] == pytest.approx(150.0 * 0.15)
    assert active[7] == pytest.approx(150.0 * 0.25)


@pytest.mark.parametrize('mode', [13, 14, 17, 18])  # Fs, Fp
def test_flat_sole_gets_no_heel_input(make_obs, mode):
    q, v = _with_sole_pitch(0.1, rate=0.2)
    assert np.all(heel_torque(make_obs(t=1.0, q=q, v=v, mode=mode), HeelParameters()) == 0.0)


@pytest.mark.parametrize(('key', 'value'), [('stiffness', -1.0), ('landing_pitch', 2.0),
                                            ('ramp_time', 'fast'), ('contact_damping', None)])
def test_from_dict_rejects_bad_values_naming_the_key(key, value):
    with pytest.raises(GaitManagerError, match=key):
        HeelParameters.from_dict({key: value})
    with pytest.raises(GaitManagerError, match='K7'):
        HeelParameters.from_dict({'K7': 1.0})
