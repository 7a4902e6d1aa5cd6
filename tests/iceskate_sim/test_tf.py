"""/tf in the bags: at every sample the world pose of every URDF link, read back with the
``mcap`` reader (not rosbags) and checked against forward kinematics of the URDF on a free-flyer
base placed by the support foot, not by the simulator's support-rooted models."""

import pathlib
import xml.etree.ElementTree as ET

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pinocchio as pin
import pytest
from rosbags.highlevel import AnyReader

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import HeldCommand, JointCommand
from iceskate_sim.model.dynamics import ContactState
from iceskate_sim.model.modes import MODES
from iceskate_sim.model.robot import (
    N_COORDINATES,
    PIVOT_Y,
    PIVOTS,
    Q1,
    SIDES,
    Y0,
    anatomical_map,
    load_robot,
)
from iceskate_sim.physics.hybrid import FrictionModel, HybridState
from iceskate_sim.physics.integrators import IntegratorConfig
from iceskate_sim.physics.simulation import Simulator, SimulatorConfig, initial_state
from iceskate_sim.recording.bag import BagRecorder, LinkTransforms, Sample
from iceskate_sim.recording.bag_types import make_typestore

PERIODS = 300  # 0.3 s at 1 ms
TOLERANCE = 1e-9  # m, and on rotation-matrix entries


def _urdf_tree(urdf: str) -> tuple[set[str], set[tuple[str, str]]]:
    """The URDF's link names and the (parent, child) link pairs /tf must hold: one per joint
    and ('world', root link), read from the XML."""
    robot = ET.fromstring(urdf)
    links = {link.get('name') for link in robot.iter('link')}
    pairs = {(j.find('parent').get('link'), j.find('child').get('link'))
             for j in robot.iter('joint')}
    (root,) = links - {child for _, child in pairs}
    return links, pairs | {('world', root)}


def _record(path: pathlib.Path, samples: list[Sample], background: bool) -> None:
    urdf = load_robot().urdf_path.read_text(encoding='utf-8')
    with BagRecorder(path, {'scene': 'tf-test'}, urdf, background=background) as recorder:
        for sample in samples:
            recorder.write(sample)


@pytest.fixture
def run_samples(robot, random_state) -> list[Sample]:
    """0.3 s of double support on a Coulomb floor from the bent-knee stance: the legs and trunk
    held by a joint impedance, the torso yawing and the arms swinging; sampled as the headless
    runner does."""
    stance, _ = random_state(17, scale=0.0)
    config = SimulatorConfig(integrator=IntegratorConfig('implicit_euler', step=1e-3),
                             friction=FrictionModel(0.8, 'coulomb'))
    sim = Simulator(robot, config, initial_state(stance, 17))
    stiffness = np.full(N_COORDINATES, 800.0)
    stiffness[[Y0, Q1]] = 0.0
    stiffness[11:17] = 20.0
    samples = []
    for _ in range(PERIODS):
        reference = stance.copy()
        reference[[8, 11, 14]] = np.array([0.2, 0.5, -0.5]) * np.sin(8 * np.pi * sim.time)
        command = JointCommand(np.zeros(N_COORDINATES), stiffness, 0.1 * stiffness, reference)
        head = sim.head_placement()
        sim.advance(HeldCommand.combine([command]))
        start = sim.start_state
        samples.append(Sample(start, sim.start_result, {'posture': command.torque(start.q,
                                                                                   start.v)},
                              head.translation.copy(), head.rotation.copy(),
                              sim.events[-1] if sim.events else None))
    assert sim.ended is None
    return samples


@pytest.fixture
def random_samples(dynamics, random_state) -> list[Sample]:
    """One random state of every mode on every support side and pivot (q1 tipped where the
    mode frees it), 1 ms apart."""
    samples = []
    for mode in MODES.values():
        for side in SIDES:
            for pivot in PIVOTS:
                q, v = random_state(mode)
                contact = ContactState(mode, side, pivot)
                state = HybridState(len(samples) * 1e-3, q, v, contact)
                head = dynamics.frame_placement(contact, q, 'head_top')
                tau = np.zeros(N_COORDINATES)
                samples.append(Sample(state, dynamics.evaluate(contact, q, v, tau),
                                      {'none': tau}, head.translation, head.rotation, None))
    return samples


def _decoded(bag: pathlib.Path) -> tuple[list, list]:
    """(/tf messages, /joint_states messages) of the bag, in order, decoded by mcap_ros2."""
    (path,) = bag.glob('*.mcap')
    tf, joint_states = [], []
    with path.open('rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(
                topics=['/tf', '/joint_states']):
            into = tf if channel.topic == '/tf' else joint_states
            into.append((message.log_time, decoded))
    return tf, joint_states


