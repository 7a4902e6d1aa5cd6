"""Where the body is drawn: the URDF on a free-flyer base, placed by the support foot.

A sample's Table-2 coordinates (support-rooted) become the configuration of the URDF model with
a free-flyer base: the joints by ``anatomical_map``, the base such that the support sole's
pivot edge lies on the ice at (its x, y0 + the edge's offset, 0), turned by q1 about x. The
tests check the links' poses against the simulator's own /tf to 1e-9.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from iceskate_sim.model.robot import PIVOT_Y, PIVOTS, Q1, SIDES, Y0, Robot, anatomical_map
from iceskate_sim.ros.conversions import PIVOT_OF_CODE  # on a flat sole both edges: one pose


@dataclass(frozen=True)
class ViewFrame:
    """What the view shows of one sample.

    :param t: simulated time [s]. :param q: Table-2 coordinates (18,) [m, rad].
    :param mode: Table 2 mode number. :param side: support side, 'right' or 'left'.
    :param pivot: pivot edge of the support sole, 'toe' or 'heel'.
    :param step_index: support exchanges so far.
    :param head_target: visual lifting's head target (y, z) [m] (NaN: none).
    """

    t: float
    q: np.ndarray
    mode: int
    side: str
    pivot: str
    step_index: int
    head_target: np.ndarray

    @classmethod
    def of_columns(cls, columns: dict[str, np.ndarray], k: int) -> ViewFrame:
        """Sample ``k`` of a trajectory's columns (``trajectory.npz``: side and pivot as codes,
        ``psi_d`` the head target (y, z, pitch))."""
        return cls(float(columns['t'][k]), np.asarray(columns['q'][k], dtype=float),
                   int(columns['mode'][k]), SIDES[int(columns['side'][k])],
                   PIVOT_OF_CODE[int(columns['pivot'][k])], int(columns['step_index'][k]),
                   np.asarray(columns['head_target'][k][:2], dtype=float))


class BodyPose:
    """The URDF model on a free-flyer base, its visual geometry, and the base of a sample."""

    def __init__(self, robot: Robot) -> None:
        path = str(robot.urdf_path)
        self.model = pin.buildModelFromUrdf(path, pin.JointModelFreeFlyer())
        self.visual = pin.buildGeomFromUrdf(self.model, path, pin.GeometryType.VISUAL)
        self.data = self.model.createData()
        self.geometry = pin.GeometryData(self.visual)
        self._joints = {side: [(i, self.model.joints[self.model.getJointId(joint)].idx_q, sign)
                               for i, joint, sign in anatomical_map(side)] for side in SIDES}
        self._edges = {(side, pivot): self.model.getFrameId(f'{side}_{pivot}')
                       for side in SIDES for pivot in PIVOTS}

    def configuration(self, frame: ViewFrame) -> np.ndarray:
        """The free-flyer configuration (nq,) of ``frame``: base x, y, z [m], quaternion x, y,
        z, w, then the URDF's joint angles [rad]."""
        q = frame.q
        configuration = pin.neutral(self.model)
        for i, index, sign in self._joints[frame.side]:
            configuration[index] = sign * q[i]
        edge_id = self._edges[(frame.side, frame.pivot)]
        pin.forwardKinematics(self.model, self.data, configuration)  # base at the origin
        edge = pin.updateFramePlacement(self.model, self.data, edge_id)
        world_edge = pin.SE3(pin.rpy.rpyToMatrix(q[Q1], 0.0, 0.0),
                             np.array([edge.translation[0], q[Y0] + PIVOT_Y[frame.pivot], 0.0]))
        configuration[:7] = pin.SE3ToXYZQUAT(world_edge * edge.inverse())
        return configuration

    def place(self, configuration: np.ndarray) -> None:
        """Forward kinematics at ``configuration``: ``frame_placement`` and the visual
        geometry's world placements ``geometry.oMg`` then hold its poses."""
        pin.forwardKinematics(self.model, self.data, configuration)
        pin.updateGeometryPlacements(self.model, self.data, self.visual, self.geometry)

    def frame_placement(self, frame_name: str) -> pin.SE3:
        """World placement of the URDF frame ``frame_name`` at the last ``place``."""
        return pin.updateFramePlacement(self.model, self.data,
                                        self.model.getFrameId(frame_name)).copy()
