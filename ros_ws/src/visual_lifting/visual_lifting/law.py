"""Visual-lifting control law, the paper's eqs. (8)-(9) (model-spec §6), ROS-free.

The head-top pose psi = (y_H [m], z_H [m], pitch [rad]) in the world is pulled towards a desired
pose psi_d by a virtual spring: tau_h = J_H(q)^T K_p (psi_d - psi), applied to the joints on the
path from the support foot to the head (1, 2, 3, 4, 8, 9, 10, 17; seed §5.2). The vision step is
skipped as in the seed: psi comes from the kinematics (``GaitDynamics.head_pose``).

Every function here is pure: it depends only on its arguments. Torques are 18-vectors over
``[y0, q1, ..., q17]`` in N m (entry i = joint i; the y0 entry is always 0).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
import math
import numbers
from typing import Any, NamedTuple

import numpy as np

from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.observation import Observation
from visual_lifting.errors import VisualLiftingError

N_COORDINATES = 18
DESIRED_Y_OPTIONS = ('moving', 'follow', 'fixed')


@dataclass(frozen=True)
class VisualLiftingParameters:
    """Parameters of the visual-lifting law (defaults: model-spec §6 and §11).

    :param kp: K_p = diag(k_y [N/m], k_z [N/m], k_pitch [N m/rad]) on psi = (y, z, pitch);
        seed eq. (9): (20, 290, 1100), order and SI units per model-spec §6/§11 #6.
    :param joints: joints that receive the torque (seed §5.2: 1, 2, 3, 4, 8, 9, 10, 17); a
        joint gets torque only while its coordinate is active in the mode.
    :param joint1_torque: apply the joint-1 (floor pivot) entry while q1 is active
        (model-spec §3.3 / §11 #18 switch).
    :param desired_y: forward target y_d: 'moving' y_H(0) + v_d t, 'follow' y_H(t) (forward
        term off), 'fixed' y_H(0) (model-spec §6, §11 #7).
    :param v_d: forward speed of the 'moving' target [m/s] (model-spec §6: 0.3).
    :param z_d: target head-top height [m]; None means the initial height z_H(0).
    :param pitch_d: target head pitch [rad] (model-spec §6: 0).
    :param max_dy: saturation of |delta y| [m] (model-spec §11 #24: 0.3); None disables it.
    """

    kp: tuple[float, float, float] = (20.0, 290.0, 1100.0)
    joints: tuple[int, ...] = (1, 2, 3, 4, 8, 9, 10, 17)
    joint1_torque: bool = True
    desired_y: str = 'moving'
    v_d: float = 0.3
    z_d: float | None = None
    pitch_d: float = 0.0
    max_dy: float | None = 0.3

    def __post_init__(self) -> None:
        """Validate and normalise every field (raises VisualLiftingError naming the key)."""
        kp = _sequence('kp', self.kp)
        if len(kp) != 3:
            raise VisualLiftingError(f'kp must have 3 entries (y, z, pitch), got {len(kp)}')
        kp = tuple(_real('kp', k, low=0.0) for k in kp)
        joints = _sequence('joints', self.joints)
        checked = []
        for j in joints:
            if isinstance(j, bool) or not isinstance(j, numbers.Integral) or not 1 <= j <= 17:
                raise VisualLiftingError(f'joints entries must be integers in 1..17, got {j!r}')
            checked.append(int(j))
        if len(set(checked)) != len(checked):
            raise VisualLiftingError(f'joints must not repeat a joint, got {checked}')
        if not isinstance(self.joint1_torque, bool):
            raise VisualLiftingError(f'joint1_torque must be a bool, got {self.joint1_torque!r}')
        if self.desired_y not in DESIRED_Y_OPTIONS:
            raise VisualLiftingError(
                f'desired_y must be one of {DESIRED_Y_OPTIONS}, got {self.desired_y!r}')
        z_d = None if self.z_d is None else _real('z_d', self.z_d, low=0.0, open_low=True)
        max_dy = (None if self.max_dy is None
                  else _real('max_dy', self.max_dy, low=0.0, open_low=True))
        object.__setattr__(self, 'kp', kp)
        object.__setattr__(self, 'joints', tuple(checked))
        object.__setattr__(self, 'v_d', _real('v_d', self.v_d))
        object.__setattr__(self, 'z_d', z_d)
        object.__setattr__(self, 'pitch_d', _real('pitch_d', self.pitch_d))
        object.__setattr__(self, 'max_dy', max_dy)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> VisualLiftingParameters:
        """Build from a mapping (e.g. YAML); unknown keys and bad values raise an error."""
        if not isinstance(d, Mapping):
            raise VisualLiftingError(f'visual-lifting parameters must be a mapping, got {d!r}')
        known = {f.name for f in fields(cls)}
        for key in d:
            if key not in known:
                raise VisualLiftingError(
                    f'unknown visual-lifting parameter {key!r}; expected one of {sorted(known)}')
        return cls(**dict(d))


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
        shift (model-spec §14.4). 'follow' ignores dy: its forward error is zero by definition.
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


def visual_lifting(obs: Observation, dynamics: GaitDynamics, params: VisualLiftingParameters,
                   psi_initial: np.ndarray, offset: Sequence[float] = (0.0, 0.0)) -> HeadTask:
    """Evaluate the whole law once (one head-pose computation): torque, psi, psi_d, error."""
    psi, jac = dynamics.head_pose(obs.contact(), obs.q)
    psi_d = desired_head_pose(params, obs.t, psi, psi_initial, offset)
    tau = visual_lifting_torque(obs, dynamics, params, psi_d, pose=(psi, jac))
    return HeadTask(tau, psi, psi_d, head_error(psi_d, psi, params))


def _sequence(name: str, value: Any) -> tuple[Any, ...]:
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise VisualLiftingError(f'{name} must be a list, got {value!r}')
    return tuple(value)


def _real(name: str, value: Any, low: float | None = None, open_low: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise VisualLiftingError(f'{name} must be a number, got {value!r}')
    x = float(value)
    if not math.isfinite(x):
        raise VisualLiftingError(f'{name} must be finite, got {value!r}')
    if low is not None and (x < low or (open_low and x == low)):
        bound = '>' if open_low else '>='
        raise VisualLiftingError(f'{name} must be {bound} {low}, got {value!r}')
    return x
