"""effort_cdr: EffortCommand CDR bytes <-> ControllerCommand, against the typestores' own codecs.

Reference bytes come from rosbags' serializer (the bag's codec) and, where rclpy is installed,
from rclpy's (what a controller written against the message class publishes).
"""

import numpy as np
import pytest

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import CommandValues, ControllerCommand, JointCommand
from iceskate_sim.model.robot import COORDINATE_NAMES
from iceskate_sim.recording.bag import MessageFactory
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.ros.conversions import command_fields, command_from_message
from iceskate_sim.ros.effort_cdr import CommandDecoder, CommandEncoder, read_effort_command

TYPE = 'iceskate_interfaces/msg/EffortCommand'
STAMP = 1_234_567_890_123  # ns


@pytest.fixture(scope='module')
def typestore():
    return make_typestore()


def answers() -> dict[str, ControllerCommand]:
    """Commands of every layout: plain, with impedance and breakdown, with a head target."""
    plain = JointCommand(np.linspace(-1, 1, 18))
    pd = JointCommand(np.ones(18), np.full(18, 800.0), np.full(18, 80.0), np.linspace(0, 1, 18))
    q, v = np.linspace(-0.2, 0.3, 18), np.linspace(1.0, -1.0, 18)
    return {'plain': ControllerCommand(plain, {}),
            'breakdown': ControllerCommand.of({'posture': pd, 'yaw': plain}, q, v),
            'head': ControllerCommand(plain, {'visual_lifting': plain.effort},
                                      np.array([0.1, 1.2, -0.05]))}


def rosbags_bytes(typestore, source: str, stamp_ns: int, **fields) -> bytes:
    """A message of ``fields`` (others empty) serialized by rosbags."""
    factory = MessageFactory(typestore)
    empty = np.zeros(0)
    values = {'joint_names': list(COORDINATE_NAMES), 'effort': np.zeros(18),
              'stiffness': empty, 'damping': empty, 'position_reference': empty,
              'source_names': [], 'source_efforts': empty, 'head_target': empty}
    for key, value in fields.items():
        values[key] = value if key in ('joint_names', 'source_names') else np.asarray(
            value, dtype=float)
    msg = typestore.types[TYPE](header=factory.header(stamp_ns / 1e9), source=source, **values)
    return bytes(typestore.serialize_cdr(msg, TYPE))


def assert_same(got: ControllerCommand, expected: ControllerCommand) -> None:
    for name in ('effort', 'stiffness', 'damping', 'reference'):
        a, b = getattr(got.command, name), getattr(expected.command, name)
        assert (a is None) == (b is None), name
        if a is not None:
            np.testing.assert_array_equal(a, b)
    assert list(got.source_efforts) == list(expected.source_efforts)
    for name, tau in expected.source_efforts.items():
        np.testing.assert_array_equal(got.source_efforts[name], tau)
    assert (got.head_target is None) == (expected.head_target is None)
    if expected.head_target is not None:
        np.testing.assert_array_equal(got.head_target, expected.head_target)


@pytest.mark.parametrize('layout', list(answers()))
def test_encoded_bytes_decode_with_rosbags_to_the_command(typestore, layout):
    answer = answers()[layout]
    data = CommandEncoder('gait_manager').encode(CommandValues.of(answer), STAMP)
    msg = typestore.deserialize_cdr(data, TYPE)
    assert msg.source == 'gait_manager'
    assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == STAMP
    assert_same(command_from_message(msg), answer)
    fields = command_fields(answer)
    assert data == rosbags_bytes(typestore, 'gait_manager', STAMP, **{
        key: value for key, value in fields.items() if len(value)})


def test_the_encoder_rewrites_values_and_stamp_and_follows_a_layout_change(typestore):
    encoder = CommandEncoder('gait_manager')
    rng = np.random.default_rng(3)
    for k, layout in enumerate(['breakdown', 'breakdown', 'plain', 'head', 'breakdown']):
        base = answers()[layout]
        command = base.command
        scaled = JointCommand(command.effort * rng.uniform(), *(
            (command.stiffness * 2.0, command.damping, command.reference + 0.1)
            if command.has_impedance else ()))
        answer = ControllerCommand(scaled, {s: tau + k for s, tau in base.source_efforts.items()},
                                   base.head_target)
        values = CommandValues.of(answer)
        data = CommandEncoder('gait_manager').encode(values, STAMP + k)
        assert encoder.encode(values, STAMP + k) == data  # reused bytes == fresh ones
        assert_same(command_from_message(typestore.deserialize_cdr(data, TYPE)), answer)


