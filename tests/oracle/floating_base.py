"""Test oracle: a second, independent formulation of the gait dynamics, used as a cross-check.

The URDF is loaded as it is (rooted at the pelvis) on a 6-dof free-flyer base, so the robot has
22 velocity coordinates and no notion of support foot. Every contact of a Table 2 mode becomes
rows of a constraint Jacobian on Pinocchio frames:

* support foot flat and stuck: all 6 rows of the pivot-edge frame; on an edge (q1 present):
  drop the rotation about x; gliding (y0 present): drop the translation along y and add
  Coulomb friction -mu sgn(yd0) N_s on it, N_s being the vertical multiplier;
* swing foot: heel height (C_hz), heel y (C_hy) and the swing sole's rotation about x (C_fr),
  with friction on a sliding heel.

Input torques given in Table 2 coordinates are mapped onto the anatomical joints (support-leg
signs flipped); the q1 torque acts as a moment of the floor on the support foot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.dynamics import ContactState, DynamicsParameters
from iceskate_sim.model.robot import N_COORDINATES, Q1, Y0, Robot, anatomical_map
from oracle.dynamics import GaitDynamics

_LWA = pin.LOCAL_WORLD_ALIGNED
_LIN_X, _LIN_Y, _LIN_Z, _ANG_X, _ANG_Y, _ANG_Z = range(6)


@dataclass
class FloatingBaseResult:
    """Table-2 accelerations and contact forces computed by the floating-base formulation."""

    qdd: np.ndarray  # (18,) [m/s^2, rad/s^2]
    multipliers: np.ndarray  # (f_nz, f_ny, tau_n) of the swing contact [N, N, N m]
    support_normal: float  # N_s [N]
    support_friction: float  # F_y [N]


class FloatingBaseDynamics:
    """Free-flyer model of the URDF with the contacts of a Table 2 mode as constraints."""

    def __init__(self, robot: Robot, params: DynamicsParameters | None = None) -> None:
        self.params = params or DynamicsParameters()
        self.model = pin.buildModelFromUrdf(str(robot.urdf_path), pin.JointModelFreeFlyer())
        self.data = self.model.createData()
        self._reduced = GaitDynamics(robot, self.params)  # only to place the base (kinematics)
        self._maps = {}
        for side in ('right', 'left'):
            entries = []
            for i, urdf_joint, sign in anatomical_map(side):
                joint = self.model.joints[self.model.getJointId(urdf_joint)]
                entries.append((i, joint.idx_q, joint.idx_v, sign))
            self._maps[side] = entries

    def state(self, contact: ContactState, q: np.ndarray, v: np.ndarray,
              ) -> tuple[np.ndarray, np.ndarray]:
        """Free-flyer configuration (nq = 23) and velocity (nv = 22) of a Table-2 state."""
        placement = self._reduced.frame_placement(contact, q, 'pelvis')
        velocity = self._reduced.frame_velocity(contact, q, v, 'pelvis')
        q_ff = np.zeros(self.model.nq)
        v_ff = np.zeros(self.model.nv)
        q_ff[:7] = pin.SE3ToXYZQUAT(placement)
        # free-flyer velocity is expressed in the local (pelvis) frame
        v_ff[:3] = placement.rotation.T @ velocity.linear
        v_ff[3:6] = placement.rotation.T @ velocity.angular
        for i, idx_q, idx_v, sign in self._maps[contact.side]:
            q_ff[idx_q] = sign * q[i]
            v_ff[idx_v] = sign * v[i]
        return q_ff, v_ff

    def evaluate(self, contact: ContactState, q: np.ndarray, v: np.ndarray,
                 applied: np.ndarray) -> FloatingBaseResult:
        """Solve the floating-base KKT system for the mode in ``contact``.

        :param applied: all non-contact generalized forces in Table-2 coordinates
            (inputs, damping, soft stops), length 18.
        """
        mode = contact.mode
        model, data = self.model, self.data
        q_ff, v_ff = self.state(contact, q, v)
        pin.computeAllTerms(model, data, q_ff, v_ff)
        pin.forwardKinematics(model, data, q_ff, v_ff, np.zeros(model.nv))
        pin.updateFramePlacements(model, data)
        mu = self.params.mu
        swing = 'left' if contact.side == 'right' else 'right'
        pivot_frame = model.getFrameId(f'{contact.side}_{contact.pivot}')
        heel_frame = model.getFrameId(f'{swing}_heel')
        J_sup = pin.getFrameJacobian(model, data, pivot_frame, _LWA)
        a_sup = pin.getFrameClassicalAcceleration(model, data, pivot_frame, _LWA).vector
        J_heel = pin.getFrameJacobian(model, data, heel_frame, _LWA)
        a_heel = pin.getFrameClassicalAcceleration(model, data, heel_frame, _LWA).vector

        tau = np.zeros(model.nv)
        for i, _idx_q, idx_v, sign in self._maps[contact.side]:
            tau[idx_v] = sign * applied[i]
        if mode.q1_active:  # torque at the floor pivot = moment of the floor on the foot
            tau += J_sup[_ANG_X] * applied[Q1]

        rows, cols, drift, labels = [], [], [], []
        support_rows = [_LIN_X, _LIN_Z, _ANG_Y, _ANG_Z]
        if not mode.y0_active:
            support_rows.append(_LIN_Y)
        if not mode.q1_active:
            support_rows.append(_ANG_X)
        for r in sorted(support_rows):
            rows.append(J_sup[r])
            col = J_sup[r].copy()
            if r == _LIN_Z and mode.y0_active:
                col -= mu * contact.support_slide_dir * J_sup[_LIN_Y]
            cols.append(col)
            drift.append(a_sup[r])
            labels.append(('support', r))
        for name in mode.constraints:
            if name == 'hz':
                row, col, acc = J_heel[_LIN_Z], J_heel[_LIN_Z].copy(), a_heel[_LIN_Z]
                if mode.swing_sliding:
                    col -= mu * contact.heel_slide_dir * J_heel[_LIN_Y]
            elif name == 'hy':
                row, col, acc = J_heel[_LIN_Y], J_heel[_LIN_Y], a_heel[_LIN_Y]
            else:
                row, col, acc = J_heel[_ANG_X], J_heel[_ANG_X], a_heel[_ANG_X]
            rows.append(row)
            cols.append(col)
            drift.append(acc)
            labels.append(('swing', name))
        J = np.array(rows)
        B = np.array(cols)
        nv, nc = model.nv, len(rows)
        M = data.M.copy()
        M = np.triu(M) + np.triu(M, 1).T
        A = np.block([[M, -B.T], [J, np.zeros((nc, nc))]])
        b = np.concatenate([tau - data.nle, -np.array(drift)])
        try:
            x = np.linalg.solve(A, b)
        except np.linalg.LinAlgError as exc:
            raise SimulationError(f'floating-base mode {mode.number}: singular ({exc})') from exc
        a_ff, lam = x[:nv], x[nv:]

        qdd = np.zeros(N_COORDINATES)
        for i, _idx_q, idx_v, sign in self._maps[contact.side]:
            qdd[i] = sign * a_ff[idx_v]
        support_acc = J_sup @ a_ff + a_sup
        qdd[Q1] = support_acc[_ANG_X] if mode.q1_active else 0.0
        qdd[Y0] = support_acc[_LIN_Y] if mode.y0_active else 0.0
        multipliers = np.zeros(3)
        normal = tangential = 0.0
        for (kind, what), value in zip(labels, lam, strict=True):
            if kind == 'swing':
                multipliers[{'hz': 0, 'hy': 1, 'fr': 2}[what]] = value
            elif what == _LIN_Z:
                normal = float(value)
            elif what == _LIN_Y:
                tangential = float(value)
        if mode.y0_active:
            tangential = -mu * contact.support_slide_dir * normal
        return FloatingBaseResult(qdd, multipliers, normal, tangential)
