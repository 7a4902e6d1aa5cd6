"""recording.cdr: byte layouts computed from the ``.msg`` definitions, checked against the
bytes rosbags' own serializer writes (``Typestore.serialize_cdr``) for every message type the
project sends, with strings and sequence lengths that move every alignment."""

import numpy as np
import pytest
from rosbags.interfaces import Nodetype

import iceskate_native
from iceskate_sim.model.robot import COORDINATE_NAMES
from iceskate_sim.recording import cdr
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.recording.cdr import LayoutCache, LayoutError, layout_for, layout_of
from iceskate_sim.recording.messages import TOPICS

NAMES = list(COORDINATE_NAMES)

#: (case id, message type, shape): every type of messages.TOPICS, EffortCommand, GaitState with
#: and without multipliers, TFMessage with several transforms, and odd lengths everywhere (a
#: string of 1, 2 or 3 bytes before numbers of 8, a bool sequence of odd length, a sequence of
#: numbers that is empty).
CASES = [
    ('clock', 'rosgraph_msgs/msg/Clock', {}),
    ('joint_states', 'sensor_msgs/msg/JointState',
     {'name': NAMES, 'position': 18, 'velocity': 18, 'effort': 18}),
    ('joint_states_odd', 'sensor_msgs/msg/JointState',
     {'header.frame_id': 'ab', 'name': ['a', 'bc', ''], 'position': 3, 'velocity': 0,
      'effort': 1}),
    ('head_pose', 'geometry_msgs/msg/PoseStamped', {'header.frame_id': 'world'}),
    ('gait_state_no_multipliers', 'iceskate_interfaces/msg/GaitState',
     {'multiplier_names': [], 'multipliers': 0, 'position': 18, 'velocity': 18}),
    ('gait_state_multipliers', 'iceskate_interfaces/msg/GaitState',
     {'header.frame_id': 'x', 'multiplier_names': ['f_nz', 'tau_n'], 'multipliers': 2,
      'last_transition_cause': 'support glide stopped', 'position': 18, 'velocity': 18}),
    ('gait_state_one', 'iceskate_interfaces/msg/GaitState',
     {'multiplier_names': ['f_nz'], 'multipliers': 1, 'last_transition_cause': 'E1',
      'position': 5, 'velocity': 0}),
    ('joint_dynamics', 'iceskate_interfaces/msg/JointDynamics',
     {'name': NAMES, 'active': 18, 'acceleration': 18,
      'source_names': ['posture', 'heel', 'passive'], 'source_efforts': 54}),
    ('joint_dynamics_odd', 'iceskate_interfaces/msg/JointDynamics',
     {'header.frame_id': 'abc', 'name': ['q'], 'active': 3, 'acceleration': 3,
      'source_names': ['passive'], 'source_efforts': 3}),
    ('robot_description', 'std_msgs/msg/String', {'data': '<robot name="r"/>'}),
    ('empty_string', 'std_msgs/msg/String', {}),
    ('tf_one', 'tf2_msgs/msg/TFMessage',
     {'transforms': 1, 'transforms.0.header.frame_id': 'world',
      'transforms.0.child_frame_id': 'pelvis'}),
    ('tf_several', 'tf2_msgs/msg/TFMessage',
     {'transforms': 4, 'transforms.0.header.frame_id': 'world',
      'transforms.0.child_frame_id': 'pelvis', 'transforms.1.header.frame_id': 'pelvis',
      'transforms.1.child_frame_id': 'r', 'transforms.2.header.frame_id': 'r',
      'transforms.2.child_frame_id': 'ab', 'transforms.3.child_frame_id': 'head_top'}),
    ('tf_none', 'tf2_msgs/msg/TFMessage', {'transforms': 0}),
    ('effort_command', 'iceskate_interfaces/msg/EffortCommand',
     {'source': 'posture', 'joint_names': NAMES, 'effort': 18, 'stiffness': 18,
      'damping': 18, 'position_reference': 18, 'source_names': ['posture', 'arm'],
      'source_efforts': 36, 'head_target': 3}),
    ('effort_command_sparse', 'iceskate_interfaces/msg/EffortCommand',
     {'source': 'yaw', 'joint_names': ['torso_yaw'], 'effort': 1, 'stiffness': 0,
      'damping': 0, 'position_reference': 0, 'source_names': [], 'source_efforts': 0,
      'head_target': 0}),
    # fixed-size arrays, uint32, bool and a nested message (not sent by the project, but the
    # layout walks ARRAY fields too)
    ('camera_info', 'sensor_msgs/msg/CameraInfo',
     {'header.frame_id': 'cam', 'distortion_model': 'plumb_bob', 'd': 5}),
]

