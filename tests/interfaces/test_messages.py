"""iceskate_interfaces as built by colcon: CDR round trips, .msg consistency, and two processes.

Needs the built workspace on the path (``. ./env.sh``); skipped when rclpy is missing.
"""

import json
import math
from pathlib import Path
import subprocess
import sys
import textwrap
import time

import pytest

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip('rclpy')
serialization = pytest.importorskip('rclpy.serialization')
interfaces_msg = pytest.importorskip('iceskate_interfaces.msg')
interfaces_srv = pytest.importorskip('iceskate_interfaces.srv')

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Point  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

EffortCommand = interfaces_msg.EffortCommand
GaitState = interfaces_msg.GaitState
JointDynamics = interfaces_msg.JointDynamics
StepSimulation = interfaces_srv.StepSimulation

MSG_DIR = Path(__file__).resolve().parents[2] / 'ros_ws' / 'src' / 'interfaces' / 'msg'
COORDINATES = ['y0'] + [f'q{i}' for i in range(1, 18)]

#: Upper bound of every wait in the two-process test (discovery + start of a Python process).
DEADLINE_S = 60.0


def make_gait_state() -> GaitState:
    """Return a GaitState with every field set to a non-default value."""
    return GaitState(
        header=Header(stamp=Time(sec=12, nanosec=345_000_000), frame_id='world'),
        mode=18,
        support_side=GaitState.SUPPORT_LEFT,
        pivot=GaitState.PIVOT_TOE,
        step_index=7,
        y0_active=False,
        q1_active=True,
        multiplier_names=['f_nz', 'f_ny', 'tau_n'],
        multipliers=[412.5, -37.25, 3.125],
        support_normal_force=250.75,
        support_friction_force=-5.5,
        zmp=Point(x=0.01, y=0.42, z=0.0),
        zmp_inside_support=True,
        last_transition_cause='cop_reached_toe',
        last_transition_stamp=Time(sec=12, nanosec=1_000_000),
        position=[0.01 * i for i in range(len(COORDINATES))],
        velocity=[-0.5 + 0.125 * i for i in range(len(COORDINATES))],
    )


def make_effort_command(source: str = 'visual_lifting') -> EffortCommand:
    """Return an EffortCommand over all 18 coordinates with distinct efforts."""
    return EffortCommand(
        header=Header(stamp=Time(sec=3, nanosec=250_000_000), frame_id=''),
        source=source,
        joint_names=COORDINATES,
        effort=[0.5 * i - 4.0 for i in range(len(COORDINATES))],
    )


def make_joint_dynamics() -> JointDynamics:
    """Return a JointDynamics with two effort sources."""
    return JointDynamics(
        header=Header(stamp=Time(sec=3, nanosec=251_000_000), frame_id='world'),
        name=COORDINATES,
        active=[False, True] + [True] * 16,
        acceleration=[0.0, -1.5] + [math.sin(i) for i in range(16)],
        source_names=['visual_lifting', 'passive'],
        source_efforts=[0.25 * i - 3.0 for i in range(2 * len(COORDINATES))],
    )


@pytest.mark.parametrize('make', [make_gait_state, make_effort_command, make_joint_dynamics])
def test_message_survives_cdr_round_trip(make):
    message = make()
    data = serialization.serialize_message(message)
    assert isinstance(data, bytes) and len(data) > 0
    assert serialization.deserialize_message(data, type(message)) == message


def test_step_simulation_request_and_response_survive_cdr_round_trip():
    request = StepSimulation.Request(control_periods=250)
    response = StepSimulation.Response(
        success=False, message='not paused', sim_time=Time(sec=9, nanosec=5))
    for message in (request, response):
        data = serialization.serialize_message(message)
        assert serialization.deserialize_message(data, type(message)) == message


def test_gait_state_constants_have_documented_values():
    assert (GaitState.SUPPORT_RIGHT, GaitState.SUPPORT_LEFT) == (0, 1)
    assert (GaitState.PIVOT_NONE, GaitState.PIVOT_TOE, GaitState.PIVOT_HEEL) == (0, 1, 2)


