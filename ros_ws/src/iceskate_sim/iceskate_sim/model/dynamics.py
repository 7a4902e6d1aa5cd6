"""The humanoid's model terms in every Table 2 gait mode (SI units): ``ModelTerms`` (M, h, g,
constraint rows, frames, the head-top pose and its Jacobian), ``DynamicsParameters`` and
``DynamicsResult``, the answer of eq. (7), which runs in C++. See docs/model.md §4 and
docs/architecture.md, 'The native core and its test oracle'.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from iceskate_native.parameters import checked, setting
from iceskate_sim.errors import InputRefused
from iceskate_sim.model.modes import GaitMode
from iceskate_sim.model.robot import N_COORDINATES, Q1, Y0, Robot

_LWA = pin.LOCAL_WORLD_ALIGNED
_LEG_CHAIN = slice(1, 8)  # q1..q7: the swing-sole pitch C_fr = q0 + q1 + ... + q7 (q0 = 0)


@dataclass(frozen=True)
class DynamicsParameters:
    """Physical options of the contact and joint model (a scene's ``dynamics``, whose ``mu`` is
    the floor's)."""

    mu: float = setting(0.005, 'Coulomb coefficient of a sliding foot', low=0.0, high=2.0)
    baumgarte: float = setting(0.0, 'Baumgarte constant of the swing constraints', unit='1/s',
                               low=0.0, high=1e4)
    joint_limits: bool = setting(True, 'soft joint stops on (docs/model.md §2.6)')
    limit_stiffness: float = setting(1e4, 'stiffness of a soft stop', unit='N m/rad', low=0.0,
                                     high=1e7)
    limit_damping: float = setting(100.0, 'damping of a soft stop (while it is penetrated)',
                                   unit='N m s/rad', low=0.0, high=1e5)
    damping: bool = setting(True, 'joint damping of Table 1 on')
    __post_init__ = checked(InputRefused)


@dataclass
class ContactState:
    """The discrete part of the hybrid state besides the mode number.

    :param mode: the Table 2 mode.
    :param side: support side, 'right' (a = 0) or 'left' (a = 1).
    :param pivot: edge of the support sole that q1 turns about, 'toe' or 'heel'.
    :param heel_anchor_y: y_h* [m], the world y the swing heel is pinned at (C_hy).
    :param support_slide_dir: sgn(yd0) of a gliding support foot (+1 on ice).
    :param heel_slide_dir: sgn(yd_h) of a sliding swing heel (+1 on ice).
    """

    mode: GaitMode
    side: str = 'right'
    pivot: str = 'toe'
    heel_anchor_y: float = 0.0
    support_slide_dir: float = 1.0
    heel_slide_dir: float = 1.0


@dataclass
class DynamicsResult:
    """Solution of eq. (7) at one state.

    :ivar qdd: accelerations of all 18 coordinates (0 for locked ones) [rad/s^2, m/s^2].
    :ivar multipliers: (f_nz [N], f_ny [N], tau_n [N m]); 0 where inactive.
    :ivar support_wrench: floor wrench on the support foot, world-aligned, at the point
        (x_support, y0, 0): (F_x, F_y, F_z [N], M_x, M_y, M_z [N m]).
    :ivar support_normal: N_s [N], vertical floor reaction on the support foot.
    :ivar support_friction: F_y [N], floor force on the support foot along y.
    :ivar zmp_y: world y [m] of the support foot's centre of pressure (nan if N_s <= 0).
    :ivar heel_friction: friction force on a sliding swing heel along y [N] (0 otherwise).
    :ivar applied: generalized force applied besides the constraints: inputs, damping and
        soft stops, per coordinate [N m, N].
    :ivar swing_heel: world position of the swing heel point [m].
    :ivar swing_heel_velocity: world velocity of the swing heel point [m/s].
    :ivar swing_toe_z: height of the swing toe point [m].
    :ivar passive: joint damping and soft-stop torques (part of ``applied``) [N m].
    """

    qdd: np.ndarray
    multipliers: np.ndarray
    support_wrench: np.ndarray
    support_normal: float
    support_friction: float
    zmp_y: float
    heel_friction: float
    applied: np.ndarray = field(repr=False)
    swing_heel: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(3))
    swing_heel_velocity: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(3))
    swing_toe_z: float = 0.0
    passive: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(18))


