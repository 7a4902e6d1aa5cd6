"""The /tf transforms of recorded samples in robot_state_publisher's layout."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.robot import SIDES, anatomical_map


class LinkTransforms:
    """The /tf transforms of a URDF robot: ``world`` -> the URDF's root link, then one per URDF
    joint, parent link -> child link (the fixed joints too, constant, in every message), each a
    row (x, y, z [m], qx, qy, qz, qw).

    The root link's world pose comes with the sample (the native loop's ``root_pose``: its
    placement in the support model of the sample's contact, as the simulation places every
    link). A revolute joint's row is its origin turned about its axis by its URDF angle, the
    Table-2 coordinate of ``anatomical_map`` for the sample's support side.

    :param model: the URDF's Pinocchio model (``Robot.urdf_model``).
    :raises SimulationError: for a URDF joint neither revolute nor fixed, or one without a
        Table-2 coordinate.
    :ivar root: the URDF's root link.
    :ivar frames: (frame_id, child_frame_id) of each row: URDF link names, and ``world``.
    """

    def __init__(self, model: pin.Model) -> None:
        frames = model.frames
        child_of = {f.parentFrame: f for f in frames if f.type == pin.FrameType.BODY}
        self.root = child_of[0].name  # the link on the universe frame
        self.frames = [('world', self.root)]
        origins = [pin.SE3.Identity()]
        moving: list[int] = []
        joints: list[str] = []
        axes: list[np.ndarray] = []
        for k, frame in enumerate(frames):
            if k == 0 or frame.type not in (pin.FrameType.JOINT, pin.FrameType.FIXED_JOINT):
                continue
            parent, child = frames[frame.parentFrame], child_of[k]
            self.frames.append((parent.name, child.name))
            if frame.type == pin.FrameType.FIXED_JOINT:
                origins.append(parent.placement.inverse() * child.placement)
                continue
            origins.append(parent.placement.inverse() * model.jointPlacements[frame.parentJoint])
            moving.append(len(origins) - 1)
            joints.append(frame.name)
            axes.append(_revolute_axis(model, frame.parentJoint))
        self._constant = np.array([pin.SE3ToXYZQUAT(m) for m in origins])
        self._moving = np.array(moving, dtype=np.intp)
        # origin quaternion (v, w) times the turn (a sin h, cos h) about axis a by angle 2 h:
        # sin h (w a + v x a, -v . a) + cos h (v, w)
        v, w, a = self._constant[moving, 3:6], self._constant[moving, 6:], np.array(axes)
        self._sin_part = np.hstack([w * a + np.cross(v, a), -np.sum(v * a, axis=1, keepdims=True)])
        self._cos_part = self._constant[moving, 3:]
        self._coordinates = []
        for side in SIDES:
            coordinate = {name: (i, sign) for i, name, sign in anatomical_map(side)}
            missing = sorted(set(joints) - set(coordinate))
            if missing:
                raise SimulationError(f'URDF joints {missing} have no Table-2 coordinate')
            index, sign = zip(*(coordinate[name] for name in joints), strict=True)
            self._coordinates.append((np.array(index, dtype=np.intp), np.array(sign)))

    def block_rows(self, q: np.ndarray, side: np.ndarray, root_pose: np.ndarray) -> np.ndarray:
        """The rows of m samples: Table-2 coordinates q (m, 18) [m, rad], support side (m,)
        (index in SIDES), root link world pose (m, 7) -> (m, len(frames), 7)."""
        out = np.repeat(self._constant[None], len(q), axis=0)
        out[:, 0] = root_pose
        for code, (index, sign) in enumerate(self._coordinates):
            rows = np.flatnonzero(side == code)
            if rows.size:
                half = (0.5 * q[rows][:, index] * sign)[:, :, None]
                with np.errstate(invalid='ignore'):  # an infinite angle: NaN, as recorded
                    sin, cos = np.sin(half), np.cos(half)
                out[rows[:, None], self._moving, 3:] = sin * self._sin_part + cos * self._cos_part
        return out


def _revolute_axis(model: pin.Model, joint: int) -> np.ndarray:
    """The unit axis of a revolute joint of ``model``, in its frame.

    :raises SimulationError: if the joint is not revolute (one coordinate, no translation).
    """
    joint_model = model.joints[joint]
    if joint_model.nq == joint_model.nv == 1:
        data = joint_model.createData()
        joint_model.calc(data, np.zeros(model.nq))  # it reads its entries of the model's q
        subspace = np.ravel(data.S)  # (linear, angular) velocity of a unit joint speed
        if not np.any(subspace[:3]):
            return subspace[3:]
    raise SimulationError(f'URDF joint {model.names[joint]} ({joint_model.shortname()}) is '
                          'neither revolute nor fixed; /tf cannot place its link')