IDS = [case[0] for case in CASES]


def test_the_cases_cover_every_topic():
    types = {msgtype for _, msgtype, _ in CASES}
    assert set(TOPICS.values()) <= types
    assert 'iceskate_interfaces/msg/EffortCommand' in types


@pytest.fixture(scope='module')
def typestore():
    return make_typestore()


def _random(rng: np.random.Generator, primitive: str, count: int | None):
    """``count`` random values of a primitive (None: one, as a Python scalar)."""
    dtype = np.dtype(cdr.PRIMITIVES[primitive])
    n = 1 if count is None else count
    if primitive == 'bool':
        values = rng.integers(0, 2, n).astype(bool)
    elif dtype.kind == 'f':
        values = (rng.standard_normal(n) * 10.0 ** rng.integers(-3, 4, n)).astype(dtype)
    else:
        info = np.iinfo(dtype)
        values = rng.integers(info.min, info.max, n, dtype=dtype, endpoint=True)
    if count is None:
        return values[0].item()
    return values


def _zero(primitive: str, count: int | None):
    dtype = bool if primitive == 'bool' else np.dtype(cdr.PRIMITIVES[primitive])
    return np.zeros(count, dtype) if count is not None else (
        False if primitive == 'bool' else dtype.type(0).item())


def build(typestore, msgtype, shape, rng=None, prefix=''):
    """A rosbags message of ``msgtype`` with the strings and lengths of ``shape`` (as
    ``layout_for`` takes it) and random numbers (0 if ``rng`` is None), and those numbers by
    path (arrays as arrays)."""
    fields, numbers = {}, {}

    def value(primitive, path, count=None):
        v = _zero(primitive, count) if rng is None else _random(rng, primitive, count)
        numbers[path] = np.atleast_1d(np.asarray(v))
        return v

    for name, (kind, detail) in typestore.fielddefs[msgtype][1]:
        path = prefix + name
        if kind == Nodetype.NAME:
            fields[name], inner = build(typestore, detail, shape, rng, path + '.')
            numbers.update(inner)
        elif kind == Nodetype.BASE:
            primitive = detail[0]
            fields[name] = (str(shape.get(path, '')) if primitive == 'string'
                            else value(primitive, path))
        else:
            (element_kind, element), length = detail
            if kind == Nodetype.SEQUENCE:
                given = shape.get(path, 0)
                length = len(given) if isinstance(given, (list, tuple)) else int(given)
            if element_kind == Nodetype.NAME:
                items = []
                for k in range(length):
                    item, inner = build(typestore, element, shape, rng, f'{path}.{k}.')
                    items.append(item)
                    numbers.update(inner)
                fields[name] = items
            elif element[0] == 'string':
                given = list(shape.get(path, ()))
                fields[name] = [given[k] if k < len(given) else str(shape.get(f'{path}.{k}', ''))
                                for k in range(length)]
            else:
                fields[name] = value(element[0], path, length)
    return typestore.types[msgtype](**fields), numbers


def _serialize(typestore, message, msgtype) -> bytes:
    return bytes(typestore.serialize_cdr(message, msgtype))