@pytest.mark.parametrize('message_type', [GaitState, EffortCommand, JointDynamics])
def test_built_fields_match_msg_file_parsed_by_rosbags(message_type):
    """The generated Python type and the .msg text that bags embed agree field by field."""
    typesys = pytest.importorskip('rosbags.typesys')
    name = message_type.__name__
    text = (MSG_DIR / f'{name}.msg').read_text()
    parsed = typesys.get_types_from_msg(text, f'iceskate_interfaces/msg/{name}')
    constants, fields = parsed[f'iceskate_interfaces/msg/{name}'][:2]
    assert [field for field, _ in fields] == list(message_type.get_fields_and_field_types())
    for constant, _, value in constants:
        assert getattr(message_type, constant) == value


# Subscriber process: prints one JSON line with what it received, exits 0; exits 2 on timeout.
SUBSCRIBER = textwrap.dedent("""
    import json, sys, time
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from iceskate_interfaces.msg import EffortCommand, GaitState

    deadline = time.monotonic() + float(sys.argv[1])
    rclpy.init()
    node = rclpy.create_node('iceskate_test_subscriber')
    received = {}
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)

    def on_gait_state(msg):
        received.setdefault('gait_state', {
            'stamp': [msg.header.stamp.sec, msg.header.stamp.nanosec],
            'mode': msg.mode, 'pivot': msg.pivot, 'support_side': msg.support_side,
            'multiplier_names': list(msg.multiplier_names),
            'multipliers': list(msg.multipliers),
            'zmp': [msg.zmp.x, msg.zmp.y, msg.zmp.z],
            'cause': msg.last_transition_cause})

    def on_effort(msg):
        received.setdefault('effort_command', {
            'stamp': [msg.header.stamp.sec, msg.header.stamp.nanosec],
            'source': msg.source, 'joint_names': list(msg.joint_names),
            'effort': list(msg.effort)})

    node.create_subscription(GaitState, 'gait_state', on_gait_state, qos)
    node.create_subscription(EffortCommand, 'effort_command', on_effort, qos)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    while len(received) < 2 and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    node.destroy_node()
    rclpy.try_shutdown()
    print(json.dumps(received), flush=True)
    sys.exit(0 if len(received) == 2 else 2)
""")


@pytest.mark.slow
def test_gait_state_and_effort_command_cross_processes(ros_context, ros_env):
    """A publisher here and a subscriber in a child process exchange both message types."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    child = subprocess.Popen(
        [sys.executable, '-c', SUBSCRIBER, str(DEADLINE_S)], env=ros_env,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    node = rclpy.create_node('iceskate_test_publisher', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    try:
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        gait_pub = node.create_publisher(GaitState, 'gait_state', qos)
        effort_pub = node.create_publisher(EffortCommand, 'effort_command', qos)
        gait_state, effort_command = make_gait_state(), make_effort_command()

        def publish_when_matched():
            # Publish repeatedly (10 Hz) once the child's subscriptions are matched, until it
            # has received both and exited.
            if gait_pub.get_subscription_count() and effort_pub.get_subscription_count():
                gait_pub.publish(gait_state)
                effort_pub.publish(effort_command)

        node.create_timer(0.1, publish_when_matched)
        executor.add_node(node)
        deadline = time.monotonic() + DEADLINE_S
        while child.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert child.poll() is not None, f'subscriber process still running after {DEADLINE_S} s'
        stdout, stderr = child.communicate(timeout=10)
        assert child.returncode == 0, (
            f'subscriber failed ({child.returncode}):\n{stdout}\n{stderr}')
    finally:
        if child.poll() is None:
            child.kill()
            child.communicate(timeout=10)
        executor.shutdown()
        node.destroy_node()

    received = json.loads(stdout.strip().splitlines()[-1])
    assert received['gait_state'] == {
        'stamp': [12, 345_000_000], 'mode': 18, 'pivot': GaitState.PIVOT_TOE,
        'support_side': GaitState.SUPPORT_LEFT, 'multiplier_names': ['f_nz', 'f_ny', 'tau_n'],
        'multipliers': [412.5, -37.25, 3.125], 'zmp': [0.01, 0.42, 0.0],
        'cause': 'cop_reached_toe'}
    assert received['effort_command'] == {
        'stamp': [3, 250_000_000], 'source': 'visual_lifting', 'joint_names': COORDINATES,
        'effort': list(effort_command.effort)}
