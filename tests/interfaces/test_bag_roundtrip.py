"""Our messages in an MCAP rosbag2 bag: rosbags writes and reads them, mcap_ros2 decodes them.

ROS-free: the types come from the .msg files through iceskate_sim.recording.bag_types, no build
needed.
"""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('rosbags')

from rosbags.rosbag2 import Reader, StoragePlugin, Writer  # noqa: E402

from iceskate_sim.errors import SimulationError  # noqa: E402
from iceskate_sim.installed import share_path  # noqa: E402
from iceskate_sim.recording.bag_types import make_typestore, msg_types  # noqa: E402

GAIT_STATE = 'iceskate_interfaces/msg/GaitState'
EFFORT_COMMAND = 'iceskate_interfaces/msg/EffortCommand'
JOINT_DYNAMICS = 'iceskate_interfaces/msg/JointDynamics'
COORDINATES = ['y0'] + [f'q{i}' for i in range(1, 18)]
SOURCE_MSG_DIR = Path(__file__).resolve().parents[2] / 'ros_ws' / 'src' / 'interfaces' / 'msg'


def is_field(name: str) -> bool:
    """Tell a message field from rosbags' extra dataclass fields (constants, __msgtype__)."""
    return not name.startswith('__') and not name.isupper()


def to_plain(value):
    """Return value with rosbags dataclasses as dicts and NumPy arrays as lists (for ==)."""
    if dataclasses.is_dataclass(value):
        return {f.name: to_plain(getattr(value, f.name))
                for f in dataclasses.fields(value) if is_field(f.name)}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [to_plain(v) for v in value]
    return value


def from_mcap(value):
    """Return an mcap_ros2 decoded message (dynamic object with __slots__) as plain data."""
    slots = getattr(type(value), '__slots__', None)
    if slots:
        return {name: from_mcap(getattr(value, name)) for name in slots if is_field(name)}
    if isinstance(value, (list, tuple)):
        return [from_mcap(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value


def make_messages(typestore, step: int):
    """Return (gait_state, effort_command, joint_dynamics) of one simulated step."""
    t = typestore.types
    Time = t['builtin_interfaces/msg/Time']
    Header = t['std_msgs/msg/Header']
    Point = t['geometry_msgs/msg/Point']
    stamp = Time(sec=step // 1000, nanosec=(step % 1000) * 1_000_000)
    header = Header(stamp=stamp, frame_id='world')
    n = len(COORDINATES)
    effort = t[EFFORT_COMMAND](
        header=header, source='visual_lifting', run_token='', joint_names=COORDINATES,
        effort=np.linspace(-3.0, 3.0, n) + step, stiffness=np.full(n, 800.0),
        damping=np.full(n, 16.0), position_reference=np.linspace(-0.1, 0.1, n),
        source_names=['posture', 'yaw'], source_efforts=np.linspace(-1.0, 1.0, 2 * n),
        head_target=np.array([0.1 * step, 1.6, -0.01]))
    gait_state = t[GAIT_STATE](
        header=header, mode=1 + step % 20, support_side=step % 2, pivot=step % 3,
        step_index=step, y0_active=step % 2 == 0, q1_active=step % 3 != 0,
        multiplier_names=['f_nz', 'tau_n'], multipliers=np.array([400.0 + step, -2.5]),
        support_normal_force=300.0 - step, support_friction_force=-0.05 * step,
        zmp=Point(x=0.0, y=0.1 * step, z=0.0), zmp_inside_support=step % 4 != 0,
        swing_clearance=0.002 * step,
        last_transition_cause=f'step_{step}', last_transition_stamp=stamp,
        support_exchange_stamp=stamp, touched_down=step % 2 == 1, touchdown_stamp=stamp,
        heel_anchor_y=0.01 * step, position=np.linspace(-0.5, 0.5, n) * step,
        velocity=np.linspace(1.0, -1.0, n) + step)
    dynamics = t[JOINT_DYNAMICS](
        header=header, name=COORDINATES,
        active=np.array([step % 2 == 0] + [True] * 17, dtype=bool),
        acceleration=np.arange(len(COORDINATES), dtype=np.float64) * 0.25 - step,
        source_names=['visual_lifting', 'passive'],
        source_efforts=np.linspace(-2.0, 2.0, 2 * n) * step)
    return gait_state, effort, dynamics


@pytest.fixture
def bag(tmp_path):
    """Write an MCAP bag of 5 steps; return (path, {topic: [plain messages in order]})."""
    typestore = make_typestore()
    path = tmp_path / 'bag'
    expected = {'/gait_state': [], '/effort_command': [], '/joint_dynamics': []}
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {
            '/gait_state': writer.add_connection('/gait_state', GAIT_STATE, typestore=typestore),
            '/effort_command': writer.add_connection(
                '/effort_command', EFFORT_COMMAND, typestore=typestore),
            '/joint_dynamics': writer.add_connection(
                '/joint_dynamics', JOINT_DYNAMICS, typestore=typestore),
        }
        for step in range(5):
            timestamp = 1_000_000_000 + step * 1_000_000
            for topic, message in zip(expected, make_messages(typestore, step), strict=True):
                data = typestore.serialize_cdr(message, message.__msgtype__)
                writer.write(connections[topic], timestamp, data)
                expected[topic].append(to_plain(message))
    return path, expected


def test_make_typestore_registers_all_interface_messages():
    typestore = make_typestore()
    for name in (GAIT_STATE, EFFORT_COMMAND, JOINT_DYNAMICS):
        assert name in typestore.types
    assert typestore.types[GAIT_STATE].PIVOT_HEEL == 2


def test_the_msg_dir_is_the_installed_packages(tmp_path, monkeypatch):
    """The first prefix of AMENT_PREFIX_PATH whose ament index holds iceskate_interfaces; none:
    one sentence saying the workspace is not built."""
    prefix = tmp_path / 'prefix'
    share = prefix / 'share' / 'iceskate_interfaces' / 'msg'
    share.mkdir(parents=True)
    for source in SOURCE_MSG_DIR.glob('*.msg'):
        (share / source.name).write_text(source.read_text())
    index = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / 'iceskate_interfaces').touch()
    monkeypatch.setenv('AMENT_PREFIX_PATH', f'{tmp_path / "empty"}:{prefix}')
    assert share_path('iceskate_interfaces', 'msg') == share
    assert make_typestore().types['iceskate_interfaces/msg/GaitState'].PIVOT_HEEL == 2
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path / 'empty'))
    with pytest.raises(SimulationError, match='package iceskate_interfaces is not installed'):
        make_typestore()


