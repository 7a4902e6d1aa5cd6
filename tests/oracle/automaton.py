"""Test oracle: the hybrid gait automaton in Python (docs/model.md §6-§7), the readable
formulation the native transitions (``iceskate_native/src/guards.cpp``, ``transitions.cpp``) are
checked against.

Each guard of ``iceskate_sim.physics.hybrid.GUARDS`` is a scalar function of the state and its
dynamics (``GUARD_VALUES``) that becomes positive when its transition should happen. The integrator
locates the first sign change in time; ``apply_transition`` performs the reset: a perfectly
inelastic impact projected on the new constraint set where contact is made, a change of
coordinates (add/drop q1 or y0), or the support exchange that re-roots the tree.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import HeldCommand
from iceskate_sim.model.dynamics import ContactState, DynamicsResult
from iceskate_sim.model.modes import MODES, SUPPORT_STATES, SWING_STATES, GaitMode
from iceskate_sim.model.robot import N_COORDINATES, Q1, SOLE_HEEL_Y, SOLE_TOE_Y, Y0
from iceskate_sim.physics.hybrid import (
    COP_BAND,
    FLIGHT,
    FORCE_BAND,
    MOMENT_BAND,
    TOE_FIRST,
    TOE_SCUFF,
    FrictionModel,
    Guard,
    HybridState,
    Transition,
    guards_of,
)
from oracle.dynamics import GaitDynamics

_LEG = slice(1, 8)
_LEG_JOINTS = np.arange(2, 8)
EPS_V = 1.0e-4  # m/s, velocity dead band of docs/model.md §6.3 (heel strike: slide vs. pin, §7.3)
_BY_CODES = {(m.support, m.swing): m for m in MODES.values()}


def mode_for(support: str, swing: str) -> GaitMode:
    """Return the mode made of a support-foot state and a swing-foot state."""
    try:
        return _BY_CODES[(support, swing)]
    except KeyError:
        raise SimulationError(
            f'no gait mode for support {support!r} and swing {swing!r}; support in '
            f'{tuple(SUPPORT_STATES)}, swing in {tuple(SWING_STATES)}') from None


class RunEnded(Exception):
    """A physical situation the paper's model cannot represent; ends a run cleanly."""

    def __init__(self, reason: str, state: HybridState) -> None:
        """Store the reason and the state at which the run ended."""
        super().__init__(reason)
        self.reason = reason
        self.state = state


def _stuck_support_friction(s: HybridState, r: DynamicsResult, f: FrictionModel) -> float:
    """E4: the reaction needed to hold the support foot exceeds friction."""
    if f.rule == 'ice':  # only a forward-wanting foot (reaction pointing back) can slide
        return -r.support_friction - f.mu * r.support_normal - FORCE_BAND
    return abs(r.support_friction) - f.mu * r.support_normal - FORCE_BAND


def _pinned_heel_tangential(s: HybridState, r: DynamicsResult, f: FrictionModel) -> float:
    """S3: the reaction needed to pin the swing heel exceeds friction."""
    f_nz, f_ny = r.multipliers[0], r.multipliers[1]
    if f.rule == 'ice':
        return -f_ny - f.mu * f_nz - FORCE_BAND
    return abs(f_ny) - f.mu * f_nz - FORCE_BAND


#: The value of each guard of ``iceskate_sim.physics.hybrid.GUARDS`` (positive: due), by name.
GUARD_VALUES: dict[str, Callable[[HybridState, DynamicsResult, FrictionModel], float]] = {
    'E1': lambda s, r, f: r.support_wrench[3] - (SOLE_TOE_Y + COP_BAND) * r.support_normal,
    'E2': lambda s, r, f: (SOLE_HEEL_Y - COP_BAND) * r.support_normal - r.support_wrench[3],
    'E3': lambda s, r, f: s.q[Q1] if s.contact.pivot == 'toe' else -s.q[Q1],
    'E4': _stuck_support_friction,
    'E5': lambda s, r, f: -s.contact.support_slide_dir * s.v[0],
    'E6': lambda s, r, f: -r.support_normal - FORCE_BAND,
    'S1': lambda s, r, f: -r.swing_heel[2],
    'S7': lambda s, r, f: -r.swing_toe_z - TOE_SCUFF,
    'S2': lambda s, r, f: -s.contact.heel_slide_dir * r.swing_heel_velocity[1],
    'S3': _pinned_heel_tangential,
    'S4': lambda s, r, f: -s.q[_LEG].sum(),
    'S5': lambda s, r, f: -r.multipliers[2] - MOMENT_BAND,
    'S6': lambda s, r, f: -r.multipliers[0] - FORCE_BAND,
}


