"""effort_cdr: EffortCommand CDR bytes <-> ControllerCommand, against the typestores' own codecs.

Reference bytes come from rosbags' serializer (the bag's codec) and, where rclpy is installed,
from rclpy's (what a controller written against the message class publishes). A decoder that
knows a sender's layout reads its values in place (read-only views of the message's bytes);
the checked way (a new layout) gives copies: ``writeable`` tells which way a message went.
"""

import numpy as np
import pytest

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import CommandValues
from iceskate_sim.model.robot import COORDINATE_NAMES
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.ros.conversions import command_from_message
from iceskate_sim.ros.effort_cdr import CommandDecoder, CommandEncoder
from oracle.commands import ControllerCommand, JointCommand, command_of, values_of
from oracle.messages import command_fields

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


def rosbags_bytes(typestore, source: str, stamp_ns: int, run_token: str = '', **fields) -> bytes:
    """A message of ``fields`` (others empty) serialized by rosbags."""
    empty = np.zeros(0)
    values = {'joint_names': list(COORDINATE_NAMES), 'effort': np.zeros(18),
              'stiffness': empty, 'damping': empty, 'position_reference': empty,
              'source_names': [], 'source_efforts': empty, 'head_target': empty}
    for key, value in fields.items():
        values[key] = value if key in ('joint_names', 'source_names') else np.asarray(
            value, dtype=float)
    types = typestore.types
    header = types['std_msgs/msg/Header'](
        stamp=types['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9,
                                                   nanosec=stamp_ns % 10**9), frame_id='')
    msg = types[TYPE](header=header, source=source, run_token=run_token, **values)
    return bytes(typestore.serialize_cdr(msg, TYPE))


def assert_same(got: CommandValues | ControllerCommand,
                expected: CommandValues | ControllerCommand) -> None:
    got, expected = (command_of(x) if isinstance(x, CommandValues) else x
                     for x in (got, expected))
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
    data = CommandEncoder('gait_manager').encode(values_of(answer), STAMP)
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
        values = values_of(answer)
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


def wire_bytes(serialization, msg, typestore) -> bytes:
    """What a raw subscription gets of the rclpy EffortCommand ``msg``:
    ``serialize_message``'s bytes (their padding left uninitialized) cut to the size of
    rosbags' serialization of the same fields. ``serialize_message`` returns a buffer of the
    estimated size, up to 16 bytes longer (measured: a Python publisher's EffortCommand of
    76 bytes arrives as 76 bytes; ``serialize_message`` gives 92)."""
    size = len(rosbags_bytes(
        typestore, msg.source, msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec,
        msg.run_token,
        joint_names=list(msg.joint_names), source_names=list(msg.source_names),
        **{key: np.asarray(getattr(msg, key)) for key in (
            'effort', 'stiffness', 'damping', 'position_reference', 'source_efforts',
            'head_target')}))
    return bytes(serialization.serialize_message(msg))[:size]


@pytest.mark.parametrize('layout', list(answers()))
def test_the_decoder_reads_rclpy_bytes_whose_padding_is_not_zero(typestore, layout):
    """rclpy's serializer leaves its padding bytes uninitialized."""
    serialization = pytest.importorskip('rclpy.serialization')
    from iceskate_interfaces.msg import EffortCommand
    answer = answers()[layout]
    msg = EffortCommand(source='gait_manager')
    for key, value in command_fields(answer).items():
        setattr(msg, key, value)
    msg.header.stamp.sec, msg.header.stamp.nanosec = 3, 7
    data = wire_bytes(serialization, msg, typestore)
    decoder = CommandDecoder()
    for _ in range(2):  # the checked way, then the known layout
        source, ns, got = decoder.decode(data)
        assert (source, ns) == ('gait_manager', 3_000_000_007)
        assert_same(got, answer)
    data = CommandEncoder('gait_manager').encode(values_of(answer), 5)
    back = serialization.deserialize_message(data, EffortCommand)
    assert_same(command_from_message(back), answer)


@pytest.mark.parametrize('pad', [1, 2, 3])
def test_trailing_padding_bytes_read_the_same(typestore, pad):
    """Fast DDS may pad a message to 4 bytes (bytes of any value): the checked way and the
    known layout read it as the message."""
    for layout, answer in answers().items():
        fields = {key: value for key, value in command_fields(answer).items() if len(value)}
        data = rosbags_bytes(typestore, layout, STAMP, **fields)
        decoder = CommandDecoder()
        for padded in (data + b'\xab' * pad, data + bytes(pad)):  # new layout, then known
            source, ns, got = decoder.decode(padded)
            assert (source, ns) == (layout, STAMP)
            assert_same(got, answer)


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


def test_the_checked_way_gives_the_fields(typestore):
    """A new layout: every field read from its place (the values copies of the bytes)."""
    data = rosbags_bytes(typestore, 'yaw', STAMP, effort=np.arange(18.0),
                         stiffness=np.full(18, 2.0), damping=np.full(18, 0.5),
                         position_reference=np.linspace(0, 1, 18), source_names=['a', 'b'],
                         source_efforts=np.arange(36.0), head_target=[0.1, 1.2, -0.05])
    source, ns, got = CommandDecoder().decode(data)
    assert (source, ns, got.sources) == ('yaw', STAMP, ('a', 'b'))
    for name, want in (('effort', np.arange(18.0)), ('stiffness', np.full(18, 2.0)),
                       ('damping', np.full(18, 0.5)), ('reference', np.linspace(0, 1, 18)),
                       ('source_efforts', np.arange(36.0)),
                       ('head_target', [0.1, 1.2, -0.05])):
        np.testing.assert_array_equal(getattr(got, name), want, err_msg=name)
        assert getattr(got, name).flags.writeable, name  # not a view of the message