def test_the_decoder_reads_what_rosbags_writes_the_same_twice(typestore):
    decoder = CommandDecoder()
    for layout, answer in answers().items():
        fields = {key: value for key, value in command_fields(answer).items() if len(value)}
        for stamp in (STAMP, STAMP + 1_000_000):  # the first checked, the second by layout
            source, ns, got = decoder.decode(rosbags_bytes(typestore, layout, stamp, **fields))
            assert (source, ns) == (layout, stamp)
            assert_same(got, answer)


def test_the_decoder_reads_rclpy_bytes_whose_padding_is_not_zero():
    """rclpy's serializer leaves its padding bytes (and some trailing bytes) uninitialized."""
    serialization = pytest.importorskip('rclpy.serialization')
    from iceskate_interfaces.msg import EffortCommand
    answer = answers()['breakdown']
    msg = EffortCommand(source='gait_manager')
    for key, value in command_fields(answer).items():
        setattr(msg, key, value)
    msg.header.stamp.sec, msg.header.stamp.nanosec = 3, 7
    data = serialization.serialize_message(msg)
    decoder = CommandDecoder()
    for _ in range(2):
        source, ns, got = decoder.decode(data)
        assert (source, ns) == ('gait_manager', 3_000_000_007)
        assert_same(got, answer)
    data = CommandEncoder('gait_manager').encode(CommandValues.of(answer), 5)
    back = serialization.deserialize_message(data, EffortCommand)
    assert_same(command_from_message(back), answer)


@pytest.mark.parametrize('change, match', [
    ({'effort': [float('nan')] + [0.0] * 17}, r"effort is not finite at \['y0'\]"),
    ({'effort': [0.0] * 17}, 'effort has 17 entries for 18 joint names'),
    ({'stiffness': [-1.0] * 18, 'damping': [0.0] * 18, 'position_reference': [0.0] * 18},
     'must be >= 0'),
    ({'source_names': ['yaw'], 'source_efforts': [float('inf')] + [0.0] * 17},
     'source_efforts is not finite'),
    ({'head_target': [1.0, float('nan'), 0.0]}, 'head_target must be empty or 3 finite'),
])
def test_a_bad_value_is_named_after_good_messages_of_the_same_layout(typestore, change, match):
    """The fast way (known layout) never lets a bad value through: the checked way names it."""
    good = {key: np.zeros(len(value)) if key not in ('source_names',) else value
            for key, value in change.items()}
    if 'effort' in change:
        good['effort'] = np.zeros(18)
    decoder = CommandDecoder()
    decoder.decode(rosbags_bytes(typestore, 'posture', STAMP, **good))
    with pytest.raises(SimulationError, match="source 'posture'.*" + match):
        decoder.decode(rosbags_bytes(typestore, 'posture', STAMP + 1, **change))


@pytest.mark.parametrize('cut', [0, 3, 30, 100])
def test_bytes_that_are_not_a_command_are_named(typestore, cut):
    data = rosbags_bytes(typestore, 'posture', STAMP, stiffness=np.ones(18),
                         damping=np.ones(18), position_reference=np.ones(18))
    with pytest.raises(SimulationError, match=r'undecodable effort_commands message \(\d+ '
                                              r'bytes\)'):
        CommandDecoder().decode(data[:cut] if cut != 3 else b'\x01\x00' + data[2:])


def test_read_effort_command_gives_the_fields(typestore):
    data = rosbags_bytes(typestore, 'yaw', STAMP, effort=np.arange(18.0),
                         source_names=['a', 'b'], source_efforts=np.arange(36.0))
    msg, _ = read_effort_command(data)
    assert (msg.source, msg.stamp_ns, msg.frame_id) == ('yaw', STAMP, '')
    assert msg.joint_names == list(COORDINATE_NAMES) and msg.source_names == ['a', 'b']
    np.testing.assert_array_equal(msg.source_efforts, np.arange(36.0))
    assert msg.stiffness.size == 0


def test_the_skeleton_tells_senders_and_source_names_of_one_layout_apart(typestore):
    """Messages that differ only in the sender's or the sources' names (same lengths) decode
    as their own, the fast way or not."""
    decoder = CommandDecoder()
    for k in range(3):
        for sender, names in (('aa', ['x', 'y']), ('bb', ['x', 'y']), ('aa', ['u', 'v'])):
            data = rosbags_bytes(typestore, sender, STAMP + k, effort=np.full(18, k + 1.0),
                                 source_names=names, source_efforts=np.arange(36.0) * k)
            source, ns, got = decoder.decode_values(data)
            assert (source, ns, got.sources) == (sender, STAMP + k, tuple(names))
            np.testing.assert_array_equal(got.effort, np.full(18, k + 1.0))
            np.testing.assert_array_equal(got.source_efforts, np.arange(36.0) * k)
