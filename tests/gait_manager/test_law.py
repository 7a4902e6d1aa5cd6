"""Gait-manager entry point: enabled sources only, head stance, nested parameter validation."""

import numpy as np
import pytest

from gait_manager.errors import GaitManagerError
from gait_manager.feedforward import FeedforwardParameters
from gait_manager.law import (
    SOURCES,
    GaitManagerParameters,
    gait_manager_torques,
    head_stance,
    total_torque,
)
from gait_manager.posture import PostureParameters, posture_torque
from gait_manager.yaw import YawParameters, yaw_torque


def test_all_sources_by_default(make_obs, dynamics):
    obs = make_obs(t=1.2, t_exchange=1.0, mode=2)
    torques = gait_manager_torques(obs, dynamics, GaitManagerParameters())
    assert tuple(torques) == SOURCES
    for name, tau in torques.items():
        assert tau.shape == (18,) and tau[0] == 0.0, name
    np.testing.assert_array_equal(torques['posture'],
                                  posture_torque(obs, dynamics, PostureParameters()))
    np.testing.assert_array_equal(total_torque(torques), sum(torques.values()))


@pytest.mark.parametrize('enabled', [(), ('yaw',), ('heel', 'arm_assist'),
                                     ('feedforward', 'yaw', 'heel', 'arm_assist')])
def test_disabled_sources_are_absent_and_not_computed(make_obs, enabled):
    obs = make_obs(t=1.2, t_exchange=1.0, mode=10, t_touchdown=1.1)
    params = GaitManagerParameters(enabled=frozenset(enabled))
    # dynamics=None: posture and weight transfer would need it, so they must not be evaluated
    torques = gait_manager_torques(obs, None, params)
    assert set(torques) == set(enabled)
    if 'yaw' in enabled:
        np.testing.assert_array_equal(torques['yaw'], yaw_torque(obs, YawParameters()))
    assert np.all(total_torque(torques) == sum(torques.values(), np.zeros(18)))


def test_head_stance_follows_the_posture_source(make_obs):
    obs = make_obs(t=2.0, t_exchange=1.0, t_touchdown=1.5)
    params = GaitManagerParameters()
    stance = head_stance(params)
    assert stance == params.posture.stance
    np.testing.assert_allclose(stance.shift(obs), [0.2, -0.03])
    moved = GaitManagerParameters(posture=PostureParameters(shift_y1=0.05, shift_time2=0.2))
    assert head_stance(moved) == moved.posture.stance != stance
    no_posture = GaitManagerParameters(enabled=frozenset({'yaw'}))
    assert head_stance(no_posture) is None
    for reference in ('standing', 'balance'):
        other = GaitManagerParameters(posture=PostureParameters(reference=reference))
        assert head_stance(other) is None


def test_from_dict_nested():
    params = GaitManagerParameters.from_dict({
        'enabled': ['posture', 'yaw'],
        'posture': {'stiffness': 400, 'reference': 'standing'},
        'yaw': {'phase': 'A'},
    })
    assert params.enabled == frozenset({'posture', 'yaw'})
    assert params.posture.stiffness == 400.0 and params.posture.reference == 'standing'
    assert params.yaw.phase == 'A' and params.feedforward == FeedforwardParameters()
    assert GaitManagerParameters.from_dict({}) == GaitManagerParameters()


@pytest.mark.parametrize(('d', 'key'), [
    ({'postures': {}}, 'postures'),
    ({'posture': {'kq': 1}}, 'posture.kq'),
    ({'posture': {'stiffness': -1}}, 'posture.stiffness'),
    ({'feedforward': {'hip_amplitude': 'big'}}, 'feedforward.hip_amplitude'),
    ({'weight_transfer': {'share': 5}}, 'weight_transfer.share'),
    ({'heel': {'stiffness': None}}, 'heel.stiffness'),
    ({'arm_assist': {'off_from_step_index': 1.5}}, 'arm_assist.off_from_step_index'),
    ({'yaw': {'phase': 'C'}}, 'yaw.phase'),
    ({'yaw': 30}, 'yaw'),
    ({'enabled': ['posture', 'gravity']}, 'enabled'),
    ({'enabled': 'posture'}, 'enabled'),
])
def test_from_dict_rejects_bad_input_naming_the_key(d, key):
    with pytest.raises(GaitManagerError, match=key.replace('.', r'\.')):
        GaitManagerParameters.from_dict(d)


def test_constructor_validates_blocks_and_sources():
    with pytest.raises(GaitManagerError, match='posture'):
        GaitManagerParameters(posture={'stiffness': 1.0})
    with pytest.raises(GaitManagerError, match='enabled'):
        GaitManagerParameters(enabled=frozenset({'vla'}))
    assert issubclass(GaitManagerError, ValueError)
