"""Replay of a recorded bag, and the shipped node YAMLs loaded into the real nodes."""

from pathlib import Path
import subprocess

import pytest

rclpy = pytest.importorskip('rclpy')
pytestmark = [pytest.mark.ros, pytest.mark.slow]

from geometry_msgs.msg import PoseStamped  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from iceskate_bringup.graph import NodeSpec, command_of, config_file  # noqa: E402
from iceskate_interfaces.msg import GaitState, JointDynamics  # noqa: E402
from iceskate_sim.recording.bag_types import make_typestore  # noqa: E402

TINY = Path(__file__).resolve().parent / 'data' / 'tiny_stand.yaml'
TYPES = {'/clock': Clock, '/joint_states': JointState, '/head_pose': PoseStamped,
         '/gait_state': GaitState, '/joint_dynamics': JointDynamics}


def test_replay_republishes_the_bags_messages_with_clock(graph_run, listener, ros_env):
    bag = graph_run.out / 'bag'
    recorded: dict[str, list[bytes]] = {}
    msgtypes = {}
    with AnyReader([bag]) as reader:
        for conn, _, raw in reader.messages():
            recorded.setdefault(conn.topic, []).append(bytes(raw))
            msgtypes[conn.topic] = conn.msgtype
    assert '/tf' in recorded
    del recorded['/tf']  # no tf2_msgs Python package here: replay leaves /tf out (and says so)
    store = make_typestore()

    def canonical(topic: str, raw: bytes) -> bytes:
        # the transport may pad a payload to 4 bytes: compare rosbags' own serialization
        msgtype = msgtypes[topic]
        return bytes(store.serialize_cdr(store.deserialize_cdr(raw, msgtype), msgtype))
    for topic, kind in TYPES.items():
        listener.subscribe(topic, kind, raw=True)
    listener.subscribe('/robot_description', String, depth=1, raw=True, latched=True)
    spec = NodeSpec('iceskate_analysis', 'replay', 'iceskate_analysis.replay', '', bag)
    replay = subprocess.Popen(command_of(spec) + [str(bag), '--fast',
                                                  '--wait-for-subscribers', '30'],
                              env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        listener.spin_until(lambda: replay.poll() is not None and all(
            len(listener.messages[t]) >= len(recorded[t]) for t in recorded), 60.0,
            'every recorded message')
    finally:
        if replay.poll() is None:
            replay.kill()
        output = replay.communicate(timeout=10)[0].decode(errors='replace')
    assert replay.returncode == 0, output
    assert '/tf (tf2_msgs/msg/TFMessage) is not replayed' in output
    assert set(recorded) == set(TYPES) | {'/robot_description'}
    for topic, payloads in recorded.items():
        received = [canonical(topic, bytes(m)) for m in listener.messages[topic]]
        assert received == [canonical(topic, raw) for raw in payloads], topic


@pytest.mark.parametrize('package, node, module, cls, name, value', [
    ('iceskate_sim', 'simulator', 'iceskate_sim.ros.simulator_node', 'SimulatorNode', 'scene',
     str(TINY)),
    ('visual_lifting', 'visual_lifting', 'visual_lifting.visual_lifting_node',
     'VisualLiftingNode', 'v_d', 0.5),
    ('gait_manager', 'gait_manager', 'gait_manager.gait_manager_node', 'GaitManagerNode',
     'yaw.amplitude', 12.0),
])
def test_shipped_yaml_loads_into_the_node(ros_context, package, node, module, cls, name, value):
    import importlib
    path = config_file(package, node)
    assert path.is_file()
    node_class = getattr(importlib.import_module(module), cls)
    instance = node_class(context=ros_context, cli_args=[
        '--ros-args', '--params-file', str(path), '-p', f'{name}:={value}'])
    try:
        assert instance.get_name() == node
        assert instance.get_parameter(name).value == value  # -p wins over the file
        if node == 'simulator':
            assert instance.config.lockstep and instance.config.control_timeout == 5.0
        else:
            assert instance.get_parameter('use_sim_time').value is True
    finally:
        instance.destroy_node()
