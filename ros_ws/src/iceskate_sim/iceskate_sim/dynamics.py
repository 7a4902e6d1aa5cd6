"""Constrained equations of motion of every Table 2 gait mode (the paper's eq. 7).

One routine serves all 20 modes: the mode (``iceskate_sim.modes``) says which of the 18
coordinates ``[y0, q1, ..., q17]`` are active and which swing-foot constraints act; the locked
coordinates keep their value and have zero velocity. For the active coordinates ``a`` and the
active constraint rows ``J`` it solves

    [ M_aa + F_sup   -(J^T + friction columns) ] [ qdd_a  ]   [ tau_a - h_a - g_a - D qd_a + ... ]
    [ J               0                        ] [ lambda ] = [ -Jdot qd (- Baumgarte)           ]

with Coulomb friction on a sliding swing heel (f_t = mu f_nz against the heel velocity) and on a
gliding support foot (F_y = -mu sgn(yd0) N_s, N_s from the vertical momentum balance, model-spec
4.4), which makes the matrix non-symmetric. Everything runs on Pinocchio's C++ algorithms
(computeAllTerms, forwardKinematics for the velocity-product terms, RNEA for the support wrench).

Units: SI (m, rad, s, kg, N, N m).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from iceskate_sim.errors import SimulationError
from iceskate_sim.modes import MULTIPLIER_NAMES, GaitMode
from iceskate_sim.robot import (
    GRAVITY,
    JOINT_LIMITS,
    N_COORDINATES,
    PIVOT_Y,
    Q1,
    SIDES,
    SOLE_HEEL_Y,
    SOLE_TOE_Y,
    Y0,
    Robot,
)

_LWA = pin.LOCAL_WORLD_ALIGNED
_LEG_CHAIN = slice(1, 8)  # q1..q7: the swing-sole pitch C_fr = q0 + q1 + ... + q7 (q0 = 0)
_F_NZ, _F_NY, _TAU_N = 0, 1, 2
_RANK_TOLERANCE = 1e-10  # Hadamard ratio of the constraint Gram matrix below which it is singular


@dataclass(frozen=True)
class DynamicsParameters:
    """Physical options of the contact and joint model.

    :param mu: Coulomb coefficient of a sliding foot (ice: 0.005, forward sliding only).
    :param baumgarte: Baumgarte constant alpha [1/s] of the swing constraints (0: off).
    :param joint_limits: apply the soft stops of model-spec 9.2.
    :param limit_stiffness: soft-stop stiffness [N m/rad].
    :param limit_damping: soft-stop damping [N m s/rad] (acts only while a stop is penetrated).
    :param damping: apply the joint damping of Table 1.
    """

    mu: float = 0.005
    baumgarte: float = 0.0
    joint_limits: bool = True
    limit_stiffness: float = 1.0e4
    limit_damping: float = 100.0
    damping: bool = True


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
    :ivar support_tangential: F_y [N], floor force on the support foot along y.
    :ivar cop_y: world y [m] of the support foot's centre of pressure (nan if N_s <= 0).
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
    support_tangential: float
    cop_y: float
    heel_friction: float
    applied: np.ndarray = field(repr=False)
    swing_heel: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(3))
    swing_heel_velocity: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(3))
    swing_toe_z: float = 0.0
    passive: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(18))

    def multiplier(self, name: str) -> float:
        """Return the multiplier called ``name`` ('f_nz', 'f_ny' or 'tau_n')."""
        return float(self.multipliers[MULTIPLIER_NAMES.index(name)])


def check_state(q: np.ndarray, v: np.ndarray, where: str = 'state') -> tuple[np.ndarray,
                                                                            np.ndarray]:
    """Return ``q``, ``v`` as float arrays of length 18, or raise SimulationError."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    for name, x in (('q', q), ('v', v)):
        if x.shape != (N_COORDINATES,):
            raise SimulationError(
                f'{where}: {name} must have {N_COORDINATES} entries [y0, q1..q17], '
                f'got shape {x.shape}')
        if not np.all(np.isfinite(x)):
            bad = [i for i in range(N_COORDINATES) if not np.isfinite(x[i])]
            raise SimulationError(f'{where}: {name} has non-finite entries at indices {bad}')
    return q, v


