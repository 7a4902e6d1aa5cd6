"""Test oracle: the constrained equations of motion of every Table 2 gait mode (the paper's
eq. 7) as written in docs/model.md, the readable formulation the native solve
(``iceskate_native/src/dynamics.cpp``) is checked against.

One routine serves all 20 modes: the mode (``iceskate_sim.model.modes``) says which of the 18
coordinates ``[y0, q1, ..., q17]`` are active and which swing-foot constraints act; the locked
coordinates keep their value and have zero velocity. For the active coordinates ``a`` and the
active constraint rows ``J`` it solves

    [ M_aa + F_sup   -(J^T + friction columns) ] [ qdd_a  ]   [ tau_a - h_a - g_a - D qd_a + ... ]
    [ J               0                        ] [ lambda ] = [ -Jdot qd (- Baumgarte)           ]

with Coulomb friction on a sliding swing heel (f_t = mu f_nz against the heel velocity) and on a
gliding support foot (F_y = -mu sgn(yd0) N_s, N_s from the vertical momentum balance,
docs/model.md §4.4), which makes the matrix non-symmetric. The model terms are
``iceskate_sim.model.dynamics.ModelTerms``' (Pinocchio's computeAllTerms, which also leaves the
velocity-product accelerations, and RNEA for the support wrench).

Units: SI (m, rad, s, kg, N, N m).
"""

from __future__ import annotations

import functools
import math
from operator import itemgetter
from types import ModuleType

import numpy as np
import pinocchio as pin

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import all_finite
from iceskate_sim.model.dynamics import (
    ContactState,
    DynamicsParameters,
    DynamicsResult,
    ModelTerms,
    locked_coordinates,
)
from iceskate_sim.model.modes import MULTIPLIER_NAMES, GaitMode
from iceskate_sim.model.robot import (
    GRAVITY,
    JOINT_LIMITS,
    N_COORDINATES,
    PIVOT_Y,
    Q1,
    SOLE_HEEL_Y,
    SOLE_TOE_Y,
    Y0,
    Robot,
)

_LWA = pin.LOCAL_WORLD_ALIGNED
_LEG_CHAIN = slice(1, 8)  # q1..q7: the swing-sole pitch C_fr = q0 + q1 + ... + q7 (q0 = 0)
_F_NZ, _F_NY, _TAU_N = 0, 1, 2
_RANK_TOLERANCE = 1e-10  # Hadamard ratio of the constraint Gram matrix below which it is singular
_RANK_SAFE = 1e3 * _RANK_TOLERANCE  # above this the closed-form ratio needs no exact recheck
_SHAPE = (N_COORDINATES,)
_ROW_OF = {'hz': 2, 'hy': 1}  # row of the LOCAL_WORLD_ALIGNED heel Jacobian / acceleration


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


