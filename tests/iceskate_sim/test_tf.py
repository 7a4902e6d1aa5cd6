"""/tf in the bags: at every (or every n-th) sample the world pose of every URDF link, read
back with the ``mcap`` reader (not rosbags) and checked against forward kinematics of the URDF
on a free-flyer base placed by the support foot, not by the simulator's support-rooted models.
The samples are the native loop's block columns (q, support side and pivot, and its /tf rows
``tf``)."""

from dataclasses import replace
import pathlib
import xml.etree.ElementTree as ET

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pinocchio as pin
import pytest
from rosbags.highlevel import AnyReader

from iceskate_bringup.scene import load_scene
from iceskate_sim.model.dynamics import ContactState
from iceskate_sim.model.modes import MODES
from iceskate_sim.model.robot import (
    PIVOT_Y,
    PIVOTS,
    Q1,
    SIDES,
    Y0,
    anatomical_map,
    load_robot,
)
from iceskate_sim.model.stamps import seconds_to_ns
from iceskate_sim.physics.hybrid import HybridState
from iceskate_sim.recording.bag import BagRecorder
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.recording.messages import Events, SampleMessages
from iceskate_sim.run.session import Session

#: a fast-stepping skate gait (test data): both support sides, flat and tipped soles
FAST_SKATE = pathlib.Path(__file__).resolve().parents[1] / 'data' / 'fast_skate.yaml'
PERIODS = 600  # 0.6 s at 1 ms
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


def _record(path: pathlib.Path, blocks: list[tuple[dict, Events]], background: bool,
            tf_every: int = 1) -> None:
    urdf = load_robot().urdf_path.read_text(encoding='utf-8')
    with BagRecorder(path, {'scene': 'tf-test'}, urdf, background=background,
                     tf_every=tf_every) as recorder:
        for block, events in blocks:
            recorder.write_block(block, events)


def _concatenated(blocks: list[dict]) -> dict:
    """One block of the rows of ``blocks`` (the columns the checks read)."""
    return {key: np.concatenate([b[key] for b in blocks])
            for key in ('t', 'q', 'side', 'pivot', 'tf', 'head_position')}


@pytest.fixture(scope='module')
def run_blocks(native_blocks) -> tuple[list[tuple[dict, Events]], dict]:
    """0.6 s of the fast skate gait on the native loop, in its blocks of 250 periods (each with
    its latest events), and all their rows."""
    scene = replace(load_scene(FAST_SKATE), duration=PERIODS * 1e-3, record_bag=False)
    blocks, events, session = native_blocks(scene, 250)
    assert session.sim.ended is None
    return ([(b, Events.of(b['last_event'], events)) for b in blocks],
            _concatenated(blocks))


@pytest.fixture
def random_block(random_state) -> dict:
    """One random state of every mode on every support side and pivot (q1 tipped where the
    mode frees it), 1 ms apart: the native loop's live sample of each, set on its simulator."""
    session = Session(replace(load_scene('stand'), record_bag=False))
    loop = session.command_inbox(())
    rows = []
    for mode in MODES.values():
        for side in SIDES:
            for pivot in PIVOTS:
                q, v = random_state(mode)
                session.sim.set_state(HybridState(len(rows) * 1e-3, q, v,
                                                  ContactState(mode, side, pivot)))
                rows.append(loop.kernel.live())
    return {key: np.concatenate([row[key] for row in rows])
            for key in ('t', 'q', 'side', 'pivot', 'tf', 'head_position', 'last_event',
                        'stamps_ns')}