class GaitDynamics:
    """Per-mode dynamics and derived quantities of the humanoid.

    Holds one Pinocchio data object per support model, so an instance is not thread-safe;
    make one per thread.
    """

    def __init__(self, robot: Robot, params: DynamicsParameters | None = None) -> None:
        self.robot = robot
        self.params = params or DynamicsParameters()
        self._data = {key: sm.new_data() for key, sm in robot.models.items()}
        self._zeros = np.zeros(N_COORDINATES)
        self._damping = robot.damping if self.params.damping else np.zeros(N_COORDINATES)
        limits = sorted(JOINT_LIMITS.items())
        self._limit_index = np.array([i for i, _ in limits], dtype=np.intp)
        self._limit_lower = np.array([lo for _, (lo, _hi) in limits])
        self._limit_upper = np.array([hi for _, (_lo, hi) in limits])
        self._mass = robot.total_mass
        self._lower = np.tril_indices(N_COORDINATES, -1)

    # ----------------------------------------------------------------- helpers
    def _model(self, contact: ContactState) -> tuple[pin.Model, pin.Data, dict[str, int]]:
        key = (contact.side, contact.pivot)
        sm = self.robot.models.get(key)
        if sm is None:
            raise SimulationError(f'unknown support side/pivot {key}; sides {SIDES}')
        return sm.model, self._data[key], sm.frame_ids

    def passive_forces(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Joint damping and soft-stop torques for all 18 coordinates [N m]."""
        force = -self._damping * v
        if self.params.joint_limits:
            idx = self._limit_index
            below = np.minimum(q[idx] - self._limit_lower, 0.0)
            above = np.maximum(q[idx] - self._limit_upper, 0.0)
            penetration = below + above
            engaged = penetration != 0.0
            force[idx] -= (self.params.limit_stiffness * penetration
                           + self.params.limit_damping * v[idx] * engaged)
        return force

    def _limit_damping_engaged(self, q: np.ndarray) -> np.ndarray:
        """Soft-stop damping of the stops engaged at q (18,) [N m s/rad]."""
        out = np.zeros(N_COORDINATES)
        if self.params.joint_limits:
            idx = self._limit_index
            engaged = (q[idx] < self._limit_lower) | (q[idx] > self._limit_upper)
            out[idx] = self.params.limit_damping * engaged
        return out

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
        locked = _locked(contact.mode)
        rows[:, locked] = 0.0
        heel_y_row[locked] = 0.0
        return rows, drift, position, heel_y_row

    # ------------------------------------------------------------- main routine
    def evaluate(self, contact: ContactState, q: np.ndarray, v: np.ndarray,
                 tau: np.ndarray, push: tuple[str, np.ndarray] | None = None,
                 stiffness: np.ndarray | None = None, damping: np.ndarray | None = None,
                 implicit_step: float = 0.0) -> DynamicsResult:
        """Solve eq. (7) of ``contact.mode`` at (q, v) under input torques ``tau``.

        :param contact: mode, support side, pivot and contact anchors.
        :param q: coordinates [y0, q1..q17] (m, rad), length 18; locked entries are held.
        :param v: velocities, length 18; entries of locked coordinates must be 0.
        :param tau: input generalized forces, length 18 (y0 entry ignored: unactuated; q1
            entry applied only while q1 is active).
        :param push: optional external force (link frame name, world force [N] (3,)) acting
            at that frame's origin, e.g. a push on the chest.
        :param stiffness: joint-impedance stiffness K (18,) [N m/rad]: adds -K q (the K q_ref
            part belongs in ``tau``).
        :param damping: joint-impedance damping B (18,) [N m s/rad]: adds -B v.
        :param implicit_step: h > 0 returns the acceleration of a step of size h with joint,
            impedance and soft-stop damping taken implicitly, (M + h D) a = f - D v (MuJoCo's
            implicitfast idea); 0 gives the exact acceleration.
        :raises SimulationError: on malformed input or a rank-deficient constraint set.
        """
        mode = contact.mode
        model, data, frames = self._model(contact)
        q, v = check_state(q, v, f'mode {mode.number} dynamics')
        tau = np.asarray(tau, dtype=float)
        if tau.shape != (N_COORDINATES,) or not np.all(np.isfinite(tau)):
            raise SimulationError(f'mode {mode.number} dynamics: tau must be {N_COORDINATES} '
                                  f'finite values, got shape {tau.shape}')
        locked = _locked(mode)
        if np.any(v[locked] != 0.0):
            raise SimulationError(f'mode {mode.number} dynamics: locked coordinates '
                                  f'{locked} must have zero velocity, got {v[locked]}')
        act = mode.active
        n = act.size
        nc = len(mode.constraints)
        mu = self.params.mu

        pin.computeAllTerms(model, data, q, v)
        pin.forwardKinematics(model, data, q, v, self._zeros)  # data.a = velocity products
        M = data.M
        M[self._lower] = M.T[self._lower]
        passive = self.passive_forces(q, v)
        applied = passive.copy()
        applied[1:] += tau[1:]
        if stiffness is not None:
            applied[1:] -= stiffness[1:] * q[1:] + damping[1:] * v[1:]
        if not mode.q1_active:
            applied[Q1] = 0.0
        applied[Y0] = 0.0
        if push is not None:
            applied += pin.getFrameJacobian(model, data, frames[push[0]], _LWA)[:3].T @ push[1]

        rows, drift, position, heel_y_row = self._constraint_rows(contact, data, model,
                                                                  frames, q)
        size = n + nc
        A = np.zeros((size, size))
        b = np.zeros(size)
        A[:n, :n] = M[np.ix_(act, act)]
        b[:n] = applied[act] - data.nle[act]
        if implicit_step > 0.0:
            implicit = self._damping + self._limit_damping_engaged(q)
            if damping is not None:
                implicit = implicit + damping
            implicit[Y0] = 0.0
            A[np.arange(n), np.arange(n)] += implicit_step * implicit[act]
        force_cols = rows.copy()  # generalized-force direction of each multiplier
        if mode.swing_sliding:  # friction mu f_nz on the heel, against its velocity
            force_cols[0] -= mu * contact.heel_slide_dir * heel_y_row
        if nc:
            A[:n, n:] = -force_cols[:, act].T
            A[n:, :n] = rows[:, act]
            b[n:] = -drift
            alpha = self.params.baumgarte
            if alpha:
                b[n:] -= 2.0 * alpha * rows @ v + alpha * alpha * position
        if mode.y0_active:  # Q_sup = -mu s0 N_s, N_s = m (g + zdd_com) - f_nz
            pin.centerOfMass(model, data, pin.KinematicLevel.ACCELERATION, False)
            k = mu * contact.support_slide_dir
            A[0, :n] += k * self._mass * data.Jcom[2, act]
            b[0] -= k * self._mass * (GRAVITY + data.acom[0][2])
            if nc:
                A[0, n] -= k
        if nc:
            self._check_rank(rows[:, act], contact)
        try:
            x = np.linalg.solve(A, b)
        except np.linalg.LinAlgError as exc:
            raise SimulationError(f'mode {mode.number}: singular dynamics matrix ({exc})') from exc

        if not np.all(np.isfinite(x)):
            raise SimulationError(f'mode {mode.number} dynamics: the solution is not finite '
                                  f'(|v|max {np.max(np.abs(v)):.3g}, |q|max '
                                  f'{np.max(np.abs(q)):.3g})')
        qdd = np.zeros(N_COORDINATES)
        qdd[act] = x[:n]
        multipliers = np.zeros(3)
        for k, name in enumerate(mode.multipliers):
            multipliers[MULTIPLIER_NAMES.index(name)] = x[n + k]
        heel_friction = (-mu * contact.heel_slide_dir * multipliers[_F_NZ]
                         if mode.swing_sliding else 0.0)
        wrench = self._support_wrench(contact, model, data, frames, q, v, qdd, multipliers,
                                      heel_friction, applied, push)
        normal = float(wrench[2])
        cop_y = float(q[Y0] + wrench[3] / normal) if normal > 0.0 else float('nan')
        heel = frames['swing_heel']
        heel_position = pin.updateFramePlacement(model, data, heel).translation.copy()
        heel_velocity = pin.getFrameVelocity(model, data, heel, _LWA).linear.copy()
        toe_z = float(pin.updateFramePlacement(model, data, frames['swing_toe']).translation[2])
        return DynamicsResult(qdd, multipliers, wrench, normal, float(wrench[1]), cop_y,
                              float(heel_friction), applied, heel_position, heel_velocity, toe_z,
                              passive)

    def _check_rank(self, jac: np.ndarray, contact: ContactState) -> None:
        gram = jac @ jac.T
        diag = np.diag(gram)
        ratio = np.linalg.det(gram) / np.prod(diag) if np.all(diag > 0) else 0.0
        if ratio < _RANK_TOLERANCE:
            raise SimulationError(
                f'mode {contact.mode.number}: swing constraints {contact.mode.constraints} '
                f'are rank-deficient at this posture (Hadamard ratio {ratio:.2e}); the '
                'all-straight double-support posture is singular (model-spec 13.1)')

    def _support_wrench(self, contact: ContactState, model: pin.Model, data: pin.Data,
                        frames: dict[str, int], q: np.ndarray, v: np.ndarray, qdd: np.ndarray,
                        multipliers: np.ndarray, heel_friction: float,
                        applied: np.ndarray, push: tuple[str, np.ndarray] | None,
                        ) -> np.ndarray:
        """Floor wrench on the support foot at (x_s, y0, 0), world-aligned.

        RNEA gives the wrench the base must supply for the motion; the swing contact and any
        push supply part of it, the rest comes from the support foot.
        """
        pin.rnea(model, data, q, v, qdd)
        wrench = data.f[1].vector.copy()  # (force, moment) through the y0 joint, world-aligned
        origin = data.oMi[1].translation
        if contact.mode.constraints:
            heel = data.oMf[frames['swing_heel']].translation
            force = np.array([0.0, multipliers[_F_NY] + heel_friction, multipliers[_F_NZ]])
            wrench[:3] -= force
            wrench[3:] -= _cross(heel - origin, force)
            wrench[3] -= multipliers[_TAU_N]
        if push is not None:
            at = pin.updateFramePlacement(model, data, frames[push[0]]).translation
            wrench[:3] -= push[1]
            wrench[3:] -= _cross(at - origin, push[1])
        if contact.mode.q1_active:  # input and damping at the floor hinge act beside contact
            wrench[3] -= applied[Q1]
        return wrench

    # ------------------------------------------------------ derived quantities
    def push_force(self, contact: ContactState, q: np.ndarray,
                   push: tuple[str, np.ndarray]) -> np.ndarray:
        """Generalized force J^T f of an external force f [N] at a link frame (18,)."""
        model, data, frames = self._model(contact)
        pin.computeJointJacobians(model, data, q)
        force = pin.getFrameJacobian(model, data, frames[push[0]], _LWA)[:3].T @ push[1]
        force[_locked(contact.mode)] = 0.0
        return force

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
        z_axis = placement.rotation[:, 2]
        zx, zy, zz = z_axis
        denom = zy * zy + zz * zz
        pitch = float(np.arctan2(-zy, zz))
        pitch_row = np.array([1.0, -zx * zy / denom, -zx * zz / denom]) @ jac[3:]
        psi = np.array([placement.translation[1], placement.translation[2], pitch])
        jac_h = np.vstack([jac[1], jac[2], pitch_row])
        jac_h[:, _locked(contact.mode)] = 0.0
        return psi, jac_h

    def frame_placement(self, contact: ContactState, q: np.ndarray, name: str) -> pin.SE3:
        """World placement of a named frame of the support model."""
        model, data, frames = self._model(contact)
        pin.forwardKinematics(model, data, q)
        return pin.updateFramePlacement(model, data, frames[name]).copy()

    def frame_velocity(self, contact: ContactState, q: np.ndarray, v: np.ndarray,
                       name: str) -> pin.Motion:
        """Spatial velocity (world-aligned at the frame) of a named frame."""
        model, data, frames = self._model(contact)
        pin.forwardKinematics(model, data, q, v)
        return pin.getFrameVelocity(model, data, frames[name], _LWA).copy()

    def center_of_mass(self, contact: ContactState, q: np.ndarray) -> np.ndarray:
        """Whole-body centre of mass in the world [m]."""
        model, data, _ = self._model(contact)
        return pin.centerOfMass(model, data, q).copy()

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

    def constraint_residuals(self, contact: ContactState, q: np.ndarray,
                             v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position residuals C(q) [m, rad] and velocity residuals J qd of active constraints."""
        model, data, frames = self._model(contact)
        pin.forwardKinematics(model, data, q, v, self._zeros)
        pin.computeJointJacobians(model, data, q)
        rows, _, position, _ = self._constraint_rows(contact, data, model, frames, q)
        return position, rows @ v

    def support_polygon_y(self, contact: ContactState, q: np.ndarray) -> tuple[float, float]:
        """World y of the heel and toe edges of the support sole when it is flat [m]."""
        del contact
        return float(q[Y0] + SOLE_HEEL_Y), float(q[Y0] + SOLE_TOE_Y)

    def pivot_y(self, contact: ContactState, q: np.ndarray) -> float:
        """World y of the support pivot edge [m]."""
        return float(q[Y0] + PIVOT_Y[contact.pivot])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two 3-vectors (np.cross costs ~15 us per call)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _locked(mode: GaitMode) -> list[int]:
    locked = []
    if not mode.y0_active:
        locked.append(Y0)
    if not mode.q1_active:
        locked.append(Q1)
    return locked
