"""gait_state_cdr: GaitState CDR bytes -> the native observation, against the typestores' own
codecs and ``observation_from_gait_state`` (the conversion of a decoded message)."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from iceskate_bringup.scene import load_scene, scene_sources
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.stamps import stamp_to_ns
from iceskate_sim.physics.native_control import native_observation
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.ros.conversions import observation_from_gait_state
from iceskate_sim.ros.gait_state_cdr import read_observation
from iceskate_sim.ros.lockstep import LockstepSession
from iceskate_sim.run.session import Session

TYPE = 'iceskate_interfaces/msg/GaitState'
FAST_SKATE = Path(__file__).resolve().parents[1] / 'data' / 'fast_skate.yaml'


@pytest.fixture(scope='module')
def typestore():
    return make_typestore()


FIELDS = ('t', 'q', 'v', 'mode', 'side', 'pivot', 'step_index', 't_exchange', 'heel_anchor_y',
          't_touchdown')


def assert_same(a, b) -> None:
    """Native observations ``a`` and ``b`` are equal, field by field."""
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and np.array_equal(x, y), name
        else:
            assert x == y or (x != x and y != y), name  # NaN: no touchdown


@pytest.fixture(scope='module')
def states(typestore) -> list[bytes]:
    """Live gait_state bytes of 1.5 s of the fast skating gait (every 10th instant: modes,
    multipliers, touchdowns and causes of several kinds)."""
    scene = replace(load_scene(FAST_SKATE), duration=1.5)
    from iceskate_bringup.composition import ControlStack
    session = LockstepSession(Session(scene), scene_sources(scene))
    stack = ControlStack(scene, session.robot, session.session.observation())
    out = []
    while not session.done:
        data = session.state_bytes(('/gait_state',))['/gait_state']
        if session.periods % 10 == 0:
            out.append(data)
        obs = session.session.observation()
        for controller, command in stack.commands(obs).items():
            session.offer(controller, session.t_ns, command)
        session.step()
    return out


def test_the_reader_gives_the_observation_of_the_decoded_message(typestore, states):
    seen = {'modes': set(), 'multipliers': set(), 'touched': set()}
    for data in states:
        msg = typestore.deserialize_cdr(data, TYPE)
        ns, obs = read_observation(data)
        assert ns == stamp_to_ns(msg.header.stamp)
        assert_same(obs, native_observation(observation_from_gait_state(msg)))
        seen['modes'].add(obs.mode)
        seen['multipliers'].add(len(msg.multipliers))
        seen['touched'].add(bool(msg.touched_down))
    assert len(seen['modes']) >= 3 and len(seen['multipliers']) >= 2
    assert seen['touched'] == {True, False}


def test_the_reader_reads_rclpy_bytes_whose_padding_is_not_zero(typestore, states):
    serialization = pytest.importorskip('rclpy.serialization')
    from iceskate_interfaces.msg import GaitState
    for data in states[::15]:
        back = serialization.serialize_message(
            serialization.deserialize_message(data, GaitState))
        assert_same(read_observation(back)[1], native_observation(
            observation_from_gait_state(typestore.deserialize_cdr(data, TYPE))))


def _changed(typestore, data: bytes, **change) -> bytes:
    msg = typestore.deserialize_cdr(data, TYPE)
    for key, value in change.items():
        setattr(msg, key, value)
    return bytes(typestore.serialize_cdr(msg, TYPE))


@pytest.mark.parametrize(('change', 'match'), [
    ({'support_side': 2}, 'gait_state support_side must be 0 or 1, got 2'),
    ({'pivot': 7}, 'gait_state pivot must be 0, 1 or 2, got 7'),
    ({'mode': 21}, 'gait_state: observation mode 21 is not a Table 2 mode'),
    ({'heel_anchor_y': np.inf}, "gait_state: the observation's t, t_exchange and heel_anchor_y"),
    ({'position': np.zeros(17)}, r'gait_state position has 17 entries; it needs 18'),
    ({'velocity': np.r_[np.zeros(5), np.nan, np.zeros(12)]},
     r"gait_state velocity is not finite at \['q5'\]"),
])
def test_a_malformed_field_is_named(typestore, states, change, match):
    with pytest.raises(SimulationError, match=match):
        read_observation(_changed(typestore, states[3], **change))


@pytest.mark.parametrize('cut', [0, 2, 20, 200, -1])
def test_bytes_that_are_not_a_gait_state_are_named(states, cut):
    data = states[3]
    with pytest.raises(SimulationError, match=r'undecodable gait_state \(\d+ bytes\)'):
        read_observation(data[:cut] if cut != 2 else b'\x01\x00' + data[2:])