@pytest.mark.parametrize(('msgtype', 'shape'), [c[1:] for c in CASES], ids=IDS)
def test_the_template_is_what_rosbags_writes_with_zero_numbers(typestore, msgtype, shape):
    layout = layout_for(typestore, msgtype, shape)
    message, numbers = build(typestore, msgtype, shape)
    expected = _serialize(typestore, message, msgtype)
    assert layout.template == expected
    assert layout.size == len(expected)
    # every number of the message is a field of the layout, nothing else is
    assert set(layout.fields) == set(numbers)
    for path, field in layout.fields.items():
        assert field.count == len(numbers[path]), path
        assert field.dtype == np.dtype(cdr.PRIMITIVES[_primitive(typestore, msgtype, path)])


def _primitive(typestore, msgtype, path):
    """The primitive type name of the numeric field ``path`` of ``msgtype``."""
    parts = path.split('.')
    while True:
        name = parts.pop(0)
        kind, detail = dict(typestore.fielddefs[msgtype][1])[name]
        if kind == Nodetype.BASE:
            return detail[0]
        if kind == Nodetype.NAME:
            msgtype = detail
            continue
        (element_kind, element), _ = detail
        if element_kind == Nodetype.NAME:
            parts.pop(0)  # the index
            msgtype = element
            continue
        return element[0]


@pytest.mark.parametrize(('msgtype', 'shape'), [c[1:] for c in CASES], ids=IDS)
def test_layout_of_reads_back_every_number_rosbags_wrote(typestore, msgtype, shape):
    rng = np.random.default_rng(len(msgtype) + len(shape))
    message, numbers = build(typestore, msgtype, shape, rng)
    data = _serialize(typestore, message, msgtype)
    layout = layout_of(typestore, msgtype, data)
    assert layout.size == len(data)
    assert set(layout.fields) == set(numbers)
    for path, expected in numbers.items():
        got = layout.read(data, path)
        assert got.dtype == layout.fields[path].dtype
        assert np.array_equal(got, expected.astype(got.dtype)), path
    # the strings are the message's, found where layout_for puts them
    planned = layout_for(typestore, msgtype, shape)
    assert layout.strings == planned.strings
    assert layout.fields == planned.fields
    assert layout.template == planned.template  # the bytes with their numbers zeroed
    for path, given in shape.items():
        if isinstance(given, list):
            assert layout.texts(path) == given
        elif isinstance(given, str):
            assert layout.strings[path] == given


def _messages(typestore, msgtype, shape, rows, seed):
    rng = np.random.default_rng(seed)
    built = [build(typestore, msgtype, shape, rng) for _ in range(rows)]
    expected = [_serialize(typestore, message, msgtype) for message, _ in built]
    values = {path: np.stack([numbers[path] for _, numbers in built])
              for path in built[0][1]}
    # a field of one number as (rows,), as the encoders give it
    values = {path: v[:, 0] if v.shape[1] == 1 else v for path, v in values.items()}
    return expected, values


def _column(values: np.ndarray) -> np.ndarray:
    """A column of samples as the loop gives them: float64, int64 or bool, (rows, count)."""
    kind = values.dtype.kind
    dtype = np.float64 if kind == 'f' else bool if kind == 'b' else np.int64
    return np.ascontiguousarray(values.astype(dtype, casting='unsafe').reshape(len(values), -1))


def _written(layout, values: dict, paths: list[str]) -> tuple:
    """The program writing ``paths`` of ``values`` (column k: path k) and its columns."""
    program = layout.program({path: [(k, i) for i in range(layout.fields[path].count)]
                              for k, path in enumerate(paths)})
    return program, [_column(values[path]) for path in paths]


