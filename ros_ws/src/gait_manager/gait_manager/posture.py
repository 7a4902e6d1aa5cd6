"""Posture stabiliser (docs/model.md, posture stabiliser), ROS-free.

Visual lifting alone cannot hold the robot up: its 3-row task leaves a null space (knee squat,
trunk folding, ...) unstable. This term adds, as its own switchable source,

    tau_post = N^T [K_q (q_ref - q) - B_q dq]  on the driven joints (default 2, 3, 4, 9, 10)
             + g(q)                            on the gravity joints (default the same; switch)
             - K_8 q_8 - B_8 dq_8              on the torso yaw (centring spring)

with N^T = I - J_H^T (J_H^+)^T over the driven joints when the null-space projection is on
(default off), else I. The neck (17) is left out by default: its PD cancels visual lifting there.

Reference posture q_ref:
* 'standing': the bent-knee posture q2..q7 = (-a, 2a, -a, a, -2a, a), a = 0.05 rad;
* 'moving', the moving stance: the pelvis centre follows a target that starts at the
  standing posture's position over the support ankle at t_e, moves +dy1 forward and dz1 down
  over T1 (smoothstep), then a further +dy2 over T2 after the heel strike t_touchdown
  (``iceskate_sim.stance``). The support leg angles q2, q3, q4 come from a planar 2-link IK
  (ankle -> hip, shank 0.40 m, thigh 0.38 m, read from the model) with the knee forward
  (q3 >= 0) and the pelvis pitch phi_4 = q1 + q2 + q3 + q4 held at its reference; the ankle
  position uses the current y0 and q1. Torso, arms and neck go to 0 (trunk upright), the swing
  leg to the standing posture. The same shift (dy, -dz) is returned as a head offset so that
  visual lifting's y_d, z_d move with the stance.
Entries 0 and 1 of q_ref copy the current y0 and q1 (not driven), so forward kinematics of q_ref
puts the pelvis centre on the target.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math
from typing import Any, NamedTuple

import numpy as np

from gait_manager._params import zeros
from gait_manager.errors import GaitManagerError
from iceskate_sim.command import JointCommand
from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.observation import Observation
from iceskate_sim.parameters import check_fields, from_mapping, setting
from iceskate_sim.robot import SupportModel
from iceskate_sim.stance import StanceSchedule

REFERENCES = ('moving', 'standing', 'balance')
YAW_JOINT = 8


@dataclass(frozen=True)
class PostureParameters:
    """Parameters of the posture stabiliser and its stance reference (docs/model.md, posture
    stabiliser). Each field's description, unit and range are its ``setting``."""

    reference: str = setting(
        'moving', "reference posture: 'moving' stance, fixed 'standing' posture, or 'balance' "
        '(the walking stabiliser of the balance block; only the yaw spring of this block is '
        'used then)', choices=REFERENCES)
    joints: tuple[int, ...] = setting(
        (2, 3, 4, 9, 10), 'joints driven by the PD (stance 2, 3, 4; torso 9, 10; not the neck)',
        low=2, high=17, distinct=True)
    stiffness: float = setting(800.0, 'K_q of the PD (400 also works, 200 is too weak)',
                               unit='N m/rad', low=0.0)
    damping: float = setting(16.0, 'B_q of the PD', unit='N m s/rad', low=0.0)
    gravity_compensation: bool = setting(True, 'add the gravity torque g(q) on gravity_joints')
    gravity_joints: tuple[int, ...] = setting(
        (2, 3, 4, 9, 10), 'joints that get g(q) (stance and torso; never the swing leg in the '
        'air: it throws the leg up)', low=2, high=17, distinct=True)
    yaw_stiffness: float = setting(20.0, 'K_8 of the torso-yaw centring spring', unit='N m/rad',
                                   low=0.0)
    yaw_damping: float = setting(2.0, 'B_8 of the torso-yaw centring spring', unit='N m s/rad',
                                 low=0.0)
    null_space: bool = setting(False, 'project the PD into the null space of the head Jacobian '
                               'J_H over the driven joints')
    bend: float = setting(0.05, 'knee bend a of the bent-knee standing posture', unit='rad',
                          low=0.0, high=0.5)
    pelvis_pitch: float = setting(0.0, 'pelvis pitch phi_4 = q1 + q2 + q3 + q4 kept by the '
                                  "'moving' reference", unit='rad', low=-0.8, high=0.8)
    shift_y1: float = setting(0.10, 'forward hip shift dy1 after the support exchange',
                              unit='m', low=-0.4, high=0.4)
    shift_z1: float = setting(0.03, 'downward hip shift dz1 after the support exchange',
                              unit='m', low=-0.1, high=0.3)
    shift_time1: float = setting(0.6, 'duration T1 of the first shift', unit='s', low=0.0)
    shift_y2: float = setting(0.10, 'further forward hip shift dy2 after the heel strike',
                              unit='m', low=-0.4, high=0.4)
    shift_time2: float = setting(0.5, 'duration T2 of the second shift', unit='s', low=0.0)

    def __post_init__(self) -> None:
        """Check and normalise every field (GaitManagerError naming the key)."""
        check_fields(self, GaitManagerError)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> PostureParameters:
        """Build from a mapping; unknown keys and bad values raise GaitManagerError."""
        return from_mapping(cls, d, GaitManagerError, 'posture.')

    @property
    def stance(self) -> StanceSchedule:
        """The moving stance schedule of the shift_* fields."""
        return StanceSchedule(self.shift_y1, self.shift_z1, self.shift_time1, self.shift_y2,
                              self.shift_time2)