def guard_values(state: HybridState, result: DynamicsResult,
                 friction: FrictionModel) -> np.ndarray:
    """Values of the guards of the current mode (positive: due)."""
    return np.array([GUARD_VALUES[g.name](state, result, friction)
                     for g in guards_of(state.mode)])


# ------------------------------------------------------------------------ impacts
def impact(dynamics: GaitDynamics, contact: ContactState, q: np.ndarray, v: np.ndarray,
           rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Perfectly inelastic impact onto the constraint rows ``rows`` (k x 18).

    Solves [M -J^T; J 0] [v+; Pi] = [M v-; 0] over the active coordinates of
    ``contact.mode``. Returns v+ (18,) and the impulses Pi (k,) [N s, N m s].
    """
    act = contact.mode.active
    M = dynamics.mass_matrix(contact, q)
    J = rows[:, act]
    k = J.shape[0]
    n = act.size
    A = np.zeros((n + k, n + k))
    A[:n, :n] = M
    A[:n, n:] = -J.T
    A[n:, :n] = J
    b = np.zeros(n + k)
    b[:n] = M @ v[act]
    try:
        x = np.linalg.solve(A, b)
    except np.linalg.LinAlgError as exc:
        raise SimulationError(f'impact in mode {contact.mode.number}: singular ({exc})') from exc
    v_plus = np.zeros(N_COORDINATES)
    v_plus[act] = x[:n]
    return v_plus, x[n:]


# --------------------------------------------------------------- support exchange
NEW_SUPPORT_OF_SWING = {'Fp': 'F-S', 'Fs': 'F-G', 'Hp': 'R-S', 'Hs': 'R-G'}


def reroot(dynamics: GaitDynamics, state: HybridState) -> HybridState:
    """Support exchange (E6, swing in contact): re-root at the old swing foot (docs/model.md §7.4).

    q1' = phi_7 (old swing-foot pitch), q2'..q7' = -q7..-q2, q8..q17 unchanged (same map for
    the velocities); y0' puts the new support's heel where the old swing heel is, so every
    link keeps its world pose and velocity.
    """
    old = state.contact
    new_support = NEW_SUPPORT_OF_SWING.get(old.mode.swing)
    if new_support is None:
        raise SimulationError(f'support exchange needs a swing contact; {state.summary()}')
    mode = mode_for(new_support, 'A')
    q, v = state.q, state.v
    q_new = q.copy()
    v_new = v.copy()
    q_new[Q1] = q[_LEG].sum() if mode.q1_active else 0.0
    v_new[Q1] = v[_LEG].sum() if mode.q1_active else 0.0
    q_new[2:8] = _other_legs(q)
    v_new[2:8] = _other_legs(v)
    heel = dynamics.frame_placement(old, q, 'swing_heel').translation
    heel_velocity = dynamics.frame_velocity(old, q, v, 'swing_heel').linear
    q_new[Y0] = heel[1] - SOLE_HEEL_Y
    v_new[Y0] = heel_velocity[1] if mode.y0_active else 0.0
    side = 'left' if old.side == 'right' else 'right'
    pivot = 'heel' if mode.q1_active else 'toe'
    contact = ContactState(mode, side, pivot, 0.0, support_slide_dir=old.heel_slide_dir)
    return HybridState(state.t, q_new, v_new, contact, state.step_index + 1, state.t,
                       float('nan'))


def _other_legs(x: np.ndarray, sign: float = -1.0) -> np.ndarray:
    """Entries 2..7 of ``x`` in the other support foot's coordinates: q2'..q7' = -q7..-q2
    (``sign`` +1 for gains, whose sign does not follow the coordinate's)."""
    return sign * x[7:1:-1]


def rerooted_command(command: HeldCommand) -> HeldCommand:
    """The same physical command in the coordinates of the other support foot: a command held
    over a control period keeps acting on the same motors when the tree re-roots inside it.
    Its y0 and q1 entries act between the floor and the old support foot, which has left the
    floor: they end."""
    entries = []
    for values, sign in ((command.bias, -1.0), (command.stiffness, 1.0), (command.damping, 1.0)):
        moved = values.copy()
        moved[[Y0, Q1]] = 0.0
        moved[2:8] = _other_legs(values, sign)
        entries.append(moved)
    return HeldCommand(*entries)


def _swapped(mode: GaitMode, support: str | None = None, swing: str | None = None) -> GaitMode:
    return mode_for(support or mode.support, swing or mode.swing)


_ADD_Q1 = {'F-S': 'R-S', 'F-G': 'R-G'}
_DROP_Q1 = {'R-S': 'F-S', 'R-G': 'F-G'}
_ADD_Y0 = {'F-S': 'F-G', 'R-S': 'R-G'}
_DROP_Y0 = {'F-G': 'F-S', 'R-G': 'R-S'}
_PIN = {'Hs': 'Hp', 'Fs': 'Fp'}
_UNPIN = {'Hp': 'Hs', 'Fp': 'Fs'}
_FLATTEN = {'Hs': 'Fs', 'Hp': 'Fp'}
_UNFLATTEN = {'Fs': 'Hs', 'Fp': 'Hp'}


def project_positions(dynamics: GaitDynamics, contact: ContactState, q: np.ndarray,
                      iterations: int = 4) -> tuple[np.ndarray, float]:
    """Gauss-Newton projection of q onto the active swing constraints (least-norm steps).

    Only the leg joints q2..q7 move: the support coordinates y0 and q1 carry guards of their
    own (E3, E5) that a round-off shift must not trigger.

    :returns: projected q and the largest residual |C| seen before projecting [m, rad].
    """
    q = q.copy()
    act = _LEG_JOINTS
    worst = 0.0
    for k in range(iterations):
        C, _ = dynamics.constraint_residuals(contact, q, np.zeros(N_COORDINATES))
        if k == 0:
            worst = float(np.max(np.abs(C))) if C.size else 0.0
        if not C.size or np.max(np.abs(C)) < 1e-14:
            break
        J = dynamics.constraint_jacobian(contact, q)[:, act]
        q[act] -= J.T @ np.linalg.solve(J @ J.T, C)
    return q, worst


def _impact_into(dynamics: GaitDynamics, state: HybridState, contact: ContactState,
                 extra_rows: np.ndarray | None = None,
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Impact of ``state`` onto the constraints of ``contact`` (plus ``extra_rows``).

    Positions are first projected onto the new constraints (they hold only to the event
    tolerance at the located instant). Returns (q, v+, impulses).
    """
    q, _ = project_positions(dynamics, contact, state.q)
    rows = dynamics.constraint_jacobian(contact, q)
    if extra_rows is not None:
        rows = np.vstack([extra_rows, rows])
    v_plus, impulse = impact(dynamics, contact, q, state.v, rows)
    return q, v_plus, impulse


def apply_transition(dynamics: GaitDynamics, friction: FrictionModel, state: HybridState,
                     guard: Guard, result: DynamicsResult) -> tuple[HybridState, Transition]:
    """Perform the reset of ``guard`` at ``state`` (located on the guard's zero).

    :raises RunEnded: for flight (both feet off) and toe-first touchdown, which the paper's
        model cannot represent.
    """
    mode, c = state.mode, state.contact
    name = guard.name
    impulse: tuple[float, ...] = ()
    new = state
    if name in ('E1', 'E2'):
        pivot = 'toe' if name == 'E1' else 'heel'
        contact = replace(c, mode=_swapped(mode, support=_ADD_Q1[mode.support]), pivot=pivot)
        q = state.q.copy()
        q[Q1] = 0.0
        new = replace(state, q=q, contact=contact)
    elif name == 'E3':
        e_q1 = np.zeros((1, N_COORDINATES))
        e_q1[0, Q1] = 1.0
        q = state.q.copy()
        q[Q1] = 0.0
        q, v_plus, pi = _impact_into(dynamics, replace(state, q=q), c, e_q1)
        impulse = tuple(pi)
        v_plus[Q1] = 0.0
        contact = replace(c, mode=_swapped(mode, support=_DROP_Q1[mode.support]))
        new = replace(state, q=q, v=v_plus, contact=contact)
    elif name == 'E4':
        direction = 1.0 if friction.rule == 'ice' else float(np.sign(-result.support_friction))
        contact = replace(c, mode=_swapped(mode, support=_ADD_Y0[mode.support]),
                          support_slide_dir=direction or 1.0)
        new = replace(state, contact=contact)
    elif name == 'E5':
        v = state.v.copy()
        v[Y0] = 0.0
        new = replace(state, v=v, contact=replace(
            c, mode=_swapped(mode, support=_DROP_Y0[mode.support])))
    elif name == 'E6':
        if mode.swing == 'A':
            raise RunEnded(FLIGHT, state)
        new = reroot(dynamics, state)
    elif name == 'S7':
        raise RunEnded(TOE_FIRST, state)
    elif name == 'S1':
        new, impulse = _heel_strike(dynamics, friction, state)
    elif name == 'S2':
        contact = replace(c, mode=_swapped(mode, swing=_PIN[mode.swing]),
                          heel_anchor_y=float(result.swing_heel[1]))
        q, v_plus, pi = _impact_into(dynamics, state, contact)
        impulse = tuple(pi)
        new = replace(state, q=q, v=v_plus, contact=contact)
    elif name == 'S3':
        direction = 1.0 if friction.rule == 'ice' else float(np.sign(-result.multipliers[1]))
        new = replace(state, contact=replace(
            c, mode=_swapped(mode, swing=_UNPIN[mode.swing]), heel_slide_dir=direction or 1.0))
    elif name == 'S4':
        contact = replace(c, mode=_swapped(mode, swing=_FLATTEN[mode.swing]))
        q, v_plus, pi = _impact_into(dynamics, state, contact)
        impulse = tuple(pi)
        new = replace(state, q=q, v=v_plus, contact=contact)
    elif name == 'S5':
        new = replace(state, contact=replace(c, mode=_swapped(mode,
                                                              swing=_UNFLATTEN[mode.swing])))
    elif name == 'S6':
        new = replace(state, contact=replace(c, mode=_swapped(mode, swing='A')),
                      t_touchdown=float('nan'))
        if state.step_index == 0 and state.t_touchdown <= state.t_exchange:
            # the end of the starting double support is the first swing's t_e: the paper's
            # t_e is when a foot becomes the swing foot, and the first one does so here
            new = replace(new, t_exchange=state.t)
    else:
        raise SimulationError(f'unknown guard {name!r}')
    record = Transition(state.t, mode.number, new.mode.number, name, guard.cause, impulse,
                        new.step_index, new.contact.side)
    return new, record


def _heel_strike(dynamics: GaitDynamics, friction: FrictionModel,
                 state: HybridState) -> tuple[HybridState, tuple[float, ...]]:
    """S1: inelastic impact onto C_hz; the heel then slides (Hs) or is pinned (Hp)."""
    c = state.contact
    sliding = replace(c, mode=_swapped(c.mode, swing='Hs'), heel_slide_dir=1.0)
    q, v_slide, pi_slide = _impact_into(dynamics, state, sliding)
    heel_vy = dynamics.frame_velocity(sliding, q, v_slide, 'swing_heel').linear[1]
    heel_y = dynamics.frame_placement(c, q, 'swing_heel').translation[1]
    pinned = replace(c, mode=_swapped(c.mode, swing='Hp'), heel_anchor_y=float(heel_y))
    q, v_pin, pi_pin = _impact_into(dynamics, replace(state, q=q), pinned)
    if friction.rule == 'ice':
        use_pin = heel_vy <= EPS_V  # forward: slides; backward: toe pick holds it
    else:
        use_pin = abs(pi_pin[1]) <= friction.mu * pi_pin[0]
        if not use_pin:
            sliding = replace(sliding, heel_slide_dir=float(np.sign(heel_vy)) or 1.0)
    contact, v_plus, pi = (pinned, v_pin, pi_pin) if use_pin else (sliding, v_slide, pi_slide)
    if pi[0] < 0.0:  # the floor would have to pull: no contact is made
        return state, ()
    return replace(state, q=q, v=v_plus, contact=contact, t_touchdown=state.t), tuple(pi)


# ------------------------------------------------------- contact-consistent mode
_SUPPORT_ORDER = ('F-S', 'R-S', 'F-G', 'R-G')  # most constrained first
_SWING_ORDER = ('Fp', 'Fs', 'Hp', 'Hs', 'A')
_AT_REST = 1.0e-7  # m/s, rad/s: a coordinate this slow may switch without an impulse
_ACCEL_TOL = 1.0e-6  # m/s^2, rad/s^2


def _candidates(state: HybridState) -> list[ContactState]:
    """Contact states reachable from ``state`` without an impact, most constrained first."""
    c, q, v = state.contact, state.q, state.v
    mode = c.mode
    flat_ok = abs(q[Q1]) < 1e-12 and abs(v[Q1]) < _AT_REST
    if mode.q1_active and not flat_ok:
        pivots = [c.pivot]
    else:
        pivots = [c.pivot] if mode.q1_active else ['toe', 'heel']
    stuck_ok = abs(v[Y0]) < _AT_REST
    glide_dirs = [c.support_slide_dir] if mode.y0_active and not stuck_ok else [1.0, -1.0]
    if mode.swing == 'A':
        swings = ['A']
    else:
        swings = ['A', 'Hs', 'Hp']
        if mode.swing in ('Fs', 'Fp'):
            swings += ['Fs', 'Fp']
    out = []
    for support in _SUPPORT_ORDER:
        edge = support.startswith('R')
        glide = support.endswith('G')
        if not edge and not flat_ok:
            continue
        if not glide and mode.y0_active and not stuck_ok:
            continue
        for swing in _SWING_ORDER:
            if swing not in swings:
                continue
            for pivot in (pivots if edge else [c.pivot]):
                for direction in (glide_dirs if glide else [c.support_slide_dir]):
                    out.append(replace(c, mode=mode_for(support, swing), pivot=pivot,
                                       support_slide_dir=direction))
    return out


def _consistent(state: HybridState, r: DynamicsResult, friction: FrictionModel,
                old: GaitMode) -> bool:
    """All unilateral, friction and direction conditions of the candidate hold."""
    c, mode = state.contact, state.mode
    if r.support_normal < -FORCE_BAND:
        return False
    if not mode.y0_active:  # stuck support: the needed reaction inside the friction cone
        if _stuck_support_friction(state, r, friction) > 0.0:
            return False
    elif abs(state.v[Y0]) < _AT_REST and c.support_slide_dir * r.qdd[Y0] < -_ACCEL_TOL:
        return False
    if friction.rule == 'ice' and mode.y0_active and c.support_slide_dir < 0:
        return False
    if not mode.q1_active:
        moment = r.support_wrench[3]
        if (moment - (SOLE_TOE_Y + COP_BAND) * r.support_normal > 0.0
                or (SOLE_HEEL_Y - COP_BAND) * r.support_normal - moment > 0.0):
            return False
    elif not old.q1_active:  # a new edge: the sole must start to turn off the floor
        sign = -1.0 if c.pivot == 'toe' else 1.0
        if sign * r.qdd[Q1] < -_ACCEL_TOL:
            return False
    if mode.swing != 'A':
        if r.multipliers[0] < -FORCE_BAND:
            return False
        if mode.swing in ('Hp', 'Fp') and _pinned_heel_tangential(state, r, friction) > 0.0:
            return False
        if mode.swing in ('Fs', 'Fp') and r.multipliers[2] < -MOMENT_BAND:
            return False
        if mode.swing in ('Hs', 'Hp') and old.swing in ('Fs', 'Fp'):
            if r.qdd[_LEG].sum() < -_ACCEL_TOL:  # the toe must lift
                return False
        if mode.swing in ('Hs', 'Fs'):
            heel_vy = r.swing_heel_velocity[1]
            if friction.rule == 'ice' and c.heel_slide_dir < 0:
                return False
            if abs(heel_vy) > _AT_REST and np.sign(heel_vy) != c.heel_slide_dir:
                return False
    return True


def resolve_contact_mode(dynamics: GaitDynamics, friction: FrictionModel,
                         state: HybridState,
                         evaluate: Callable[[ContactState, np.ndarray, np.ndarray],
                                            DynamicsResult],
                         ) -> tuple[HybridState, DynamicsResult] | None:
    """A contact-consistent mode at an instant where single-guard switching cycles.

    Enumerates the modes reachable without an impact (subsets of the active contacts, and
    stick/flat constraints whose velocity is already zero), most constrained first, and
    returns the first whose solution satisfies every unilateral, friction-cone, CoP and
    direction condition; None if there is none.
    """
    old = state.mode
    for contact in _candidates(state):
        if contact.mode.swing in ('Hp', 'Fp') and old.swing not in ('Hp', 'Fp'):
            heel = dynamics.frame_placement(contact, state.q, 'swing_heel').translation
            contact = replace(contact, heel_anchor_y=float(heel[1]))
        q, v = state.q.copy(), state.v.copy()
        if not contact.mode.y0_active:
            v[Y0] = 0.0
        if not contact.mode.q1_active:
            v[Q1] = 0.0
        candidate = replace(state, q=q, v=v, contact=contact)
        rows = dynamics.constraint_jacobian(contact, q)
        if rows.size and np.max(np.abs(rows @ v)) > 1e-6:
            continue
        try:
            result = evaluate(contact, q, v)
        except SimulationError:
            continue
        if _consistent(candidate, result, friction, old):
            return candidate, result
    return None
