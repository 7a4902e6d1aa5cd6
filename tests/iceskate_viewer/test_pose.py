"""The body drawn where the simulator says it is: for every sample of a run, the world pose of
every link from ``BodyPose`` (the URDF on a free-flyer base, from trajectory.npz's columns)
equals the one the simulator recorded in the bag's /tf (the support-rooted C++ models' link
placements, composed along the tree) to 1e-9."""

import numpy as np
import pinocchio as pin
import pytest
from rosbags.highlevel import AnyReader

from iceskate_sim.model.robot import load_robot
from iceskate_viewer.pose import BodyPose, ViewFrame
from iceskate_viewer.replay import load_run

TOLERANCE = 1e-9  # m, and on rotation-matrix entries


def _tf_poses(bag: str) -> list[tuple[int, dict[str, pin.SE3]]]:
    """(stamp [ns], world pose of every link) at every /tf message of ``bag``, composed along
    the tree."""
    samples = []
    with AnyReader([bag]) as reader:
        connections = [c for c in reader.connections if c.topic == '/tf']
        for connection, stamp, raw in reader.messages(connections=connections):
            message = reader.deserialize(raw, connection.msgtype)
            world = {'world': pin.SE3.Identity()}
            for transform in message.transforms:  # parents first
                p, r = transform.transform.translation, transform.transform.rotation
                local = pin.XYZQUATToSE3(np.array([p.x, p.y, p.z, r.x, r.y, r.z, r.w]))
                world[transform.child_frame_id] = world[transform.header.frame_id] * local
            samples.append((stamp, world))
    return samples


def test_every_link_is_drawn_at_the_simulators_pose(skate_run):
    run = load_run(skate_run)
    recorded = _tf_poses(skate_run / 'bag')
    stamps = np.round(run.t * 1e9).astype(np.int64)
    assert len(recorded) == len(run.t[::8]) > 100  # /tf at 125 Hz of the 1 kHz samples
    assert set(run.columns['side']) == {0, 1} and set(run.columns['pivot']) >= {0, 1}
    body = BodyPose(load_robot())
    worst = 0.0
    for stamp, links in recorded:
        (k,) = np.flatnonzero(stamps == stamp)
        body.place(body.configuration(ViewFrame.of_columns(run.columns, k)))
        for name, expected in links.items():
            if name == 'world':
                continue
            drawn = body.frame_placement(name)
            worst = max(worst, np.max(np.abs(drawn.translation - expected.translation)),
                        np.max(np.abs(drawn.rotation - expected.rotation)))
    assert worst <= TOLERANCE, worst


def test_the_geometry_follows_its_link(skate_run):
    """Every shape's world placement is its link's placement times its URDF origin."""
    run = load_run(skate_run)
    body = BodyPose(load_robot())
    body.place(body.configuration(ViewFrame.of_columns(run.columns, len(run.t) // 2)))
    for item, placed in zip(body.visual.geometryObjects, body.geometry.oMg, strict=True):
        link = body.frame_placement(body.model.frames[item.parentFrame].name)
        np.testing.assert_allclose((link * item.placement).homogeneous, placed.homogeneous,
                                   atol=1e-12)


@pytest.mark.parametrize('code, pivot', [(0, 'toe'), (1, 'toe'), (2, 'heel')])
def test_the_pivot_names_the_edge(code, pivot):
    columns = {'t': np.zeros(1), 'q': np.zeros((1, 18)), 'mode': np.ones(1, int),
               'side': np.zeros(1, int), 'pivot': np.array([code]),
               'step_index': np.zeros(1, int), 'head_target': np.full((1, 3), np.nan)}
    assert ViewFrame.of_columns(columns, 0).pivot == pivot
