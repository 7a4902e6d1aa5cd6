"""LockstepSession (ROS-free): the simulator side of the graph gives the headless run.

Commands go through EffortCommand/JointState/GaitState CDR bytes and back, as over ROS.
"""

from dataclasses import replace
import json
from pathlib import Path

import numpy as np
import pytest

from iceskate_sim.command import JointCommand
from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.errors import SimulationError
from iceskate_sim.lockstep import LockstepSession, ordered_sources
from iceskate_sim.ros_conversions import observation_from_messages, seconds_to_ns
from iceskate_sim.runner import run
from iceskate_sim.scene import load_scene

TINY = Path(__file__).resolve().parents[1] / 'integration' / 'data' / 'tiny_stand.yaml'


@pytest.fixture(scope='module')
def scene():
    return replace(load_scene(TINY), duration=0.01)


def controllers(scene, robot):
    """The controller side of the graph, from messages (what the two nodes compute)."""
    from gait_manager.law import GaitManagerParameters, gait_manager_commands, head_offset
    from visual_lifting.law import VisualLiftingParameters, visual_lifting
    dynamics = GaitDynamics(robot)
    vl = VisualLiftingParameters.from_dict(scene.visual_lifting)
    gm = GaitManagerParameters.from_dict(scene.gait_manager)
    psi0 = []

    def answer(obs):
        if not psi0:
            psi0.append(dynamics.head_pose(obs.contact(), obs.q)[0])
        task = visual_lifting(obs, dynamics, vl, psi0[0], head_offset(obs, dynamics, gm))
        return {'visual_lifting': JointCommand(task.tau), **gait_manager_commands(obs, dynamics,
                                                                                 gm)}
    return answer


def drive(session, answer):
    ts = session.factory.typestore
    while not session.done:
        msgs = session.state_messages()
        js, gs = (ts.deserialize_cdr(session.serialize(t, msgs[t]), kind) for t, kind in (
            ('/joint_states', 'sensor_msgs/msg/JointState'),
            ('/gait_state', 'iceskate_interfaces/msg/GaitState')))
        obs = observation_from_messages(js, gs)
        for source, command in answer(obs).items():
            assert session.offer(source, seconds_to_ns(obs.t), command)
        assert session.missing() == []
        session.step()
        session.flush()
    return session.finish()


def test_lockstep_session_reproduces_the_headless_run(scene, tmp_path):
    run(scene, tmp_path / 'headless', progress=False)
    session = LockstepSession(scene, tmp_path / 'ros', tmp_path / 'ros' / 'bag')
    metrics = drive(session, controllers(scene, session.robot))
    a = np.load(tmp_path / 'ros' / 'trajectory.npz')
    b = np.load(tmp_path / 'headless' / 'trajectory.npz')
    assert sorted(a.files) == sorted(b.files)
    for key in a.files:
        scale = max(1.0, float(np.max(np.abs(b[key])))) if b[key].size else 1.0
        assert np.max(np.abs(a[key] - b[key]), initial=0.0) <= 1e-12 * scale, key
    headless = json.loads((tmp_path / 'headless' / 'metrics.json').read_text())
    assert metrics['sources'] == headless['sources'] == list(ordered_sources(scene))
    assert metrics['sim_time_s'] == headless['sim_time_s']
    assert (tmp_path / 'ros' / 'bag' / 'metadata.yaml').is_file()


def test_offer_refuses_unknown_sources_and_stale_or_future_stamps(scene):
    session = LockstepSession(scene)
    zero = JointCommand(np.zeros(18))
    with pytest.raises(SimulationError, match="unknown source 'yaw'"):
        session.offer('yaw', 0, zero)
    with pytest.raises(SimulationError, match='in the future'):
        session.offer('posture', 1_000_000, zero)
    for source in session.sources:
        assert session.offer(source, 0, zero)
    assert not session.offer('posture', 0, JointCommand(np.ones(18)))  # repeat: ignored
    session.step()
    assert session.missing() == list(session.sources)
    assert not session.offer('posture', 0, zero)  # a late repeat of t_0: ignored too
    with pytest.raises(SimulationError, match='without commands'):
        session.step()
    for source in session.sources:
        session.offer(source, 1_000_000, zero)
    session.step()
    with pytest.raises(SimulationError, match="stale command of 'posture' stamped 0.0 s"):
        session.offer('posture', 0, zero)


def test_reset_is_refused_while_recording_and_restarts_otherwise(scene, tmp_path):
    recording = LockstepSession(scene, bag=tmp_path / 'bag')
    with pytest.raises(SimulationError, match='refused while'):
        recording.reset()
    recording.finish()
    session = LockstepSession(scene)
    for source in session.sources:
        session.offer(source, 0, JointCommand(np.zeros(18)))
    session.step()
    session.reset()
    assert session.t_ns == 0 and session.periods == 0 and len(session.trajectory) == 0


def test_free_running_holds_the_latest_command(scene):
    session = LockstepSession(scene, lockstep=False)
    assert session.missing() == list(session.sources)
    session.step()  # no command yet: nothing applied
    session.offer('posture', 0, JointCommand(np.zeros(18)))  # late but not older: taken
    session.step()
    with pytest.raises(SimulationError, match='stale'):  # older than the source's last
        session.offer('posture', -1, JointCommand(np.zeros(18)))
    assert session.periods == 2