class _FreeFlyer:
    """Forward kinematics of the URDF on a free-flyer base: the support foot's pivot edge at
    (its ankle's x, y0 + pivot offset, 0), the foot turned by q1 about x."""

    def __init__(self) -> None:
        robot = load_robot()
        self.model = pin.buildModelFromUrdf(str(robot.urdf_path), pin.JointModelFreeFlyer())
        self.data = self.model.createData()
        self.links = [f.name for f in self.model.frames if f.type == pin.FrameType.BODY]

    def link_poses(self, q: np.ndarray, side: str, pivot: str) -> dict[str, pin.SE3]:
        model, data = self.model, self.data
        q_ff = pin.neutral(model)
        for i, joint, sign in anatomical_map(side):
            q_ff[model.joints[model.getJointId(joint)].idx_q] = sign * q[i]
        pin.framesForwardKinematics(model, data, q_ff)  # base at the origin
        edge = data.oMf[model.getFrameId(f'{side}_{pivot}')]
        world_edge = pin.SE3(pin.rpy.rpyToMatrix(q[Q1], 0.0, 0.0),
                             np.array([edge.translation[0], q[Y0] + PIVOT_Y[pivot], 0.0]))
        base = world_edge * edge.inverse()
        return {name: base * data.oMf[model.getFrameId(name)] for name in self.links}


def _check_tf(bag: pathlib.Path, samples: list[Sample]) -> None:
    """Every /tf message of the bag against the samples: tree, stamps, link world poses."""
    urdf = load_robot().urdf_path.read_text(encoding='utf-8')
    links, tree = _urdf_tree(urdf)
    tf, joint_states = _decoded(bag)
    assert len(tf) == len(joint_states) == len(samples)
    kinematics = _FreeFlyer()
    assert set(kinematics.links) == links
    worst = 0.0
    for (log_time, message), (js_time, js), sample in zip(tf, joint_states, samples,
                                                          strict=True):
        assert log_time == js_time
        pairs = [(t.header.frame_id, t.child_frame_id) for t in message.transforms]
        children = [child for _, child in pairs]
        assert sorted(children) == sorted(links)  # each link placed once
        assert set(pairs) == tree
        world = {'world': pin.SE3.Identity()}
        pending = list(message.transforms)
        while pending:  # compose along the tree, whatever the order
            ready = [t for t in pending if t.header.frame_id in world]
            assert ready, f'links {[t.child_frame_id for t in pending]} not reachable'
            for t in ready:
                assert (t.header.stamp.sec, t.header.stamp.nanosec) == (
                    js.header.stamp.sec, js.header.stamp.nanosec)
                r, p = t.transform.rotation, t.transform.translation
                assert abs(np.linalg.norm([r.x, r.y, r.z, r.w]) - 1.0) < 1e-12
                local = pin.XYZQUATToSE3(np.array([p.x, p.y, p.z, r.x, r.y, r.z, r.w]))
                world[t.child_frame_id] = world[t.header.frame_id] * local
                pending.remove(t)
        s = sample.state
        expected = kinematics.link_poses(s.q, s.contact.side, s.contact.pivot)
        for name in links:
            worst = max(worst, float(np.max(np.abs(world[name].translation
                                                   - expected[name].translation))),
                        float(np.max(np.abs(world[name].rotation - expected[name].rotation))))
        np.testing.assert_allclose(world['head_top'].translation, sample.head_position,
                                   rtol=0.0, atol=TOLERANCE)
    assert worst <= TOLERANCE, f'link pose error {worst:.3e}'


def test_tf_of_a_run_places_every_link_as_urdf_kinematics_does(tmp_path, run_samples):
    assert len({s.state.q[8] for s in run_samples}) > 100  # the torso turns
    _record(tmp_path / 'bag', run_samples, background=True)
    _check_tf(tmp_path / 'bag', run_samples)


def test_tf_of_every_mode_side_and_pivot(tmp_path, random_samples):
    _record(tmp_path / 'bag', random_samples, background=False)
    _check_tf(tmp_path / 'bag', random_samples)


def test_the_bag_opens_with_rosbags_and_lists_tf(tmp_path, run_samples):
    _record(tmp_path / 'bag', run_samples[:20], background=True)
    with AnyReader([tmp_path / 'bag'], default_typestore=make_typestore()) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types['/tf'] == 'tf2_msgs/msg/TFMessage'
        tf = [c for c in reader.connections if c.topic == '/tf']
        messages = [reader.deserialize(raw, c.msgtype)
                    for c, _, raw in reader.messages(connections=tf)]
    assert len(messages) == 20
    assert messages[0].transforms[0].header.frame_id == 'world'


def test_a_joint_neither_revolute_nor_fixed_is_refused(tmp_path):
    urdf = load_robot().urdf_path.read_text(encoding='utf-8')
    path = tmp_path / 'prismatic.urdf'
    path.write_text(urdf.replace('<joint name="torso_yaw" type="revolute">',
                                 '<joint name="torso_yaw" type="prismatic">'), encoding='utf-8')
    with pytest.raises(SimulationError, match='torso_yaw .* neither revolute nor fixed'):
        LinkTransforms(load_robot(str(path)))
