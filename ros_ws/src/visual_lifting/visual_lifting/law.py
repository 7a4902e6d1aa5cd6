"""Visual-lifting control law, the paper's eqs. (8)-(9) (docs/model.md §10), ROS-free.

The head-top pose psi = (y_H [m], z_H [m], pitch [rad]) in the world is pulled towards a desired
pose psi_d by a virtual spring: tau_h = J_H(q)^T K_p (psi_d - psi), applied to the joints on the
path from the support foot to the head (1, 2, 3, 4, 8, 9, 10, 17; the paper, Sec. 5.2). The vision
step is skipped as in the paper: psi comes from the kinematics (``GaitDynamics.head_pose``).

Every function here is pure: it depends only on its arguments. Torques are 18-vectors over
``[y0, q1, ..., q17]`` in N m (entry i = joint i; the y0 entry is always 0).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.observation import Observation
from iceskate_sim.parameters import check_fields, from_mapping, setting
from iceskate_sim.stance import StanceSchedule
from visual_lifting.errors import VisualLiftingError

N_COORDINATES = 18
DESIRED_Y_OPTIONS = ('moving', 'follow', 'fixed')


@dataclass(frozen=True)
class VisualLiftingParameters:
    """Parameters of the visual-lifting law (docs/model.md, visual lifting).

    Each field's description, unit and range are its ``setting``; the node declares them as
    typed ROS parameters (``ros2 param list /visual_lifting``).
    """

    kp: tuple[float, float, float] = setting(
        (20.0, 290.0, 1100.0), 'K_p = diag(k_y, k_z, k_pitch) on the head pose (y, z, pitch); '
        'the paper: 20, 290, 1100', unit='N/m, N/m, N m/rad', low=0.0)
    joints: tuple[int, ...] = setting(
        (1, 2, 3, 4, 8, 9, 10, 17), 'joints that receive the torque (support foot to head); a '
        'joint gets torque only while its coordinate is active in the mode', low=1, high=17,
        distinct=True)
    joint1_torque: bool = setting(True, 'apply the joint-1 (floor pivot) entry while q1 is active')
    desired_y: str = setting(
        'moving', "forward target y_d: 'moving' y_H(0) + v_d t, 'follow' y_H(t) (forward term "
        "off), 'fixed' y_H(0)", choices=DESIRED_Y_OPTIONS)
    v_d: float = setting(0.3, "forward speed of the 'moving' target", unit='m/s', low=-5.0,
                         high=5.0)
    z_d: float | None = setting(None, 'target head-top height; unset (NaN): the initial height',
                                unit='m', low=0.0, open_low=True)
    pitch_d: float = setting(0.0, 'target head pitch', unit='rad', low=-1.0, high=1.0)
    max_dy: float | None = setting(0.3, 'saturation of |y_d - y|; unset (NaN): none', unit='m',
                                   low=0.0, open_low=True)
    shift_y1: float = setting(0.0, 'forward shift of the target after a support exchange (the '
                              "gait manager's moving stance)", unit='m', low=-0.4, high=0.4)
    shift_z1: float = setting(0.0, 'downward shift of the target after a support exchange',
                              unit='m', low=-0.1, high=0.3)
    shift_time1: float = setting(0.6, 'duration of the first shift', unit='s', low=0.0)
    shift_y2: float = setting(0.0, 'further forward shift after the swing heel strike', unit='m',
                              low=-0.4, high=0.4)
    shift_time2: float = setting(0.5, 'duration of the second shift', unit='s', low=0.0)

    def __post_init__(self) -> None:
        """Check and normalise every field (VisualLiftingError naming the key)."""
        check_fields(self, VisualLiftingError)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> VisualLiftingParameters:
        """Build from a mapping (e.g. YAML); unknown keys and bad values raise an error."""
        return from_mapping(cls, d, VisualLiftingError)

    @property
    def stance(self) -> StanceSchedule:
        """The moving stance the target follows (no shift by default)."""
        return StanceSchedule(self.shift_y1, self.shift_z1, self.shift_time1, self.shift_y2,
                              self.shift_time2)


class HeadTask(NamedTuple):
    """One evaluation of the law: torque [N m], psi, psi_d and the (saturated) error."""

    tau: np.ndarray
    psi: np.ndarray
    psi_d: np.ndarray
    error: np.ndarray


def desired_head_pose(params: VisualLiftingParameters, t: float, psi: np.ndarray,
                      psi_initial: np.ndarray,
                      offset: Sequence[float] = (0.0, 0.0)) -> np.ndarray:
    """Return psi_d = (y_d [m], z_d [m], pitch_d [rad]) at time ``t`` [s].

    :param psi: current head pose (used by desired_y = 'follow').
    :param psi_initial: head pose at t = 0 (y_H(0), and z_H(0) when ``params.z_d`` is None).
    :param offset: (dy, dz) [m] added to y_d and z_d, e.g. the gait manager's moving-stance
        shift (docs/model.md §11.2). 'follow' ignores dy: its forward error is zero by definition.
    """
    if len(offset) != 2:
        raise VisualLiftingError(f'offset must be (dy, dz), got {offset!r}')
    dy, dz = float(offset[0]), float(offset[1])
    if params.desired_y == 'moving':
        y_d = float(psi_initial[0]) + params.v_d * float(t) + dy
    elif params.desired_y == 'fixed':
        y_d = float(psi_initial[0]) + dy
    else:  # 'follow'
        y_d = float(psi[0])
    z_d = (float(psi_initial[1]) if params.z_d is None else params.z_d) + dz
    return np.array([y_d, z_d, params.pitch_d])


def head_error(psi_d: np.ndarray, psi: np.ndarray,
               params: VisualLiftingParameters) -> np.ndarray:
    """Return delta psi = psi_d - psi with |delta y| saturated at ``params.max_dy``."""
    error = np.asarray(psi_d, dtype=float) - np.asarray(psi, dtype=float)
    if params.max_dy is not None:
        error[0] = min(max(error[0], -params.max_dy), params.max_dy)
    return error


def joint_mask(obs: Observation, params: VisualLiftingParameters) -> np.ndarray:
    """Boolean 18-mask of the coordinates that receive torque in ``obs``'s mode."""
    mask = np.zeros(N_COORDINATES, dtype=bool)
    mask[list(params.joints)] = True
    mode = obs.gait_mode
    mask[0] = False
    if not (mode.q1_active and params.joint1_torque):
        mask[1] = False
    return mask