class _Plan:
    """Index maps and preallocated KKT buffers of ``evaluate`` for one (mode, side, pivot)."""

    __slots__ = ('mode', 'model', 'data', 'frames', 'heel', 'toe', 'where', 'locked', 'act',
                 'sel', 'n', 'nc', 'n_jac', 'fr_row', 'm_index', 'j_index', 'heel_y_index',
                 'pick', 'origin_x', 'A', 'b', 'A_mm', 'A_cm', 'A_jac', 'A_mc_jac', 'A_c0',
                 'A_mc0', 'A_row0', 'A_diag', 'b_top', 'assembled')

    def __init__(self, mode: GaitMode, model: pin.Model, data: pin.Data,
                 frames: dict[str, int]) -> None:
        act = np.asarray(mode.active, dtype=np.intp)
        n, nc = act.size, len(mode.constraints)
        size = n + nc
        self.mode, self.model, self.data, self.frames = mode, model, data, frames
        self.heel, self.toe = frames['swing_heel'], frames['swing_toe']
        self.where = f'mode {mode.number} dynamics'
        self.locked = locked_coordinates(mode)
        self.act, self.n, self.nc = act, n, nc
        first = int(act[0])
        contiguous = np.array_equal(act, np.arange(first, first + n))
        self.sel = slice(first, first + n) if contiguous else act  # picks the active entries
        # M_aa from the upper triangle of M, flattened in Fortran order (Pinocchio's layout)
        self.m_index = (np.maximum.outer(act, act) * N_COORDINATES
                        + np.minimum.outer(act, act))
        jac_rows = [_ROW_OF[c] for c in mode.constraints if c != 'fr']
        self.n_jac = len(jac_rows)
        self.fr_row = n + self.n_jac if 'fr' in mode.constraints else None
        # rows of the (6, 18) heel Jacobian at the active columns, flattened in C order
        self.j_index = np.array(jac_rows, dtype=np.intp)[:, None] * N_COORDINATES + act
        self.heel_y_index = N_COORDINATES + act
        # (f_nz, f_ny, tau_n) from x[n:] + [0.0]: each name's solution entry, or the 0.0
        names = mode.multipliers
        self.pick = itemgetter(*(names.index(m) if m in names else nc
                                 for m in MULTIPLIER_NAMES))
        # the root joint is y0 along world y, so its origin is (x_s, y0, 0) without reading data
        base = model.jointPlacements[1]
        plain = (model.joints[1].shortname() == 'JointModelPY' and model.parents[1] == 0
                 and np.array_equal(base.rotation, np.eye(3))
                 and base.translation[1] == 0.0 and base.translation[2] == 0.0)
        self.origin_x = float(base.translation[0]) if plain else None
        self.A = A = np.zeros((size, size))
        self.b = b = np.zeros(size)
        self.A_mm, self.A_cm = A[:n, :n], A[n:, :n]
        self.A_jac, self.A_mc_jac = A[n:n + self.n_jac, :n], A[:n, n:n + self.n_jac]
        if nc:
            self.A_c0, self.A_mc0 = A[n, :n], A[:n, n]
        self.A_row0 = A[0, :n]
        self.A_diag = A.reshape(-1)[:n * (size + 1):size + 1]
        self.b_top = b[:n]
        #: (_input_key, state terms) of the system in A, b (None: another one)
        self.assembled: tuple[tuple, _StateTerms] | None = None
        if self.fr_row is not None:  # C_fr = q0 + q1 + ... + q7: a constant row
            fr = np.zeros(N_COORDINATES)
            fr[_LEG_CHAIN] = 1.0
            A[self.fr_row, :n] = fr[act]
            A[:n, self.fr_row] = -fr[act]


class _StateTerms:
    """What ``evaluate`` needs of a state (q, v) in one plan, whatever the input: M over the
    active coordinates, the bias forces, the passive torques, the constraint rows and drifts,
    the centre-of-mass row of a gliding support, the swing-foot points. Kept for the last
    states evaluated (``GaitDynamics._STATE_CACHE``): a period evaluates the same state under
    the old and the new command, and an event search alternates two states. The arrays are
    read-only (results share them)."""

    __slots__ = ('key', 'm_aa', 'nle', 'engaged', 'passive', 'heel', 'heel_velocity', 'toe_z',
                 'rows', 'heel_y', 'drift', 'jcom', 'acom_z')

    def __init__(self, key: tuple, plan: _Plan, dynamics: GaitDynamics, q: np.ndarray,
                 v: np.ndarray, ql: list[float]) -> None:
        model, data, heel = plan.model, plan.data, plan.heel
        self.key = key
        pin.computeAllTerms(model, data, q, v)  # leaves data.a = velocity products (a = 0)
        self.heel = _frozen(pin.updateFramePlacement(model, data, heel).translation.copy())
        self.m_aa = _frozen(data.M.reshape(-1, order='F').take(plan.m_index))  # symmetric
        self.nle = _frozen(data.nle[plan.sel].copy())  # copies: data is overwritten later
        self.engaged = dynamics.params.joint_limits and dynamics._limits_engaged(ql)
        self.passive = _frozen(dynamics.passive_forces(q, v) if self.engaged
                               else dynamics._neg_damping * v)
        self.rows = self.heel_y = self.drift = self.jcom = None
        self.acom_z = 0.0
        mode = plan.mode
        if plan.nc:
            jac = pin.getFrameJacobian(model, data, heel, _LWA)
            self.rows = _frozen(jac.take(plan.j_index))
            if mode.swing_sliding:
                self.heel_y = _frozen(jac.take(plan.heel_y_index))
            acc = pin.getFrameClassicalAcceleration(model, data, heel, _LWA).linear
            self.drift = (float(acc[2]), float(acc[1]))
        if mode.y0_active:
            pin.centerOfMass(model, data, pin.KinematicLevel.ACCELERATION, False)
            self.jcom = _frozen(data.Jcom[2, plan.sel].copy())
            self.acom_z = float(data.acom[0][2])
        self.heel_velocity = _frozen(pin.getFrameVelocity(model, data, heel, _LWA).linear.copy())
        self.toe_z = float(pin.updateFramePlacement(model, data, plan.toe).translation[2])