def test_msg_types_raises_on_directory_without_msg_files(tmp_path):
    with pytest.raises(FileNotFoundError, match='no .msg files'):
        msg_types(tmp_path)


def test_rosbags_reads_back_equal_messages(bag):
    path, expected = bag
    typestore = make_typestore()
    got = {topic: [] for topic in expected}
    with Reader(path) as reader:
        assert reader.message_count == 15
        assert {c.msgtype for c in reader.connections} == {
            GAIT_STATE, EFFORT_COMMAND, JOINT_DYNAMICS}
        for connection, _, data in reader.messages():
            message = typestore.deserialize_cdr(data, connection.msgtype)
            got[connection.topic].append(to_plain(message))
    assert got == expected


def test_mcap_ros2_decodes_bag_with_embedded_definitions(bag):
    """An independent reader decodes our types from the schemas stored in the MCAP file."""
    mcap_reader = pytest.importorskip('mcap.reader')
    mcap_decoder = pytest.importorskip('mcap_ros2.decoder')
    path, expected = bag
    (mcap_file,) = path.glob('*.mcap')
    got = {topic: [] for topic in expected}
    schemas = {}
    with mcap_file.open('rb') as stream:
        reader = mcap_reader.make_reader(
            stream, decoder_factories=[mcap_decoder.DecoderFactory()])
        for schema, channel, _, decoded in reader.iter_decoded_messages():
            schemas[channel.topic] = schema
            got[channel.topic].append(from_mcap(decoded))
    assert {topic: s.name for topic, s in schemas.items()} == {
        '/gait_state': GAIT_STATE, '/effort_command': EFFORT_COMMAND,
        '/joint_dynamics': JOINT_DYNAMICS}
    assert b'float64[] source_efforts' in schemas['/joint_dynamics'].data
    assert b'MSG: geometry_msgs/Point' in schemas['/gait_state'].data  # nested definitions
    assert got == expected