def visual_lifting_torque(obs: Observation, dynamics: GaitDynamics,
                          params: VisualLiftingParameters, psi_d: np.ndarray, *,
                          pose: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Return tau_h = J_H(q)^T K_p delta psi [N m] on the listed joints active in the mode.

    :param psi_d: desired head pose (``desired_head_pose``).
    :param pose: (psi, J_H) if already computed by ``dynamics.head_pose`` for ``obs``.
    """
    psi, jac = pose if pose is not None else dynamics.head_pose(obs.contact(), obs.q)
    error = head_error(psi_d, psi, params)
    tau = jac.T @ (np.asarray(params.kp) * error)
    tau[~joint_mask(obs, params)] = 0.0
    return tau


def head_origin(obs: Observation, dynamics: GaitDynamics) -> np.ndarray:
    """psi(0): the head pose (y [m], z [m], pitch [rad]) at the first state, origin of the
    target."""
    return dynamics.head_pose(obs.contact(), obs.q)[0]


def visual_lifting(obs: Observation, dynamics: GaitDynamics, params: VisualLiftingParameters,
                   psi_initial: np.ndarray) -> HeadTask:
    """Evaluate the whole law once (one head-pose computation): torque, psi, psi_d, error.

    The target follows the moving stance of ``params`` (``stance``).
    """
    psi, jac = dynamics.head_pose(obs.contact(), obs.q)
    psi_d = desired_head_pose(params, obs.t, psi, psi_initial, params.stance.shift(obs))
    tau = visual_lifting_torque(obs, dynamics, params, psi_d, pose=(psi, jac))
    return HeadTask(tau, psi, psi_d, head_error(psi_d, psi, params))