class StanceReference(NamedTuple):
    """q_ref (18 entries [m, rad]) and the head offset (dy, dz) [m] for visual lifting."""

    q_ref: np.ndarray
    head_offset: np.ndarray


def standing_posture(params: PostureParameters) -> np.ndarray:
    """The bent-knee standing posture as an 18-vector (y0 = q1 = 0)."""
    a = params.bend
    q = zeros()
    q[2:8] = (-a, 2.0 * a, -a, a, -2.0 * a, a)
    return q


def stance_shift(obs: Observation, params: PostureParameters) -> np.ndarray:
    """(dy, dz) [m] of the moving pelvis target relative to the standing posture (dz < 0 is
    down): +dy1, -dz1 over T1 after t_e, then +dy2 over T2 after t_touchdown."""
    return params.stance.shift(obs)


def _rot(angle: float, v: np.ndarray) -> np.ndarray:
    """Rotate a (y, z) vector by a pitch ``angle`` (about +x; positive tilts +z towards -y)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


class _LegGeometry(NamedTuple):
    base: np.ndarray  # (y, z) of the y0 joint at y0 = 0
    pivot: np.ndarray  # q1 joint relative to the base
    ankle: np.ndarray  # q2 joint relative to the pivot
    shank: np.ndarray  # q3 (knee) relative to the ankle
    thigh: np.ndarray  # q4 (hip) relative to the knee
    pelvis: np.ndarray  # pelvis_centre frame relative to the hip


_GEOMETRY: dict[int, tuple[SupportModel, _LegGeometry]] = {}


def _geometry(obs: Observation, dynamics: GaitDynamics) -> _LegGeometry:
    """Support-leg geometry of the model rooted at ``obs``'s support foot and pivot (read from
    the model once; the model stays referenced so that its id stays unique)."""
    sm = dynamics.robot.support_model(obs.side, obs.pivot)
    entry = _GEOMETRY.get(id(sm))
    if entry is not None and entry[0] is sm:
        return entry[1]
    model = sm.model

    def placement(name: str) -> np.ndarray:
        return model.jointPlacements[model.getJointId(name)].translation[1:].copy()

    pelvis = model.frames[sm.frame_ids['pelvis_centre']].placement.translation[1:].copy()
    geo = _LegGeometry(placement('y0'), placement('q1'), placement('q2'), placement('q3'),
                       placement('q4'), pelvis)
    _GEOMETRY[id(sm)] = (sm, geo)
    return geo


def _support_ankle(geo: _LegGeometry, q: np.ndarray,
                   q1_active: bool) -> tuple[np.ndarray, float]:
    """World (y, z) of the support ankle, and the q1 used (0 when q1 is locked)."""
    q1 = float(q[1]) if q1_active else 0.0
    pivot = geo.base + np.array([q[0], 0.0]) + geo.pivot
    return pivot + _rot(q1, geo.ankle), q1


def hip_target(obs: Observation, dynamics: GaitDynamics, params: PostureParameters
               ) -> np.ndarray:
    """World (y, z) [m] of the pelvis-centre target of the moving stance reference."""
    geo = _geometry(obs, dynamics)
    a = params.bend
    flat_ankle = geo.base + np.array([obs.q[0], 0.0]) + geo.pivot + geo.ankle
    knee = flat_ankle + _rot(-a, geo.shank)
    hip = knee + _rot(a, geo.thigh)
    standing = hip + _rot(0.0, geo.pelvis)
    return standing + stance_shift(obs, params)


def _angle(v: np.ndarray) -> float:
    """Pitch angle beta of a (y, z) vector: v = |v| (-sin beta, cos beta)."""
    return math.atan2(-v[0], v[1])


def support_leg_ik(obs: Observation, dynamics: GaitDynamics, params: PostureParameters,
                   target: np.ndarray) -> tuple[float, float, float]:
    """(q2, q3, q4) [rad] putting the pelvis centre on ``target`` (world y, z) with the knee
    forward and phi_4 = ``params.pelvis_pitch``. An unreachable target gives the straight (or
    fully folded) leg pointing at it."""
    geo = _geometry(obs, dynamics)
    ankle, q1 = _support_ankle(geo, obs.q, obs.gait_mode.q1_active)
    hip = np.asarray(target, dtype=float) - _rot(params.pelvis_pitch, geo.pelvis)
    d = hip - ankle
    l2, l3 = float(np.hypot(*geo.shank)), float(np.hypot(*geo.thigh))
    b2, b3 = _angle(geo.shank), _angle(geo.thigh)
    cos_gamma = (d @ d - l2 * l2 - l3 * l3) / (2.0 * l2 * l3)
    gamma = math.acos(min(max(cos_gamma, -1.0), 1.0))  # thigh relative to shank, >= 0
    shank_dir = _angle(d) - math.atan2(l3 * math.sin(gamma), l2 + l3 * math.cos(gamma))
    phi2 = shank_dir - b2
    q3 = gamma - b3 + b2
    q2 = phi2 - q1
    q4 = params.pelvis_pitch - phi2 - q3
    return q2, q3, q4


def stance_reference(obs: Observation, dynamics: GaitDynamics,
                     params: PostureParameters) -> StanceReference:
    """Return q_ref and the head offset (dy, dz) [m] of the stance reference (see module)."""
    q_ref = standing_posture(params)
    q_ref[0] = obs.q[0]
    q_ref[1] = obs.q[1] if obs.gait_mode.q1_active else 0.0
    if params.reference != 'moving':
        return StanceReference(q_ref, np.zeros(2))
    target = hip_target(obs, dynamics, params)
    q_ref[2:5] = support_leg_ik(obs, dynamics, params, target)
    return StanceReference(q_ref, stance_shift(obs, params))


def posture_command(obs: Observation, dynamics: GaitDynamics,
                    params: PostureParameters) -> JointCommand:
    """The posture stabiliser as a joint command: gravity compensation as feed-forward and the
    PD (stance reference, yaw centring spring) as a joint impedance that the simulator runs at
    its physics rate. With ``null_space`` the PD depends on J_H(q), so it is sent as a torque
    held over the control period instead."""
    if params.null_space:
        return JointCommand(posture_torque(obs, dynamics, params))
    effort = zeros()
    stiffness, damping, reference = zeros(), zeros(), zeros()
    if params.joints:
        idx = list(params.joints)
        reference[idx] = stance_reference(obs, dynamics, params).q_ref[idx]
        stiffness[idx] = params.stiffness
        damping[idx] = params.damping
    if params.gravity_compensation and params.gravity_joints:
        g = zeros()
        g[obs.gait_mode.active] = dynamics.gravity_terms(obs.contact(), obs.q)
        idx = list(params.gravity_joints)
        effort[idx] += g[idx]
    stiffness[YAW_JOINT] += params.yaw_stiffness
    damping[YAW_JOINT] += params.yaw_damping
    if not np.all(np.isfinite(effort)) or not np.all(np.isfinite(reference)):
        raise GaitManagerError(f'posture command is not finite at t = {obs.t}')
    return JointCommand(effort, stiffness, damping, reference)


def posture_torque(obs: Observation, dynamics: GaitDynamics,
                   params: PostureParameters) -> np.ndarray:
    """Return tau_post [N m] (see module docstring)."""
    tau = zeros()
    contact = obs.contact()
    if params.joints:
        idx = list(params.joints)
        q_ref = stance_reference(obs, dynamics, params).q_ref
        pd = params.stiffness * (q_ref[idx] - obs.q[idx]) - params.damping * obs.v[idx]
        if params.null_space:
            _psi, jac = dynamics.head_pose(contact, obs.q)
            jd = jac[:, idx]
            pd = pd - jd.T @ (np.linalg.pinv(jd, rcond=1e-10).T @ pd)
        tau[idx] = pd
    if params.gravity_compensation and params.gravity_joints:
        g = zeros()
        g[obs.gait_mode.active] = dynamics.gravity_terms(contact, obs.q)
        idx = list(params.gravity_joints)
        tau[idx] += g[idx]
    tau[YAW_JOINT] -= (params.yaw_stiffness * obs.q[YAW_JOINT]
                       + params.yaw_damping * obs.v[YAW_JOINT])
    if not np.all(np.isfinite(tau)):
        raise GaitManagerError(f'posture torque is not finite at t = {obs.t}')
    return tau
