"""The /tf rows of a state by Pinocchio in the Python support model: the native loop's ``tf``
column computed another way (frame placements composed with ``pin.SE3``)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from iceskate_sim.model.robot import Robot


def tf_rows(robot: Robot, side: str, pivot: str, q: np.ndarray) -> np.ndarray:
    """(pairs, 7): per ``robot.tf_frames`` pair, the child's placement in its parent's (the
    world's for ``world``) as x, y, z [m], qx, qy, qz, qw, at coordinates q (18,) on the
    support model of ``side`` and ``pivot``."""
    support = robot.support_model(side, pivot)
    data = support.new_data()
    pin.forwardKinematics(support.model, data, q)
    placed = {'world': pin.SE3.Identity()}
    for name in {name for pair in robot.tf_frames for name in pair} - {'world'}:
        placed[name] = pin.updateFramePlacement(support.model, data,
                                                support.frame_ids[name]).copy()
    return np.array([pin.SE3ToXYZQUAT(placed[parent].actInv(placed[child]))
                     for parent, child in robot.tf_frames])