def _decoded(bag: pathlib.Path) -> list[tuple[int, object]]:
    """(log time [ns], message) of the bag's /tf messages, in order, decoded by mcap_ros2."""
    (path,) = bag.glob('*.mcap')
    tf = []
    with path.open('rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(topics=['/tf']):
            assert channel.topic == '/tf'
            tf.append((message.log_time, decoded))
    return tf


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


def _check_tf(tf: list[tuple[int, object]], block: dict) -> None:
    """/tf messages (stamp [ns], message) against the rows of ``block``: tree, stamps, link
    world poses, the head on the block's head position."""
    urdf = load_robot().urdf_path.read_text(encoding='utf-8')
    links, tree = _urdf_tree(urdf)
    assert len(tf) == len(block['t'])
    kinematics = _FreeFlyer()
    assert set(kinematics.links) == links
    worst = 0.0
    for k, (log_time, message) in enumerate(tf):
        ns = seconds_to_ns(float(block['t'][k]))
        assert log_time == ns
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
                assert t.header.stamp.sec * 1_000_000_000 + t.header.stamp.nanosec == ns
                r, p = t.transform.rotation, t.transform.translation
                assert abs(np.linalg.norm([r.x, r.y, r.z, r.w]) - 1.0) < 1e-12
                local = pin.XYZQUATToSE3(np.array([p.x, p.y, p.z, r.x, r.y, r.z, r.w]))
                world[t.child_frame_id] = world[t.header.frame_id] * local
                pending.remove(t)
        q = block['q'][k]
        expected = kinematics.link_poses(q, SIDES[int(block['side'][k])],  # flat (0): toe
                                         PIVOTS[max(int(block['pivot'][k]) - 1, 0)])
        for name in links:
            worst = max(worst, float(np.max(np.abs(world[name].translation
                                                   - expected[name].translation))),
                        float(np.max(np.abs(world[name].rotation - expected[name].rotation))))
        np.testing.assert_allclose(world['head_top'].translation, block['head_position'][k],
                                   rtol=0.0, atol=TOLERANCE)
    assert worst <= TOLERANCE, f'link pose error {worst:.3e}'


def test_tf_of_a_run_places_every_link_as_urdf_kinematics_does(tmp_path, run_blocks):
    blocks, rows = run_blocks
    assert len(rows['t']) == PERIODS and len(blocks) >= 3
    assert len(set(rows['q'][:, 8].tolist())) > 100  # the torso turns
    assert set(rows['side'].tolist()) == {0, 1}  # both support feet
    assert np.ptp(rows['q'][:, Q1]) > 0.01  # the support sole tips
    _record(tmp_path / 'bag', blocks, background=True)
    _check_tf(_decoded(tmp_path / 'bag'), rows)


def test_tf_at_every_nth_sample_is_the_full_rate_tf_thinned_across_blocks(tmp_path, run_blocks):
    blocks, rows = run_blocks
    assert all(len(block['t']) % 7 for block, _ in blocks[:-1])  # the count runs on
    _record(tmp_path / 'full', blocks, background=False)
    _record(tmp_path / 'thin', blocks, background=True, tf_every=7)

    def tf(bag: pathlib.Path) -> list[tuple[int, bytes]]:
        (path,) = bag.glob('*.mcap')
        with path.open('rb') as stream:
            return [(m.log_time, m.data)
                    for _, _, m in make_reader(stream).iter_messages(topics=['/tf'])]
    full, thin = tf(tmp_path / 'full'), tf(tmp_path / 'thin')
    assert len(thin) > 10 and thin == full[::7]
    with AnyReader([tmp_path / 'thin'], default_typestore=make_typestore()) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts['/tf'] == len(full[::7]) and counts['/joint_states'] == len(rows['t'])


def test_tf_of_every_mode_side_and_pivot(robot, random_block):
    """The /tf bytes of the encoder, decoded by rosbags, over every contact."""
    typestore = make_typestore()
    encoded = SampleMessages(typestore, robot.tf_frames).encode(
        random_block, Events.of(random_block['last_event'], []), topics=('/tf',))
    assert list(encoded) == ['/tf']
    messages = [typestore.deserialize_cdr(data, 'tf2_msgs/msg/TFMessage')
                for data in encoded['/tf']]
    assert len(messages) == len(MODES) * len(SIDES) * len(PIVOTS)
    _check_tf([(seconds_to_ns(float(t)), m) for t, m in
               zip(random_block['t'], messages, strict=True)], random_block)


def test_only_the_revolute_joints_move(robot, random_block):
    """Over states of every contact, a fixed joint's transform stays (to rounding) and a
    revolute one's turns; the root link's world pose is the first row."""
    rows = random_block['tf'].reshape(len(random_block['t']), -1, 7)
    assert rows.shape[1] == len(robot.tf_frames) and robot.tf_frames[0] == ('world', 'pelvis')
    moving = np.ptp(rows[:, 1:], axis=0).max(axis=1) > 1e-12
    urdf = load_robot().urdf_path.read_text(encoding='utf-8')
    revolute = {(j.find('parent').get('link'), j.find('child').get('link'))
                for j in ET.fromstring(urdf).iter('joint') if j.get('type') == 'revolute'}
    assert {pair for pair, m in zip(robot.tf_frames[1:], moving, strict=True) if m} == revolute


def test_the_bag_opens_with_rosbags_and_lists_tf(tmp_path, run_blocks):
    blocks, _ = run_blocks
    block, events = blocks[0]
    first = {key: value[:20] if isinstance(value, np.ndarray) else value
             for key, value in block.items()}
    first['efforts'] = [e[:20] for e in block['efforts']]
    _record(tmp_path / 'bag', [(first, Events(events.cause[:20], events.causes))],
            background=True)
    with AnyReader([tmp_path / 'bag'], default_typestore=make_typestore()) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types['/tf'] == 'tf2_msgs/msg/TFMessage'
        tf = [c for c in reader.connections if c.topic == '/tf']
        messages = [reader.deserialize(raw, c.msgtype)
                    for c, _, raw in reader.messages(connections=tf)]
    assert len(messages) == 20
    assert messages[0].transforms[0].header.frame_id == 'world'


