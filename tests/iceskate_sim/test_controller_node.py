"""The controller nodes' adapter: GaitState CDR bytes in, the law's command out (in process).

The bytes are what the simulator sends: ``SampleMessages.encode`` of the native loop's samples
(the live one of a lockstep session, or a block of a headless run); the expected command is the
law's at the observation of rosbags' reading of the same bytes."""

import numpy as np
import pytest

pytest.importorskip('rclpy')
pytestmark = [pytest.mark.ros]


from gait_manager.gait_manager_node import GaitManagerNode  # noqa: E402
from gait_manager.native import GaitManagerController  # noqa: E402
from iceskate_bringup.scene import load_scene, node_parameters, scene_sources  # noqa: E402
from iceskate_native.parameters import flatten  # noqa: E402

# noqa: E402
from iceskate_sim.model.robot import load_robot  # noqa: E402
from iceskate_sim.physics.native_control import native_kinematics  # noqa: E402
from iceskate_sim.recording.bag_types import make_typestore  # noqa: E402
from iceskate_sim.recording.messages import Events, SampleMessages  # noqa: E402
from iceskate_sim.ros.effort_cdr import CommandDecoder  # noqa: E402
from iceskate_sim.ros.lockstep import LockstepSession  # noqa: E402
from iceskate_sim.ros.node_support import write_parameter_file  # noqa: E402
from iceskate_sim.run.session import Session  # noqa: E402
from oracle.commands import ControllerCommand, JointCommand, command_of, native_command, values_of  # noqa: E402
from oracle.messages import observation_from_gait_state  # noqa: E402

GAIT_STATE = 'iceskate_interfaces/msg/GaitState'


def skate_session() -> LockstepSession:
    scene = load_scene('skate')
    return LockstepSession(Session(scene), scene_sources(scene))


@pytest.fixture
def gait_manager(ros_context, tmp_path):
    params = tmp_path / 'gait_manager.yaml'  # the skate scene's block, as a launch writes it
    write_parameter_file(params, {'gait_manager': flatten(
        node_parameters(load_scene('skate'))['gait_manager'])})
    node = GaitManagerNode(context=ros_context, cli_args=['--ros-args', '--params-file',
                                                          str(params)])
    sent = []
    decoder = CommandDecoder()
    node._publisher.publish = lambda data: sent.append(_decoded(decoder, data))
    try:
        yield node, sent
    finally:
        node.destroy_node()


def _decoded(decoder: CommandDecoder, data: bytes) -> tuple[int, ControllerCommand]:
    """The stamp [ns] and command of a sent message."""
    _, stamp_ns, values = decoder.decode(data)
    return stamp_ns, command_of(values)


def assert_command(got, expected) -> None:
    for field in ('effort', 'stiffness', 'damping', 'reference'):
        assert np.array_equal(getattr(got.command, field), getattr(expected.command, field))
    assert list(got.source_efforts) == list(expected.source_efforts)
    for source, effort in expected.source_efforts.items():
        assert np.array_equal(got.source_efforts[source], effort), source


def _state_bytes(session: LockstepSession) -> bytes:
    return session.state_bytes(('/gait_state',))['/gait_state']


def test_the_answer_to_gait_state_bytes_is_the_laws_command_at_that_state(gait_manager):
    node, sent = gait_manager
    session = skate_session()
    params = node_parameters(session.scene)['gait_manager']
    assert node.params == params
    kinematics = native_kinematics(load_robot())
    law = GaitManagerController(params)
    for _ in range(3):  # t = 0 and two later states (the held command moves the robot)
        obs = session.sim.observation()
        node.on_gait_state(_state_bytes(session))
        expected = native_command(law, obs, kinematics)
        ns, got = sent[-1]
        assert ns == session.t_ns
        assert_command(got, expected)
        session.offer('gait_manager', ns, values_of(got))
        session.offer('visual_lifting', ns,
                      values_of(ControllerCommand(JointCommand(np.zeros(18)), {})))
        session.step()
    assert len(sent) == 3


