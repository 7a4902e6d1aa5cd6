"""Visual lifting, eqs. (8)-(9) (docs/model.md §10), as a controller written in Python:
``VisualLifting``, tau_h = J_H(q)^T K_p (psi_d - psi), taking ``VisualLiftingParameters``' fields
as keyword arguments; the C++ law's operations in the same order, so its answer to the last bit.
A scene names it as ``plugin: 'iceskate_bringup.examples.visual_lifting_numpy:VisualLifting'``
(the shipped scene ``stand_python``); docs/usage.md, 'Your own controller'.
"""

from __future__ import annotations

from collections.abc import Sequence
import math

import numpy as np

import iceskate_native


def ramp(dt: float, duration: float) -> float:
    """A smoothstep 3x^2 - 2x^3 from 0 to 1 over ``duration`` [s] after dt = 0 [s]."""
    if duration == 0.0:
        return 1.0 if dt >= 0.0 else 0.0
    x = min(max(dt / duration, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


class VisualLifting(iceskate_native.Controller):
    """Eq. (9) with numpy: one source (the controller's name) and the head target psi_d.

    :param kp: K_p on (y, z, pitch) [N/m, N/m, N m/rad].
    :param joints: the joints that get torque (1-17), each while its coordinate is active.
    :param joint1_torque: the joint-1 entry while q1 (the support edge) is active.
    :param desired_y: 'moving' y_H(0) + v_d t, 'fixed' y_H(0), 'follow' y_H(t).
    :param v_d: speed of the 'moving' target [m/s]. :param z_d: target height [m] (None: z_H(0)).
    :param pitch_d: target pitch [rad]. :param max_dy: bound of |y_d - y| [m] (None: none).
    :param shift_y1, shift_z1, shift_time1: forward [m] and downward [m] shift of the target
        over shift_time1 [s] after a support exchange.
    :param shift_y2, shift_time2: further forward shift [m] over shift_time2 [s] after the
        swing heel strike.
    """

    def __init__(self, kp: Sequence[float] = (20.0, 290.0, 1100.0),
                 joints: Sequence[int] = (1, 2, 3, 4, 8, 9, 10, 17), joint1_torque: bool = True,
                 desired_y: str = 'moving', v_d: float = 0.3, z_d: float | None = None,
                 pitch_d: float = 0.0, max_dy: float | None = 0.3, shift_y1: float = 0.0,
                 shift_z1: float = 0.0, shift_time1: float = 0.6, shift_y2: float = 0.0,
                 shift_time2: float = 0.5) -> None:
        super().__init__()
        if desired_y not in ('moving', 'fixed', 'follow'):
            raise ValueError(f"desired_y must be 'moving', 'fixed' or 'follow', got {desired_y!r}")
        self.kp = np.asarray(kp, dtype=float).reshape(3)
        self.mask = np.zeros(18, dtype=bool)
        self.mask[list(joints)] = True
        self.joint1_torque = bool(joint1_torque)
        self.desired_y, self.v_d, self.z_d, self.pitch_d = desired_y, v_d, z_d, pitch_d
        self.max_dy = max_dy
        self.shift = (shift_y1, shift_z1, shift_time1, shift_y2, shift_time2)
        self.origin: np.ndarray | None = None  # psi(0)

    def compute(self, obs: iceskate_native.Observation,
                kinematics: iceskate_native.Kinematics) -> dict[str, np.ndarray]:
        """tau_h [N m] at ``obs`` and the target psi_d it steers to."""
        psi, jac = kinematics.head_pose(obs)
        if obs.t == 0.0 or self.origin is None:
            self.origin = psi
        dy1, dz1, t1, dy2, t2 = self.shift  # the moving stance
        s1 = ramp(obs.t - obs.t_exchange, t1)
        dy, dz = dy1 * s1, -dz1 * s1
        if math.isfinite(obs.t_touchdown):
            dy += dy2 * ramp(obs.t - obs.t_touchdown, t2)
        y0, z0 = self.origin[0], self.origin[1]
        y_d = {'moving': y0 + self.v_d * obs.t + dy, 'fixed': y0 + dy, 'follow': psi[0]}
        psi_d = np.array([y_d[self.desired_y], (z0 if self.z_d is None else self.z_d) + dz,
                          self.pitch_d])
        error = psi_d - psi
        if self.max_dy is not None:
            error[0] = min(max(error[0], -self.max_dy), self.max_dy)
        pull = self.kp * error
        tau = jac[0] * pull[0] + jac[1] * pull[1] + jac[2] * pull[2]  # J_H^T K_p delta psi
        mask = self.mask.copy()
        mask[0] = False
        mask[1] &= self.joint1_torque and 1 in kinematics.active(obs.mode)
        return {'effort': np.where(mask, tau, 0.0), 'head_target': psi_d}