def _frozen(x: np.ndarray) -> np.ndarray:
    x.flags.writeable = False
    return x


class GaitDynamics(ModelTerms):
    """Eq. (7) of every mode in Python, on the model terms of ``ModelTerms``.

    Holds one Pinocchio data object per support model, so an instance is not thread-safe;
    make one per thread.
    """

    #: States whose input-free terms ``evaluate`` keeps (an event search alternates two).
    _STATE_CACHE = 2

    def __init__(self, robot: Robot, params: DynamicsParameters | None = None) -> None:
        super().__init__(robot, params)
        self._mass = robot.total_mass
        self._damping = robot.damping if self.params.damping else np.zeros(N_COORDINATES)
        limits = sorted(JOINT_LIMITS.items())
        self._limit_index = np.array([i for i, _ in limits], dtype=np.intp)
        self._limit_lower = np.array([lo for _, (lo, _hi) in limits])
        self._limit_upper = np.array([hi for _, (_lo, hi) in limits])
        self._neg_damping = -self._damping
        self._limit_list = [(int(i), float(lo), float(hi))
                            for i, (lo, hi) in sorted(JOINT_LIMITS.items())]
        self._plans: dict[tuple[int, str, str], _Plan] = {}
        self._states: list[_StateTerms] = []  # most recent first

    # ----------------------------------------------------------------- helpers
    def _plan(self, contact: ContactState) -> _Plan:
        model, data, frames = self._model(contact)
        plan = _Plan(contact.mode, model, data, frames)
        self._plans[(contact.mode.number, contact.side, contact.pivot)] = plan
        return plan

    def _limits_engaged(self, ql: list[float]) -> bool:
        """Whether q (as a list) penetrates any soft stop."""
        for i, lower, upper in self._limit_list:
            if ql[i] < lower or ql[i] > upper:
                return True
        return False

    def _limit_damping_engaged(self, q: np.ndarray) -> np.ndarray:
        """Soft-stop damping of the stops engaged at q (18,) [N m s/rad]."""
        out = np.zeros(N_COORDINATES)
        if self.params.joint_limits:
            idx = self._limit_index
            engaged = (q[idx] < self._limit_lower) | (q[idx] > self._limit_upper)
            out[idx] = self.params.limit_damping * engaged
        return out

    # ------------------------------------------ model quantities the tests read
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

    def push_force(self, contact: ContactState, q: np.ndarray,
                   push: tuple[str, np.ndarray]) -> np.ndarray:
        """Generalized force J^T f of an external force f [N] at a link frame (18,)."""
        model, data, frames = self._model(contact)
        pin.computeJointJacobians(model, data, q)
        force = pin.getFrameJacobian(model, data, frames[push[0]], _LWA)[:3].T @ push[1]
        force[locked_coordinates(contact.mode)] = 0.0
        return force

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

    # ------------------------------------------------------------- main routine
    def evaluate(self, contact: ContactState, q: np.ndarray, v: np.ndarray,
                 tau: np.ndarray, push: tuple[str, np.ndarray] | None = None,
                 stiffness: np.ndarray | None = None, damping: np.ndarray | None = None,
                 ) -> DynamicsResult:
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
        :raises SimulationError: on malformed input or a rank-deficient constraint set.
        """
        plan, terms, applied = self._assemble(contact, q, v, tau, push, stiffness, damping)
        q = np.asarray(q, dtype=float)
        v = np.asarray(v, dtype=float)
        x = self._solve_assembled(plan, q, v)
        mode, mu, n = plan.mode, self.params.mu, plan.n
        qdd = np.zeros(N_COORDINATES)
        qdd[plan.sel] = x[:n]
        values = plan.pick(x[n:].tolist() + [0.0])  # (f_nz, f_ny, tau_n)
        multipliers = np.array(values)
        heel_friction = (-mu * contact.heel_slide_dir * values[_F_NZ]
                         if mode.swing_sliding else 0.0)
        wrench = self._support_wrench(plan, terms.heel, q, v, qdd, values, heel_friction,
                                      applied, push)
        normal = float(wrench[2])
        zmp_y = float(q[Y0] + wrench[3] / normal) if normal > 0.0 else float('nan')
        return DynamicsResult(qdd, multipliers, wrench, normal, float(wrench[1]), zmp_y,
                              float(heel_friction), applied, terms.heel, terms.heel_velocity,
                              terms.toe_z, terms.passive)

    def implicit_acceleration(self, contact: ContactState, q: np.ndarray, v: np.ndarray,
                              tau: np.ndarray, push: tuple[str, np.ndarray] | None,
                              stiffness: np.ndarray | None, damping: np.ndarray | None,
                              step: float) -> np.ndarray:
        """Accelerations (18,) of a step of size ``step`` [s] with the joint, impedance and
        soft-stop damping D taken implicitly: (M + h D) a = f - D v over the constrained system
        of ``evaluate`` (MuJoCo's implicitfast idea); the other arguments as in ``evaluate``.

        When the last system assembled in this mode is ``evaluate``'s at the same state and
        inputs (the period's start, evaluated just before), only h D is added to it: the same
        matrix, bit for bit, without assembling it again.
        """
        mode = contact.mode
        plan = self._plans.get((mode.number, contact.side, contact.pivot))
        kept = None
        if plan is not None and plan.mode is mode and push is None and plan.assembled:
            key, terms = plan.assembled
            if key == _input_key(contact, q, v, tau, stiffness, damping):
                kept = terms
        if kept is None:
            plan, kept, _ = self._assemble(contact, q, v, tau, push, stiffness, damping)
        plan.assembled = None  # the diagonal below changes the system
        q = np.asarray(q, dtype=float)
        implicit = (self._damping + self._limit_damping_engaged(q) if kept.engaged
                    else self._damping.copy())
        if damping is not None:
            implicit = implicit + damping
        implicit[Y0] = 0.0
        plan.A_diag += step * implicit[plan.sel]
        x = self._solve_assembled(plan, q, np.asarray(v, dtype=float))
        qdd = np.zeros(N_COORDINATES)
        qdd[plan.sel] = x[:plan.n]
        return qdd

    def _assemble(self, contact: ContactState, q: np.ndarray, v: np.ndarray,
                  tau: np.ndarray, push: tuple[str, np.ndarray] | None,
                  stiffness: np.ndarray | None, damping: np.ndarray | None,
                  ) -> tuple[_Plan, _StateTerms, np.ndarray]:
        """Check the input and write eq. (7)'s system A x = b of ``contact.mode`` at (q, v)
        into the mode's plan buffers (``plan.assembled`` then names the state and inputs).

        :returns: the plan, the state's input-free terms and the applied force (18,).
        """
        mode = contact.mode
        plan = self._plans.get((mode.number, contact.side, contact.pivot))
        if plan is None or plan.mode is not mode:
            plan = self._plan(contact)
        q = np.asarray(q, dtype=float)
        v = np.asarray(v, dtype=float)
        if q.shape != _SHAPE or v.shape != _SHAPE:
            check_state(q, v, plan.where)
        tau = np.asarray(tau, dtype=float)
        ql = q.tolist()
        # float sums never warn; a non-finite (or overflowing) sum gets the exact checks
        if tau.shape != _SHAPE or not math.isfinite(sum(ql) + sum(v.tolist())
                                                    + sum(tau.tolist())):
            check_state(q, v, plan.where)
            if tau.shape != _SHAPE or not np.all(np.isfinite(tau)):
                raise SimulationError(f'{plan.where}: tau must be {N_COORDINATES} '
                                      f'finite values, got shape {tau.shape}')
        for i in plan.locked:
            if v[i] != 0.0:
                locked = plan.locked
                raise SimulationError(f'{plan.where}: locked coordinates '
                                      f'{locked} must have zero velocity, got {v[locked]}')
        model, data = plan.model, plan.data
        n, nc, sel, A, b = plan.n, plan.nc, plan.sel, plan.A, plan.b
        params = self.params
        mu = params.mu
        terms = self._state_terms(plan, q, v, ql, fresh=push is not None)

        applied = terms.passive + tau
        if stiffness is not None:
            applied -= stiffness * q + damping * v
        if not mode.q1_active:
            applied[Q1] = 0.0
        applied[Y0] = 0.0
        if push is not None:  # the terms are fresh: data holds this state's Jacobians
            jac = pin.getFrameJacobian(model, data, plan.frames[push[0]], _LWA)
            applied += jac[:3].T @ push[1]

        plan.A_mm[...] = terms.m_aa
        np.subtract(applied[sel], terms.nle, out=plan.b_top)
        if nc:
            rows = terms.rows
            plan.A_jac[...] = rows
            plan.A_mc_jac[...] = -rows.T  # generalized-force directions -J^T
            if mode.swing_sliding:  # friction mu f_nz on the heel, against its velocity
                np.subtract(mu * contact.heel_slide_dir * terms.heel_y, plan.A_c0,
                            out=plan.A_mc0)
            b[n] = -terms.drift[0]
            if plan.n_jac == 2:
                b[n + 1] = -terms.drift[1]
            if plan.fr_row is not None:
                b[plan.fr_row] = -0.0
            alpha = params.baumgarte
            if alpha:
                rows = np.zeros((nc, N_COORDINATES))
                rows[:, plan.act] = plan.A_cm
                heel_position = terms.heel
                position = [heel_position[2] if name == 'hz'
                            else heel_position[1] - contact.heel_anchor_y if name == 'hy'
                            else q[_LEG_CHAIN].sum() for name in mode.constraints]
                b[n:] -= 2.0 * alpha * rows @ v + alpha * alpha * np.array(position)
        if mode.y0_active:  # Q_sup = -mu s0 N_s, N_s = m (g + zdd_com) - f_nz
            k = mu * contact.support_slide_dir
            km = k * self._mass
            plan.A_row0 += km * terms.jcom
            b[0] -= km * (GRAVITY + terms.acom_z)
            if nc:
                A[0, n] -= k
        if nc:
            self._check_rank_fast(plan.A_cm, contact)
        plan.assembled = (None if push is not None
                          else (_input_key(contact, q, v, tau, stiffness, damping), terms))
        return plan, terms, applied

    def _solve_assembled(self, plan: _Plan, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """x = A^-1 b of the plan's assembled system (A and b are left as they are).

        :raises SimulationError: for a singular or non-finite solution.
        """
        try:
            x, finite = _solve(plan.A, plan.b)
        except np.linalg.LinAlgError as exc:
            raise SimulationError(f'mode {plan.mode.number}: singular dynamics matrix '
                                  f'({exc})') from exc
        if not finite:
            raise SimulationError(f'mode {plan.mode.number} dynamics: the solution is not '
                                  f'finite (|v|max {np.max(np.abs(v)):.3g}, |q|max '
                                  f'{np.max(np.abs(q)):.3g})')
        return x

    def _state_terms(self, plan: _Plan, q: np.ndarray, v: np.ndarray, ql: list[float],
                     fresh: bool = False) -> _StateTerms:
        """The input-free terms of (q, v) in ``plan``: kept ones if this state was evaluated
        lately (bit-identical to computing them again), else computed (always if ``fresh``:
        Pinocchio's data then holds this state for the caller)."""
        key = (plan, q.tobytes(), v.tobytes())
        states = self._states
        for i, terms in enumerate(states):
            if terms.key == key:
                del states[i]
                if not fresh:
                    states.insert(0, terms)
                    return terms
                break
        terms = _StateTerms(key, plan, self, q, v, ql)
        states.insert(0, terms)
        del states[self._STATE_CACHE:]
        return terms

    def _check_rank_fast(self, jac: np.ndarray, contact: ContactState) -> None:
        """``_check_rank`` with the Hadamard ratio in closed form (1 to 3 rows); the exact check
        runs only when that ratio is not clearly above the tolerance."""
        if len(jac) == 1:
            ratio = 1.0 if jac[0].dot(jac[0]) > 0.0 else 0.0
        elif len(jac) == 2:
            (a, b), (_, d) = jac.dot(jac.T).tolist()
            ratio = (a * d - b * b) / (a * d) if a > 0.0 and d > 0.0 else 0.0
        else:
            (a, b, c), (_, d, e), (_, _, f) = jac.dot(jac.T).tolist()
            det = a * (d * f - e * e) - b * (b * f - e * c) + c * (b * e - d * c)
            ratio = det / (a * d * f) if a > 0.0 and d > 0.0 and f > 0.0 else 0.0
        if not ratio >= _RANK_SAFE:
            self._check_rank(np.array(jac), contact)

    def _check_rank(self, jac: np.ndarray, contact: ContactState) -> None:
        gram = jac @ jac.T
        diag = np.diag(gram)
        ratio = np.linalg.det(gram) / np.prod(diag) if np.all(diag > 0) else 0.0
        if ratio < _RANK_TOLERANCE:
            raise SimulationError(
                f'mode {contact.mode.number}: swing constraints {contact.mode.constraints} '
                f'are rank-deficient at this posture (Hadamard ratio {ratio:.2e}); the '
                'all-straight double-support posture is singular (docs/model.md §4.5)')

    def _support_wrench(self, plan: _Plan, heel: np.ndarray, q: np.ndarray, v: np.ndarray,
                        qdd: np.ndarray, multipliers: tuple[float, float, float],
                        heel_friction: float, applied: np.ndarray,
                        push: tuple[str, np.ndarray] | None) -> np.ndarray:
        """Floor wrench on the support foot at (x_s, y0, 0), world-aligned.

        RNEA gives the wrench the base must supply for the motion; the swing contact and any
        push supply part of it, the rest comes from the support foot. In Python floats: numpy
        costs more than it saves on 3-vectors.
        """
        model, data = plan.model, plan.data
        pin.rnea(model, data, q, v, qdd)
        # (force, moment) through the y0 joint, world-aligned
        fx, fy, fz, mx, my, mz = data.f[1].vector.tolist()
        if plan.origin_x is None:
            ox, oy, oz = data.oMi[1].translation.tolist()
        else:
            ox, oy, oz = plan.origin_x, 0.0 + float(q[Y0]), 0.0
        if plan.nc:
            f_nz, f_ny, tau_n = multipliers
            py, pz = f_ny + heel_friction, f_nz  # the swing contact force (0, py, pz)
            hx, hy, hz = heel.tolist()
            fx, fy, fz, mx, my, mz = _minus_force_at(fx, fy, fz, mx, my, mz, hx - ox, hy - oy,
                                                     hz - oz, 0.0, py, pz)
            mx -= tau_n
        if push is not None:
            at = pin.updateFramePlacement(model, data, plan.frames[push[0]]).translation
            ax, ay, az = at.tolist()
            px, py, pz = np.asarray(push[1], dtype=float).tolist()
            fx, fy, fz, mx, my, mz = _minus_force_at(fx, fy, fz, mx, my, mz, ax - ox, ay - oy,
                                                     az - oz, px, py, pz)
        if plan.mode.q1_active:  # input and damping at the floor hinge act beside contact
            mx -= applied[Q1]
        return np.array([fx, fy, fz, mx, my, mz])


@functools.cache
def _lapack() -> ModuleType:
    """scipy's LAPACK bindings, imported on the first solve (scipy.linalg takes a fifth of a
    second to import)."""
    from scipy.linalg import lapack
    return lapack


def _solve(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, bool]:
    """x = A^-1 b by LAPACK gesv (LU with partial pivoting, as np.linalg.solve, through scipy's
    binding: 2.6 us instead of 8 us for 18 unknowns) and whether x is finite.

    :raises np.linalg.LinAlgError: if A is exactly singular.
    """
    _, _, x, info = _lapack().dgesv(A, b)
    if info > 0:
        raise np.linalg.LinAlgError(f'singular matrix (zero pivot U[{info - 1}, {info - 1}])')
    return x, all_finite(x)


def _input_key(contact: ContactState, q: np.ndarray, v: np.ndarray, tau: np.ndarray,
               stiffness: np.ndarray | None, damping: np.ndarray | None) -> tuple:
    """What the system ``_assemble`` writes for a plan depends on (bytes of the arrays):
    equal keys give equal systems."""
    return (contact.heel_anchor_y, contact.support_slide_dir, contact.heel_slide_dir,
            *(None if x is None else np.asarray(x, dtype=float).tobytes()
              for x in (q, v, tau, stiffness, damping)))


def _minus_force_at(fx: float, fy: float, fz: float, mx: float, my: float, mz: float,
                    rx: float, ry: float, rz: float, px: float, py: float, pz: float,
                    ) -> tuple[float, float, float, float, float, float]:
    """Wrench (f, m) minus the force p acting at r: (f - p, m - r x p), in scalars."""
    return (fx - px, fy - py, fz - pz, mx - (ry * pz - rz * py), my - (rz * px - rx * pz),
            mz - (rx * py - ry * px))


