"""gait_state_cdr: GaitState CDR bytes -> the native observation, against the typestores' own
codecs and ``observation_from_gait_state`` (the conversion of a decoded message).

The bytes are the live /gait_state of a lockstep run (``LockstepSession.state_bytes``: the
native loop's ``live()`` sample through ``SampleMessages``); rosbags' deserializer is the
independent reader they are checked against."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from iceskate_bringup.scene import load_scene, scene_sources
from iceskate_sim.errors import SimulationError
from iceskate_sim.physics.native_control import native_observation
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.ros.gait_state_cdr import GaitStateReader
from iceskate_sim.ros.lockstep import LockstepSession
from iceskate_sim.run.session import Session
from oracle.commands import stack_commands, values_of
from oracle.messages import observation_from_gait_state, stamp_to_ns

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
    while not session.session.done:
        data = session.state_bytes(('/gait_state',))['/gait_state']
        if session.session.periods % 10 == 0:
            out.append(data)
        obs = session.session.observation()
        for controller, command in stack_commands(stack, obs).items():
            session.offer(controller, session.t_ns, values_of(command))
        session.step()
    return out


def expected(typestore, data: bytes):
    """(stamp [ns], native observation) of ``data`` through rosbags' message and
    ``observation_from_gait_state``."""
    msg = typestore.deserialize_cdr(data, TYPE)
    return stamp_to_ns(msg.header.stamp), native_observation(observation_from_gait_state(msg))


def test_the_reader_gives_the_observation_of_the_decoded_message(typestore, states):
    reader = GaitStateReader()  # one reader: its layouts are reused and changed along the run
    seen = {'modes': set(), 'multipliers': set(), 'touched': set(), 'causes': set()}
    for data in states:
        msg = typestore.deserialize_cdr(data, TYPE)
        ns, obs = reader.read(data)
        want_ns, want = expected(typestore, data)
        assert ns == want_ns
        assert_same(obs, want)
        assert_same(GaitStateReader(typestore).read(data)[1], want)  # a fresh reader agrees
        seen['modes'].add(obs.mode)
        seen['multipliers'].add(len(msg.multipliers))
        seen['touched'].add(bool(msg.touched_down))
        seen['causes'].add(msg.last_transition_cause)
    # messages of several layouts: modes with 0 to 3 multipliers, several causes
    assert len(seen['modes']) >= 3 and len(seen['multipliers']) >= 2
    assert len(seen['causes']) >= 3
    assert seen['touched'] == {True, False}


def test_the_reader_reads_every_field_where_rosbags_does(typestore, states):
    """Every field the observation takes, set to values of its own (rosbags serializes them):
    a reader reading a wrong place, type or stamp part gives another observation."""
    reader = GaitStateReader()
    rng = np.random.default_rng(5)
    for k, data in enumerate(states[::7]):
        msg = typestore.deserialize_cdr(data, TYPE)
        msg.position = rng.uniform(-1.0, 1.0, 18)
        msg.velocity = rng.uniform(-5.0, 5.0, 18)
        msg.mode = int(rng.integers(1, 21))
        msg.support_side, msg.pivot = k % 2, k % 3
        msg.step_index = int(rng.integers(0, 2**31))
        msg.heel_anchor_y = float(rng.uniform(-3.0, 3.0))
        msg.touched_down = bool(k % 2)
        for stamp in (msg.header.stamp, msg.support_exchange_stamp, msg.touchdown_stamp):
            stamp.sec, stamp.nanosec = int(rng.integers(0, 1000)), int(rng.integers(0, 10**9))
        changed = bytes(typestore.serialize_cdr(msg, TYPE))
        ns, obs = reader.read(changed)
        assert (ns, obs.step_index) == (stamp_to_ns(msg.header.stamp), msg.step_index)
        assert_same(obs, expected(typestore, changed)[1])


@pytest.mark.parametrize('pad', [1, 2, 3])
def test_trailing_padding_bytes_read_the_same(typestore, states, pad):
    """Fast DDS may send a message padded to 4 bytes, with bytes of any value."""
    reader = GaitStateReader()
    for data in states[::10]:
        want_ns, want = expected(typestore, data)
        for fill in (b'\x00', b'\xab'):
            padded = data + fill * pad
            for read in (reader.read, GaitStateReader(typestore).read):  # known layout, new
                ns, obs = read(padded)
                assert ns == want_ns
                assert_same(obs, want)


def test_the_reader_reads_rclpy_bytes_whose_padding_is_not_zero(typestore, states):
    serialization = pytest.importorskip('rclpy.serialization')
    from iceskate_interfaces.msg import GaitState
    reader = GaitStateReader()
    for data in states[::15]:
        # serialize_message's buffer has the estimated size: cut to the message's, as a raw
        # subscription gets it
        size = len(typestore.serialize_cdr(typestore.deserialize_cdr(data, TYPE), TYPE))
        back = bytes(serialization.serialize_message(
            serialization.deserialize_message(data, GaitState)))[:size]
        assert_same(reader.read(back)[1], expected(typestore, data)[1])


def _changed(typestore, data: bytes, **change) -> bytes:
    msg = typestore.deserialize_cdr(data, TYPE)
    for key, value in change.items():
        setattr(msg, key, value)
    return bytes(typestore.serialize_cdr(msg, TYPE))


@pytest.mark.parametrize(('change', 'match'), [
    ({'support_side': 2}, 'gait_state support_side must be 0 or 1, got 2'),
    ({'pivot': 7}, 'gait_state pivot must be 0, 1 or 2, got 7'),
    ({'mode': 21}, r'gait_state mode 21 is not a mode of the table \(1-20\)'),
    ({'step_index': 2**32 - 1}, 'gait_state: observation step_index 4294967295 is beyond the '
                                '2147483647 steps a run can take'),
    ({'heel_anchor_y': np.inf}, "gait_state: the observation's t, t_exchange and heel_anchor_y"),
    ({'position': np.zeros(17)}, r'gait_state position has 17 entries; it needs 18'),
    ({'velocity': np.zeros(19)}, r'gait_state velocity has 19 entries; it needs 18'),
    ({'position': np.r_[np.zeros(3), np.nan, np.zeros(14)]},
     r"gait_state position is not finite at \['q3'\]"),
    ({'velocity': np.r_[np.zeros(5), np.nan, np.zeros(12)]},
     r"gait_state velocity is not finite at \['q5'\]"),
])
def test_a_malformed_field_is_named(typestore, states, change, match):
    bad = _changed(typestore, states[3], **change)
    if match.startswith('gait_state: '):  # the native observation refuses it, its own words
        with pytest.raises((SimulationError, ValueError)):
            native_observation(observation_from_gait_state(typestore.deserialize_cdr(bad, TYPE)))
    else:  # the checked conversion says the same
        with pytest.raises(SimulationError, match=match):
            observation_from_gait_state(typestore.deserialize_cdr(bad, TYPE))
    reader = GaitStateReader()
    reader.read(states[3])
    for read in (GaitStateReader().read, reader.read):  # a new layout, and a known one
        with pytest.raises(SimulationError, match=match):
            read(bad)
    reader.read(states[3])  # still reads the good ones


BAD_BYTES = {  # how the bytes of a good message are spoiled, what the error then says
    'empty': (lambda data: b'', 'not little-endian CDR'),
    'not CDR': (lambda data: b'\x01\x00' + data[2:], 'not little-endian CDR'),
    'big-endian': (lambda data: b'\x00\x00' + data[2:], 'not little-endian CDR'),
    'header only': (lambda data: data[:4], r'\d+ bytes end inside the message'),
    'cut at 20': (lambda data: data[:20], r'\d+ bytes end inside the message'),
    'cut at 200': (lambda data: data[:200], r'\d+ bytes end inside the message'),
    'last byte cut': (lambda data: data[:-1], r'\d+ bytes end inside the message'),
    '4 bytes more': (lambda data: data + bytes(4), '4 bytes after the end of the message'),
    'no NUL': (lambda data: data[:16] + b'x' + data[17:],  # header.frame_id: '' (1 byte)
               "string 'header.frame_id' is cut or lacks its terminating NUL"),
}


@pytest.mark.parametrize('spoil', list(BAD_BYTES))
def test_bytes_that_are_not_a_gait_state_are_named(typestore, states, spoil):
    data = states[3]
    change, match = BAD_BYTES[spoil]
    bad = change(data)
    if spoil != 'no NUL':  # rosbags cannot read them either (it drops a string's last byte)
        with pytest.raises(Exception):  # noqa: B017, PT011 (it raises several kinds)
            typestore.deserialize_cdr(bad, TYPE)
    reader = GaitStateReader()
    reader.read(data)  # a known layout does not let them through either
    with pytest.raises(SimulationError,
                       match=rf'^undecodable gait_state \({len(bad)} bytes\): .*(?:{match})'):
        reader.read(bad)