@pytest.mark.parametrize(('msgtype', 'shape'), [c[1:] for c in CASES], ids=IDS)
def test_a_program_writes_rosbags_bytes_one_row_and_many(typestore, msgtype, shape):
    layout = layout_for(typestore, msgtype, shape)
    paths = list(layout.fields)[::-1]  # any order of the paths
    expected, values = _messages(typestore, msgtype, shape, 5, seed=len(shape))
    program, columns = _written(layout, values, paths)
    assert program.size == layout.size
    many = iceskate_native.encode_rows(program, columns, 5)
    assert many.shape == (5, layout.size) and many.dtype == np.uint8
    assert [row.tobytes() for row in many] == expected
    for k in range(5):
        one = iceskate_native.encode_rows(program, [c[k:k + 1] for c in columns], 1)
        assert one[0].tobytes() == expected[k]
    assert all(layout.fits(data) for data in expected)  # a message of the layout


def test_an_empty_sequence_at_the_offset_of_the_next_field(typestore):
    """A GaitState without multipliers (modes 1-4): the empty float64 sequence has the offset
    of support_normal_force after it and writes nothing."""
    msgtype, shape = CASES[4][1:]
    layout = layout_for(typestore, msgtype, shape)
    assert layout.fields['multipliers'].count == 0
    assert layout.fields['multipliers'].offset == layout.fields['support_normal_force'].offset
    expected, values = _messages(typestore, msgtype, shape, 3, seed=13)
    paths = [p for p in layout.fields if p != 'multipliers'] + ['multipliers']
    program, columns = _written(layout, values, paths)
    assert [row.tobytes() for row in iceskate_native.encode_rows(program, columns, 3)] == expected


def test_a_program_leaves_the_fields_it_does_not_write_at_zero(typestore):
    msgtype, shape = CASES[5][1:]
    layout = layout_for(typestore, msgtype, shape)
    expected, values = _messages(typestore, msgtype, shape, 3, seed=7)
    paths = ['mode', 'multipliers', 'zmp.y', 'heel_anchor_y', 'header.stamp.nanosec']
    program, columns = _written(layout, values, paths)
    got = iceskate_native.encode_rows(program, columns, 3)
    for k in range(3):
        for path in layout.fields:
            read = layout.read(got[k].tobytes(), path)
            want = values[path][k] if path in paths else 0
            assert np.array_equal(read, np.broadcast_to(want, read.shape).astype(read.dtype)), \
                path


def test_a_program_casts_to_the_field_types_and_writes_stamps_from_nanoseconds(typestore):
    """Flags and small integers come as uint8 / int32 columns, stamps as int64 nanoseconds:
    written as rosbags writes the message's types."""
    shape = {'multiplier_names': [], 'multipliers': 0, 'position': 18, 'velocity': 18}
    layout = layout_for(typestore, 'iceskate_interfaces/msg/GaitState', shape)
    message, _ = build(typestore, 'iceskate_interfaces/msg/GaitState', shape)
    message.mode, message.support_side, message.y0_active = 8, 1, True
    message.header.stamp.sec, message.header.stamp.nanosec = 3, 999_999_999
    message.touchdown_stamp.sec = 2_000_000_000  # int32: up to 2**31 - 1 s
    expected = _serialize(typestore, message, 'iceskate_interfaces/msg/GaitState')
    columns = [np.array([8, 8], np.int32), np.array([1, 1], np.int32),
               np.array([1, 1], np.uint8),
               np.array([[3_999_999_999, 2_000_000_000 * 1_000_000_000]] * 2, np.int64)]
    program = layout.program({'mode': [(0, 0)], 'support_side': [(1, 0)],
                              'y0_active': [(2, 0)], 'header.stamp': [(3, 0)],
                              'touchdown_stamp': [(3, 1)]})
    assert [r.tobytes() for r in iceskate_native.encode_rows(program, columns, 2)] == [
        expected] * 2


