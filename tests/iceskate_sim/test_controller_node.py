"""The controller nodes' adapter: GaitState CDR bytes in, the law's command out (in process)."""

import numpy as np
import pytest

pytest.importorskip('rclpy')
pytestmark = [pytest.mark.ros]


from gait_manager.gait_manager_node import GaitManagerNode  # noqa: E402
from gait_manager.native import GaitManagerController  # noqa: E402
from iceskate_bringup.scene import load_scene, node_parameters, scene_sources  # noqa: E402
from iceskate_sim.model.command import ControllerCommand, JointCommand  # noqa: E402
from iceskate_sim.model.robot import load_robot  # noqa: E402
from iceskate_sim.parameters import flatten  # noqa: E402
from iceskate_sim.physics.native_control import native_command, native_kinematics  # noqa: E402
from iceskate_sim.ros.effort_cdr import CommandDecoder  # noqa: E402
from iceskate_sim.ros.lockstep import LockstepSession  # noqa: E402
from iceskate_sim.ros.node_support import write_parameter_file  # noqa: E402
from iceskate_sim.run.session import Session  # noqa: E402


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
    node._publisher.publish = lambda data: sent.append(decoder.decode(data)[1:])
    try:
        yield node, sent
    finally:
        node.destroy_node()


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
        for field in ('effort', 'stiffness', 'damping', 'reference'):
            assert np.array_equal(getattr(got.command, field), getattr(expected.command, field))
        assert list(got.source_efforts) == list(expected.source_efforts)
        for source, effort in expected.source_efforts.items():
            assert np.array_equal(got.source_efforts[source], effort), source
        session.offer('gait_manager', ns, got)
        session.offer('visual_lifting', ns, ControllerCommand(JointCommand(np.zeros(18)), {}))
        session.step()
    assert len(sent) == 3


def test_undecodable_gait_state_bytes_get_no_answer_and_the_next_state_does(gait_manager):
    node, sent = gait_manager
    data = _state_bytes(skate_session())
    node.on_gait_state(data[:len(data) // 3])
    assert sent == []
    node.on_gait_state(data)
    assert [ns for ns, _ in sent] == [0]