class ModelTerms:
    """Model terms and derived quantities of the humanoid in a mode.

    Holds one Pinocchio data object per support model, so an instance is not thread-safe;
    make one per thread.
    """

    def __init__(self, robot: Robot, params: DynamicsParameters | None = None) -> None:
        self.robot = robot
        self.params = params or DynamicsParameters()
        self._data: dict[tuple[str, str], pin.Data] = {}  # made at a model's first use
        self._zeros = np.zeros(N_COORDINATES)
        self._lower = np.tril_indices(N_COORDINATES, -1)

    # ----------------------------------------------------------------- helpers
    def _model(self, contact: ContactState) -> tuple[pin.Model, pin.Data, dict[str, int]]:
        sm = self.robot.support_model(contact.side, contact.pivot)
        key = (sm.side, sm.pivot)
        data = self._data.get(key)
        if data is None:
            data = self._data[key] = sm.new_data()
        return sm.model, data, sm.frame_ids

    def _constraint_rows(self, contact: ContactState, data: pin.Data, model: pin.Model,
                         frames: dict[str, int], q: np.ndarray,
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Active constraint rows J (nc x 18), velocity products Jdot v, positions C(q) and
        the y row of the swing-heel Jacobian (the friction direction).

        Needs ``computeJointJacobians`` (or ``computeAllTerms``) and
        ``forwardKinematics(q, v, 0)`` on ``data``. Columns of locked coordinates are 0.
        """
        constraints = contact.mode.constraints
        nc = len(constraints)
        rows = np.zeros((nc, N_COORDINATES))
        drift = np.zeros(nc)
        position = np.zeros(nc)
        if nc == 0:
            return rows, drift, position, np.zeros(N_COORDINATES)
        heel = frames['swing_heel']
        jac = pin.getFrameJacobian(model, data, heel, _LWA)
        acc = pin.getFrameClassicalAcceleration(model, data, heel, _LWA).linear
        heel_position = pin.updateFramePlacement(model, data, heel).translation
        for k, name in enumerate(constraints):
            if name == 'hz':
                rows[k] = jac[2]
                drift[k] = acc[2]
                position[k] = heel_position[2]
            elif name == 'hy':
                rows[k] = jac[1]
                drift[k] = acc[1]
                position[k] = heel_position[1] - contact.heel_anchor_y
            else:  # 'fr'
                rows[k, _LEG_CHAIN] = 1.0
                position[k] = q[_LEG_CHAIN].sum()
        heel_y_row = jac[1].copy()
        locked = locked_coordinates(contact.mode)
        rows[:, locked] = 0.0
        heel_y_row[locked] = 0.0
        return rows, drift, position, heel_y_row

    # ------------------------------------------------------ derived quantities
    def mass_matrix(self, contact: ContactState, q: np.ndarray) -> np.ndarray:
        """M(q) over the active coordinates of ``contact.mode`` (symmetric) [kg m^2]."""
        model, data, _ = self._model(contact)
        M = pin.crba(model, data, q).copy()
        M[self._lower] = M.T[self._lower]
        act = contact.mode.active
        return M[np.ix_(act, act)]

    def gravity_terms(self, contact: ContactState, q: np.ndarray) -> np.ndarray:
        """g(q) over the active coordinates [N m]."""
        model, data, _ = self._model(contact)
        return pin.computeGeneralizedGravity(model, data, q)[contact.mode.active].copy()

    def bias_terms(self, contact: ContactState, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """h(q, qd): Coriolis and centrifugal terms over the active coordinates [N m]."""
        model, data, _ = self._model(contact)
        g = pin.computeGeneralizedGravity(model, data, q).copy()
        return (pin.nonLinearEffects(model, data, q, v) - g)[contact.mode.active].copy()

    def head_pose(self, contact: ContactState, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Head-top pose psi = (y [m], z [m], pitch [rad]) and its Jacobian J_H (3 x 18).

        Pitch is the angle of the head z axis in the world y-z plane (positive tilts the head
        back); the Jacobian's pitch row is the exact derivative of that angle, so
        ``J_H = d psi / d q`` (columns of locked coordinates are zero).
        """
        model, data, frames = self._model(contact)
        fid = frames['head_top']
        pin.computeJointJacobians(model, data, q)
        placement = pin.updateFramePlacement(model, data, fid)
        jac = pin.getFrameJacobian(model, data, fid, _LWA)
        zx, zy, zz = placement.rotation[:, 2]
        denom = zy * zy + zz * zz
        pitch_row = np.array([1.0, -zx * zy / denom, -zx * zz / denom]) @ jac[3:]
        psi = np.array([placement.translation[1], placement.translation[2],
                        float(np.arctan2(-zy, zz))])
        jac_h = np.vstack([jac[1], jac[2], pitch_row])
        jac_h[:, locked_coordinates(contact.mode)] = 0.0
        return psi, jac_h

    def frame_placement(self, contact: ContactState, q: np.ndarray, name: str) -> pin.SE3:
        """World placement of a named frame of the support model."""
        model, data, frames = self._model(contact)
        pin.forwardKinematics(model, data, q)
        return pin.updateFramePlacement(model, data, frames[name]).copy()

    def energy(self, contact: ContactState, q: np.ndarray, v: np.ndarray) -> tuple[float, float]:
        """Kinetic and potential energy [J] (potential zero at z = 0)."""
        model, data, _ = self._model(contact)
        kinetic = pin.computeKineticEnergy(model, data, q, v)
        potential = pin.computePotentialEnergy(model, data, q)
        return float(kinetic), float(potential)

    def constraint_jacobian(self, contact: ContactState, q: np.ndarray) -> np.ndarray:
        """Rows of the active swing constraints (nc x 18; locked columns 0)."""
        model, data, frames = self._model(contact)
        pin.forwardKinematics(model, data, q, self._zeros, self._zeros)
        pin.computeJointJacobians(model, data, q)
        return self._constraint_rows(contact, data, model, frames, q)[0]


def locked_coordinates(mode: GaitMode) -> list[int]:
    """The coordinates ``mode`` locks (y0 of a stuck support, q1 of a flat sole)."""
    locked = []
    if not mode.y0_active:
        locked.append(Y0)
    if not mode.q1_active:
        locked.append(Q1)
    return locked