def test_a_program_refuses_what_it_cannot_write(typestore):
    layout = layout_for(typestore, 'rosgraph_msgs/msg/Clock', {})
    with pytest.raises(LayoutError, match="'clock.sec' holds 1 numbers, not 2"):
        layout.program({'clock.sec': [(0, 0), (0, 1)]})
    with pytest.raises(LayoutError, match="'header.stamp' is neither a numeric field nor a"):
        layout.program({'header.stamp': [(0, 0)]})
    with pytest.raises(ValueError, match='does not fit in a message of 12 bytes'):
        iceskate_native.CdrProgram(layout.template, np.array([[10, 0, 0, 0]], np.uint32))
    program = layout.program({'clock': [(1, 2)]})
    stamps = np.zeros((2, 3), np.int64)
    with pytest.raises(ValueError, match='reads element 2 of column 1, which 1 columns'):
        iceskate_native.encode_rows(program, [stamps], 2)
    with pytest.raises(ValueError, match='element 2 of column 1'):
        iceskate_native.encode_rows(program, [stamps, stamps[:, :2]], 2)
    with pytest.raises(ValueError, match='column 1 does not have 2 rows'):
        iceskate_native.encode_rows(program, [stamps, stamps[:1]], 2)
    with pytest.raises(ValueError, match='column 0 is not float64'):
        iceskate_native.encode_rows(program, [stamps.astype(np.float32), stamps], 2)
    assert iceskate_native.encode_rows(program, [stamps, stamps], 2).shape == (2, 12)


@pytest.mark.parametrize(('msgtype', 'shape'), [c[1:] for c in CASES], ids=IDS)
def test_fits_rejects_another_string_or_length(typestore, msgtype, shape):
    layout = layout_for(typestore, msgtype, shape)
    rng = np.random.default_rng(3)
    same, _ = build(typestore, msgtype, shape, rng)
    assert layout.fits(_serialize(typestore, same, msgtype))  # other numbers: the same layout
    changed = 0
    for path, given in shape.items():
        if isinstance(given, str):
            others = [given + 'x', (given[:-1] + chr(ord(given[-1]) ^ 1)) if given else 'x']
        elif isinstance(given, list):
            others = [given + ['x']] + (
                [given[:-1], [*given[:-1], given[-1] + 'y']] if given else [])
        else:
            others = [given + 1] + ([given - 1] if given else [])
        for other in others:
            message, _ = build(typestore, msgtype, {**shape, path: other}, rng)
            data = _serialize(typestore, message, msgtype)
            assert not layout.fits(data), (path, other)
            assert not layout.fits(data + bytes(-len(data) % 4)), (path, other)
            changed += 1
    assert changed or not shape


def test_fits_rejects_a_same_length_string_that_differs(typestore):
    layout = layout_for(typestore, 'geometry_msgs/msg/PoseStamped', {'header.frame_id': 'world'})
    message, _ = build(typestore, 'geometry_msgs/msg/PoseStamped', {'header.frame_id': 'worle'})
    data = _serialize(typestore, message, 'geometry_msgs/msg/PoseStamped')
    assert len(data) == layout.size and not layout.fits(data)


@pytest.fixture(scope='module')
def gait_state(typestore):
    shape = CASES[5][2]
    message, _ = build(typestore, 'iceskate_interfaces/msg/GaitState', shape,
                       np.random.default_rng(11))
    return _serialize(typestore, message, 'iceskate_interfaces/msg/GaitState')


def test_truncated_bytes_are_refused(typestore, gait_state):
    msgtype = 'iceskate_interfaces/msg/GaitState'
    for end in range(len(gait_state)):
        with pytest.raises(LayoutError):
            layout_of(typestore, msgtype, gait_state[:end])
    assert not layout_for(typestore, msgtype, CASES[5][2]).fits(gait_state[:-1])


def test_bytes_that_are_not_little_endian_cdr_are_refused(typestore, gait_state):
    msgtype = 'iceskate_interfaces/msg/GaitState'
    for header in (b'\x00\x00', b'\x01\x01', b'\x00\x03'):  # big endian, garbage, XCDR2 LE
        with pytest.raises(LayoutError, match='not little-endian CDR'):
            layout_of(typestore, msgtype, header + gait_state[2:])
    assert not layout_for(typestore, msgtype, CASES[5][2]).fits(b'\x00\x00' + gait_state[2:])


