"""The controller nodes' adapter: GaitState CDR bytes in, the law's command out (in process)."""

import numpy as np
import pytest

pytest.importorskip('rclpy')
pytestmark = [pytest.mark.ros]

from rclpy.parameter import Parameter  # noqa: E402

from gait_manager.gait_manager_node import GaitManagerNode  # noqa: E402
from gait_manager.law import GaitManagerParameters, gait_manager_commands  # noqa: E402
from iceskate_sim.command import ControllerCommand, JointCommand  # noqa: E402
from iceskate_sim.dynamics import GaitDynamics  # noqa: E402
from iceskate_sim.lockstep import LockstepSession  # noqa: E402
from iceskate_sim.robot import load_robot  # noqa: E402
from iceskate_sim.ros_conversions import command_from_message, stamp_to_ns  # noqa: E402
from iceskate_sim.scene import load_scene  # noqa: E402


@pytest.fixture
def gait_manager(ros_context):
    node = GaitManagerNode(context=ros_context, parameter_overrides=[
        Parameter('scene', Parameter.Type.STRING, 'skate')])
    sent = []
    node._publisher.publish = lambda msg: sent.append(
        (stamp_to_ns(msg.header.stamp), command_from_message(msg)))
    try:
        yield node, sent
    finally:
        node.destroy_node()


def _state_bytes(session: LockstepSession) -> bytes:
    return session.state_bytes(('/gait_state',))['/gait_state']


def test_the_answer_to_gait_state_bytes_is_the_laws_command_at_that_state(gait_manager):
    node, sent = gait_manager
    scene = load_scene('skate')
    session = LockstepSession(scene)
    params = GaitManagerParameters.from_dict(scene.gait_manager)
    dynamics = GaitDynamics(load_robot())
    for _ in range(3):  # t = 0 and two later states (the held command moves the robot)
        obs = session.sim.observation()
        node.on_gait_state(_state_bytes(session))
        expected = ControllerCommand.of(gait_manager_commands(obs, dynamics, params),
                                        obs.q, obs.v)
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
    data = _state_bytes(LockstepSession(load_scene('skate')))
    node.on_gait_state(data[:len(data) // 3])
    assert sent == []
    node.on_gait_state(data)
    assert [ns for ns, _ in sent] == [0]