def test_the_answers_to_the_states_of_a_run_are_the_laws_commands(gait_manager,
                                                                  native_loop_run):
    """States of several modes, sides and message layouts (a headless run's block of samples),
    some padded as Fast DDS may pad them: each answer is the law's command at rosbags' reading
    of the same bytes, stamped with the state's stamp."""
    node, sent = gait_manager
    scene = load_scene('skate')
    block, _, sim = native_loop_run(scene, 1500)
    typestore = make_typestore()
    messages = SampleMessages(typestore, load_robot().tf_frames)
    encoded = messages.encode(block, Events.of(block['last_event'], sim.events),
                              ('/gait_state',))['/gait_state']
    law = GaitManagerController(node_parameters(scene)['gait_manager'])
    kinematics = native_kinematics(load_robot())
    seen = set()
    for k in range(0, len(encoded), 50):
        data = encoded[k] + b'\xab' * (k % 4)
        msg = typestore.deserialize_cdr(encoded[k], GAIT_STATE)
        node.on_gait_state(data)
        ns, got = sent[-1]
        assert ns == msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        assert_command(got, native_command(law, observation_from_gait_state(msg), kinematics))
        seen.add((msg.mode, msg.support_side))
    assert len(sent) == len(range(0, len(encoded), 50))
    assert len({mode for mode, _ in seen}) >= 3 and {side for _, side in seen} == {0, 1}


def test_undecodable_gait_state_bytes_get_no_answer_and_the_next_state_does(gait_manager):
    node, sent = gait_manager
    data = _state_bytes(skate_session())
    node.on_gait_state(data[:len(data) // 3])
    assert sent == []
    node.on_gait_state(data)
    assert [ns for ns, _ in sent] == [0]


def test_a_legal_step_index_beyond_a_run_gets_no_answer_and_no_crash(gait_manager):
    """A GaitState's step_index is a uint32: 2^32 - 1 is a legal message that no run sends; the
    node answers it with nothing (one error line), not a TypeError, and goes on."""
    node, sent = gait_manager
    data = _state_bytes(skate_session())
    typestore = make_typestore()
    msg = typestore.deserialize_cdr(data, 'iceskate_interfaces/msg/GaitState')
    msg.step_index = 2**32 - 1
    node.on_gait_state(bytes(typestore.serialize_cdr(msg, 'iceskate_interfaces/msg/GaitState')))
    assert sent == []
    node.on_gait_state(data)
    assert [ns for ns, _ in sent] == [0]


def test_commands_carry_the_run_token_and_two_simulators_are_said_once(ros_context, tmp_path):
    """A controller given its run's token sends it with every command; one that sees two
    gait_state writers on its domain (two graphs) says so once."""
    import time

    from rclpy.node import Node

    from iceskate_interfaces.msg import GaitState
    from iceskate_sim.ros.node_support import STATE_QOS
    params = tmp_path / 'gait_manager.yaml'
    write_parameter_file(params, {'gait_manager': flatten(
        node_parameters(load_scene('skate'))['gait_manager']) | {'run_token': 'tok'}})
    node = GaitManagerNode(context=ros_context, cli_args=['--ros-args', '--params-file',
                                                          str(params)])
    simulators = Node('two_simulators', context=ros_context)
    warnings = []
    logger = node.get_logger()
    node.get_logger = lambda: type('Log', (), {'warning': lambda self, t: warnings.append(t),
                                               'info': lambda self, t: logger.info(t)})()
    sent = []
    node._publisher.publish = sent.append
    try:
        node.on_gait_state(_state_bytes(skate_session()))
        assert CommandDecoder('tok').decode(sent[0])[0] == 'gait_manager'
        node._check_simulator()
        assert warnings == []
        for _ in range(2):
            simulators.create_publisher(GaitState, 'gait_state', STATE_QOS)
        deadline = time.monotonic() + 10.0
        while node._states.get_publisher_count() < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        for _ in range(2):
            node._check_simulator()
        assert len(warnings) == 1 and warnings[0].startswith(
            '2 nodes publish gait_state on this ROS domain: this controller answers the states '
            'of more than one simulator'), warnings
    finally:
        simulators.destroy_node()
        node.destroy_node()