def _values(seed: int, layout: str) -> dict[str, np.ndarray]:
    """Fields of a command of ``layout`` with values of their own."""
    rng = np.random.default_rng(seed)
    fields = {'effort': rng.normal(size=18)}
    if layout in ('impedance', 'all'):
        fields |= {'stiffness': rng.uniform(0, 900, 18), 'damping': rng.uniform(0, 90, 18),
                   'position_reference': rng.normal(size=18)}
    if layout in ('breakdown', 'all'):
        fields |= {'source_names': ['posture', 'yaw'], 'source_efforts': rng.normal(size=36)}
    if layout == 'all':
        fields['head_target'] = rng.normal(size=3)
    return fields


def test_the_known_layout_way_and_the_checked_way_agree(typestore):
    """The second message of a sender's layout is read in place; it decodes as a new decoder
    (the checked way) and rosbags decode it."""
    known = CommandDecoder()
    for k, layout in enumerate(('plain', 'impedance', 'breakdown', 'all')):
        known.decode(rosbags_bytes(typestore, layout, STAMP, **_values(100 + k, layout)))
        for seed in range(3):
            data = rosbags_bytes(typestore, layout, STAMP + seed, **_values(seed, layout))
            fast = known.decode(data)
            checked = CommandDecoder().decode(data)
            assert not fast[2].effort.flags.writeable  # read in place
            assert fast[:2] == checked[:2] == (layout, STAMP + seed)
            assert fast[2].sources == checked[2].sources
            for a, b in zip(fast[2][:6], checked[2][:6], strict=True):
                np.testing.assert_array_equal(a, b)
            assert_same(known.decode(data)[2],
                        command_from_message(typestore.deserialize_cdr(data, TYPE)))


def test_a_sender_whose_layout_changes_is_checked_again(typestore):
    """A sender's message of another layout (sources, impedance, head target or joint names
    changed) is not read at the places of its former layout: it is checked and decoded as
    itself, and its bad values are named."""
    decoder = CommandDecoder()
    sequence = ('plain', 'plain', 'impedance', 'impedance', 'breakdown', 'all', 'plain')
    for seed, layout in enumerate(sequence):
        fields = _values(seed, layout)
        data = rosbags_bytes(typestore, 'gait_manager', STAMP + seed, **fields)
        source, ns, got = decoder.decode(data)
        assert (source, ns) == ('gait_manager', STAMP + seed)
        assert_same(got, command_from_message(typestore.deserialize_cdr(data, TYPE)))
    # the names in another order: the same lengths, another layout, another meaning
    names = list(reversed(COORDINATE_NAMES))
    data = rosbags_bytes(typestore, 'gait_manager', STAMP, joint_names=names,
                         effort=np.arange(18.0))
    got = decoder.decode(data)[2]
    np.testing.assert_array_equal(got.effort, np.arange(18.0)[::-1])
    # a known layout again, its gains now negative: named
    fields = _values(1, 'impedance')
    decoder.decode(rosbags_bytes(typestore, 'gait_manager', STAMP, **fields))
    fields['damping'] = -fields['damping']
    with pytest.raises(SimulationError, match="source 'gait_manager'.*must be >= 0"):
        decoder.decode(rosbags_bytes(typestore, 'gait_manager', STAMP, **fields))


def test_the_skeleton_tells_senders_and_source_names_of_one_layout_apart(typestore):
    """Messages that differ only in the sender's or the sources' names (same lengths) decode
    as their own, the fast way or not."""
    decoder = CommandDecoder()
    for k in range(3):
        for sender, names in (('aa', ['x', 'y']), ('bb', ['x', 'y']), ('aa', ['u', 'v'])):
            data = rosbags_bytes(typestore, sender, STAMP + k, effort=np.full(18, k + 1.0),
                                 source_names=names, source_efforts=np.arange(36.0) * k)
            source, ns, got = decoder.decode(data)
            assert (source, ns, got.sources) == (sender, STAMP + k, tuple(names))
            np.testing.assert_array_equal(got.effort, np.full(18, k + 1.0))
            np.testing.assert_array_equal(got.source_efforts, np.arange(36.0) * k)


def test_a_command_of_another_run_is_refused_on_both_paths(typestore):
    """A decoder with the run's token refuses a command carrying another one (or none), on the
    checked path and on the path of a layout already known for that controller."""
    from iceskate_sim.ros.effort_cdr import ForeignCommand
    values = values_of(answers()['breakdown'])
    decoder = CommandDecoder('ours')
    assert decoder.decode(CommandEncoder('gait_manager', 'ours').encode(values, STAMP))[0] \
        == 'gait_manager'  # its layout is known from now on
    for token in ('', 'ourz', 'x' * 64):
        with pytest.raises(ForeignCommand, match="naming 'gait_manager' is not of this run"):
            decoder.decode(CommandEncoder('gait_manager', token).encode(values, STAMP))
    with pytest.raises(ForeignCommand):
        CommandDecoder().decode(CommandEncoder('gait_manager', 'ours').encode(values, STAMP))