def test_a_string_without_its_nul_is_refused(typestore):
    msgtype = 'std_msgs/msg/String'
    data = _serialize(typestore, build(typestore, msgtype, {'data': 'abc'})[0], msgtype)
    assert data[-1] == 0
    with pytest.raises(LayoutError, match="string 'data' is cut or lacks its terminating NUL"):
        layout_of(typestore, msgtype, data[:-1] + b'x')
    with pytest.raises(LayoutError, match="string 'data'"):  # a length 0 has no NUL either
        layout_of(typestore, msgtype, cdr.ENCAPSULATION + bytes(4))
    with pytest.raises(LayoutError, match="string 'data'"):  # a length past the end
        layout_of(typestore, msgtype, data[:4] + (100).to_bytes(4, 'little') + data[8:])
    # a string inside a sequence: its path names it
    msgtype = 'sensor_msgs/msg/JointState'
    data = bytearray(_serialize(typestore, build(typestore, msgtype, {'name': ['a', 'bc']})[0],
                                msgtype))
    end = data.index(b'bc') + 2
    data[end] = ord('z')
    with pytest.raises(LayoutError, match="string 'name.1'"):
        layout_of(typestore, msgtype, bytes(data))


@pytest.mark.parametrize(('msgtype', 'shape'), [c[1:] for c in CASES], ids=IDS)
def test_up_to_three_padding_bytes_are_accepted_four_are_not(typestore, msgtype, shape):
    message, numbers = build(typestore, msgtype, shape, np.random.default_rng(5))
    data = _serialize(typestore, message, msgtype)
    planned = layout_for(typestore, msgtype, shape)
    for pad in (1, 2, 3):
        padded = data + bytes(pad)
        layout = layout_of(typestore, msgtype, padded)
        assert layout.size == len(data) and layout.fields == planned.fields
        assert layout.template == planned.template
        assert planned.fits(padded) and layout.fits(data)
    with pytest.raises(LayoutError, match='4 bytes after the end of the message'):
        layout_of(typestore, msgtype, data + bytes(4))
    assert not planned.fits(data + bytes(4))


def test_a_path_the_message_does_not_have_is_refused(typestore):
    with pytest.raises(LayoutError, match="JointState has no field 'names'"):
        layout_for(typestore, 'sensor_msgs/msg/JointState', {'names': ['a']})


def test_the_cache_walks_a_new_shape_once(typestore, monkeypatch):
    msgtype = 'sensor_msgs/msg/JointState'
    walks = []
    real = cdr.layout_of

    def counted(store, kind, data):
        walks.append(len(data))
        return real(store, kind, data)
    monkeypatch.setattr(cdr, 'layout_of', counted)
    rng = np.random.default_rng(2)

    def data(n: int) -> bytes:
        shape = {'name': NAMES[:n], 'position': n, 'velocity': n, 'effort': n}
        return _serialize(typestore, build(typestore, msgtype, shape, rng)[0], msgtype)

    cache = LayoutCache(typestore, msgtype, capacity=2)
    a = cache.lookup(data(3))[0]
    assert len(walks) == 1
    assert cache.lookup(data(3))[0] is a and len(walks) == 1  # other numbers, same shape
    assert cache.lookup(data(3) + b'\0')[0] is a and len(walks) == 1  # padded
    b = cache.lookup(data(4))[0]
    assert b is not a and len(walks) == 2 and b.size > a.size
    assert cache.lookup(data(3))[0] is a and len(walks) == 2  # both kept
    c = cache.lookup(data(5))[0]  # evicts the least recently used: 4
    assert len(walks) == 3
    assert cache.lookup(data(3))[0] is a and cache.lookup(data(5))[0] is c and len(walks) == 3
    assert cache.lookup(data(4))[0] is not b and len(walks) == 4
    # what the cache gives is the walk of the bytes
    sample = data(4)
    assert cache.lookup(sample)[0].fields == real(typestore, msgtype, sample).fields
    with pytest.raises(LayoutError):
        cache.lookup(sample[:-9])
