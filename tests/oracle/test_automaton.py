"""The oracle's hybrid gait automaton (docs/model.md §5-§7): re-rooting, impacts, the ice rule,
the guard values (the shipped guard table itself: tests/iceskate_sim/test_hybrid.py).

Expectations are derived here from docs/model.md, not from the code under test: link poses and
velocities come from Pinocchio on the support-rooted models, constraint rows are built from the
swing-heel Jacobian and the C_fr definition, and the impact is the M-orthogonal projection
v+ = v- - M^-1 J^T (J M^-1 J^T)^-1 J v- (the Schur-complement form of the KKT system of §7.1).
"""

from dataclasses import replace
import itertools

import numpy as np
import pinocchio as pin
import pytest

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import HeldCommand
from iceskate_sim.model.dynamics import ContactState, DynamicsResult
from iceskate_sim.model.modes import get_mode
from iceskate_sim.model.robot import JOINT_LIMITS, LINK_NAMES, N_COORDINATES, Q1, Y0
from iceskate_sim.physics.hybrid import GUARDS, FrictionModel, HybridState, guards_of
from oracle.automaton import (
    EPS_V,
    GUARD_VALUES,
    apply_transition,
    guard_values,
    mode_for,
    project_positions,
    reroot,
    rerooted_command,
)

LWA = pin.LOCAL_WORLD_ALIGNED
G = 9.81
MU_ICE = 0.005
ICE = FrictionModel(MU_ICE, 'ice')
GUARD = {g.name: g for g in GUARDS}
SIDES = ('right', 'left')
SUPPORT_CODES = ('F-S', 'R-S', 'F-G', 'R-G')
SWING_CONTACT_CODES = ('Fp', 'Fs', 'Hp', 'Hs')
# docs/model.md §7.4: the old swing contact becomes the new support state
NEW_SUPPORT = {'Fp': 'F-S', 'Fs': 'F-G', 'Hp': 'R-S', 'Hs': 'R-G'}
# swing constraints of each swing code (docs/model.md §3.2), in the order (C_hz, C_hy, C_fr)
SWING_ROWS = {'A': (), 'Hs': ('hz',), 'Hp': ('hz', 'hy'), 'Fs': ('hz', 'fr'),
              'Fp': ('hz', 'hy', 'fr')}
KNEE_BENT = np.array([-0.05, 0.1, -0.05, 0.05, -0.1, 0.05])  # q2..q7, docs/model.md §12


# ------------------------------------------------------------------ independent helpers
def _model(robot, contact: ContactState) -> tuple[pin.Model, pin.Data, dict[str, int]]:
    sm = robot.support_model(contact.side, contact.pivot)
    return sm.model, sm.model.createData(), sm.frame_ids


def _mass_matrix(robot, contact: ContactState, q: np.ndarray) -> np.ndarray:
    """Full 18 x 18 mass matrix of the support model (symmetrised CRBA)."""
    model, data, _ = _model(robot, contact)
    M = pin.crba(model, data, q)
    return np.triu(M) + np.triu(M, 1).T


def _kinetic(robot, contact: ContactState, q: np.ndarray, v: np.ndarray) -> float:
    return 0.5 * float(v @ _mass_matrix(robot, contact, q) @ v)


def _heel_jacobian(robot, contact: ContactState, q: np.ndarray) -> np.ndarray:
    """World-aligned 6 x 18 Jacobian of the swing heel point."""
    model, data, frames = _model(robot, contact)
    return pin.computeFrameJacobian(model, data, q, frames['swing_heel'], LWA)


def _rows(robot, contact: ContactState, q: np.ndarray, swing: str | None = None) -> np.ndarray:
    """Constraint rows of a swing code (C_hz, C_hy, C_fr; docs/model.md §4.2); locked columns 0."""
    mode = contact.mode
    names = SWING_ROWS[mode.swing if swing is None else swing]
    jac = _heel_jacobian(robot, contact, q)
    rows = []
    for name in names:
        if name == 'hz':
            rows.append(jac[2].copy())
        elif name == 'hy':
            rows.append(jac[1].copy())
        else:  # C_fr = q1 + ... + q7 (q1 only when present)
            row = np.zeros(N_COORDINATES)
            row[1:8] = 1.0
            rows.append(row)
    rows = np.array(rows).reshape(len(names), N_COORDINATES)
    rows[:, _locked(mode)] = 0.0
    return rows


def _locked(mode) -> list[int]:
    return [i for i in range(N_COORDINATES) if i not in set(mode.active.tolist())]


def _projection(M: np.ndarray, J: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Perfectly inelastic impact: v+ and the impulses (Schur-complement form)."""
    minv_jt = np.linalg.solve(M, J.T)
    impulse = -np.linalg.solve(J @ minv_jt, J @ v)
    return v + minv_jt @ impulse, impulse


def _impact_expected(robot, contact: ContactState, q: np.ndarray, v: np.ndarray,
                     J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """v+ (18,) and impulses of an impact onto rows J over the active coordinates."""
    act = contact.mode.active
    M = _mass_matrix(robot, contact, q)[np.ix_(act, act)]
    v_act, impulse = _projection(M, J[:, act], v[act])
    v_plus = np.zeros(N_COORDINATES)
    v_plus[act] = v_act
    return v_plus, impulse


def _posture(rng: np.random.Generator, legs: float = 0.1, upper: float = 0.3) -> np.ndarray:
    """Bent-knee stance with random legs (+-legs) and torso/arms/head (+-upper)."""
    q = np.zeros(N_COORDINATES)
    q[2:8] = 2.0 * KNEE_BENT + rng.uniform(-legs, legs, 6)
    q[8:] = rng.uniform(-upper, upper, 10)
    for i, (lower, upper_limit) in JOINT_LIMITS.items():
        q[i] = np.clip(q[i], lower + 0.05, upper_limit - 0.05)
    q[Y0] = rng.uniform(-1.0, 1.0)
    return q


def _on_constraints(dynamics, contact: ContactState, q: np.ndarray) -> np.ndarray:
    """Project q onto the swing constraints of ``contact`` and check they hold exactly."""
    q, _ = project_positions(dynamics, contact, q, iterations=60)
    C, _ = dynamics.constraint_residuals(contact, q, np.zeros(N_COORDINATES))
    assert np.max(np.abs(C)) < 1e-13, f'projection did not converge: residuals {C}'
    return q


def _double_support(dynamics, robot, rng, support: str, swing: str, side: str,
                    ) -> HybridState:
    """A double-support state whose swing constraints and their velocities hold exactly."""
    mode = mode_for(support, swing)
    pivot = str(rng.choice(['toe', 'heel']))
    q = _posture(rng)
    if mode.q1_active:  # toe pivot: heel up (q1 < 0); heel pivot: toe up (q1 > 0)
        q[Q1] = rng.uniform(0.02, 0.2) * (-1.0 if pivot == 'toe' else 1.0)
    if swing in ('Hp', 'Hs'):
        q[7] += 0.25  # swing toe up: only the heel touches
    contact = ContactState(mode, side, pivot)
    heel = dynamics.frame_placement(contact, q, 'swing_heel').translation
    contact = replace(contact, heel_anchor_y=float(heel[1]), heel_slide_dir=1.0,
                      support_slide_dir=1.0)
    q = _on_constraints(dynamics, contact, q)
    v = np.zeros(N_COORDINATES)
    v[mode.active] = rng.uniform(-1.0, 1.0, mode.active.size)
    v, _ = _impact_expected(robot, contact, q, v, _rows(robot, contact, q))
    _, Jv = dynamics.constraint_residuals(contact, q, v)
    assert np.max(np.abs(Jv)) < 1e-13
    return HybridState(1.2345, q, v, contact, step_index=4, t_exchange=0.5, t_touchdown=1.0)


# ------------------------------------------------------------------------- re-rooting E7
@pytest.mark.parametrize(('swing', 'side'),
                         list(itertools.product(SWING_CONTACT_CODES, SIDES)))
def test_reroot_keeps_world_pose_and_velocity_of_every_link(robot, dynamics, swing, side):
    rng = np.random.default_rng([20190605, SWING_CONTACT_CODES.index(swing),
                                 SIDES.index(side)])
    for support in SUPPORT_CODES:
        for _ in range(2):
            old = _double_support(dynamics, robot, rng, support, swing, side)
            new = reroot(dynamics, old)
            oc, nc = old.contact, new.contact

            # bookkeeping of docs/model.md §7.4
            assert new.mode.swing == 'A'
            assert new.mode.support == NEW_SUPPORT[swing]
            if swing in ('Hp', 'Hs'):
                assert nc.pivot == 'heel'
            assert nc.side == ('left' if side == 'right' else 'right')
            assert new.step_index == old.step_index + 1
            assert new.t == old.t and new.t_exchange == old.t
            assert np.isnan(new.t_touchdown)
            locked = _locked(new.mode)
            assert np.all(new.v[locked] == 0.0), new.v[locked]
            # the coordinate map: new q1 = old swing-foot pitch, new swing pitch = old q1
            assert new.q[Q1] == pytest.approx(old.q[1:8].sum() if new.mode.q1_active else 0.0,
                                              abs=1e-14)
            assert new.q[1:8].sum() == pytest.approx(old.q[Q1], abs=1e-13)

            names = [*LINK_NAMES, 'head_top', 'pelvis_centre']
            for name in names:
                before = dynamics.frame_placement(oc, old.q, name).homogeneous
                after = dynamics.frame_placement(nc, new.q, name).homogeneous
                err = np.max(np.abs(after - before))
                assert err <= 1e-12, f'{support}/{swing} {side}: {name} pose moved by {err:.2e}'
                vb = dynamics.frame_velocity(oc, old.q, old.v, name).vector
                va = dynamics.frame_velocity(nc, new.q, new.v, name).vector
                err = np.max(np.abs(va - vb))
                assert err <= 1e-12, (f'{support}/{swing} {side}: {name} velocity changed by '
                                      f'{err:.2e}')
            # the feet swap roles: old swing heel/toe = new support heel/toe and vice versa
            for a, b in (('swing_heel', 'support_heel'), ('swing_toe', 'support_toe'),
                         ('support_heel', 'swing_heel'), ('support_toe', 'swing_toe')):
                pa = dynamics.frame_placement(oc, old.q, a).translation
                pb = dynamics.frame_placement(nc, new.q, b).translation
                assert np.max(np.abs(pa - pb)) <= 1e-12, (a, b, pa, pb)
            # the new state is a valid state of its mode
            dynamics.evaluate(nc, new.q, new.v, np.zeros(N_COORDINATES))


@pytest.mark.parametrize('swing', ['Hs', 'Fs'])
def test_reroot_of_a_sliding_swing_foot_carries_its_speed_into_y0(robot, dynamics, swing):
    """Hs -> R-G, Fs -> F-G: the new support glides at the old heel speed, in its direction
    (a Coulomb floor lets it slide backward too)."""
    rng = np.random.default_rng(7)
    base = _double_support(dynamics, robot, rng, 'F-S', swing, 'right')
    for sign in (1.0, -1.0):  # -v meets the constraints as well: both slide directions
        old = replace(base, v=sign * base.v)
        heel_vy = dynamics.frame_velocity(old.contact, old.q, old.v, 'swing_heel').linear[1]
        assert abs(heel_vy) > 1e-3
        old = replace(old, contact=replace(old.contact, heel_slide_dir=float(np.sign(heel_vy))))
        new = reroot(dynamics, old)
        assert new.mode.y0_active
        assert new.v[Y0] == pytest.approx(heel_vy, abs=1e-14)
        assert new.contact.support_slide_dir == np.sign(heel_vy)


@pytest.mark.parametrize('swing', SWING_CONTACT_CODES)
def test_a_rerooted_command_does_the_same_work_on_every_motor(robot, dynamics, swing):
    """A command held over a period that re-roots keeps driving the same motors: on the motion
    of any one joint, carried into the new coordinates by the re-root's velocity map, the
    re-rooted command at the re-rooted state does the work the old one did at the old state.
    Its y0 and q1 entries, floor reactions on the old support foot, do no work any more."""
    rng = np.random.default_rng([424242, SWING_CONTACT_CODES.index(swing)])
    for support in SUPPORT_CODES:
        old = _double_support(dynamics, robot, rng, support, swing, 'right')
        command = HeldCommand(rng.uniform(-50.0, 50.0, N_COORDINATES),
                              rng.uniform(0.0, 500.0, N_COORDINATES),
                              rng.uniform(0.0, 30.0, N_COORDINATES))
        new = reroot(dynamics, old)
        before = command.torque(old.q, old.v)
        after = rerooted_command(command).torque(new.q, new.v)
        for j in range(N_COORDINATES):
            motion = np.zeros(N_COORDINATES)
            motion[j] = 1.0
            carried = reroot(dynamics, replace(old, v=motion)).v
            work = before[j] if j not in (Y0, Q1) else 0.0
            assert after @ carried == pytest.approx(work, abs=1e-9), (support, j)


def test_reroot_needs_a_swing_contact(dynamics):
    q = np.zeros(N_COORDINATES)
    q[2:8] = KNEE_BENT
    state = HybridState(0.0, q, np.zeros(N_COORDINATES), ContactState(get_mode(1)))
    with pytest.raises(SimulationError, match='swing contact'):
        reroot(dynamics, state)


# ------------------------------------------------------------------------------ impacts
def _heel_down_posture(dynamics, side: str) -> np.ndarray:
    """Support flat and stuck, swing heel exactly on the floor, swing toe up (0.2 rad)."""
    q = np.zeros(N_COORDINATES)
    q[2:8] = (-0.05, 0.1, -0.05, 0.3, -0.55, 0.45)
    q = _on_constraints(dynamics, ContactState(get_mode(5), side), q)
    toe = dynamics.frame_placement(ContactState(get_mode(5), side), q, 'swing_toe')
    assert toe.translation[2] > 0.05  # only the heel touches
    return q


def _heel_velocity_state(robot, dynamics, side: str, heel_v: tuple[float, float],
                         ) -> HybridState:
    """Mode 1 with the heel on the floor and the least-norm joint velocity giving heel_v."""
    q = _heel_down_posture(dynamics, side)
    contact = ContactState(get_mode(1), side)
    act = contact.mode.active
    jac = _heel_jacobian(robot, contact, q)
    v = np.zeros(N_COORDINATES)
    v[act] = np.linalg.pinv(jac[1:3, act]) @ np.asarray(heel_v)
    return HybridState(0.75, q, v, contact)


def _heel_vy_after_normal_impact(robot, state: HybridState) -> float:
    sliding = replace(state.contact, mode=get_mode(5))
    v_plus, _ = _impact_expected(robot, sliding, state.q, state.v,
                                 _rows(robot, sliding, state.q))
    return float(_heel_jacobian(robot, sliding, state.q)[1] @ v_plus)


def _check_impact(robot, dynamics, before: HybridState, after: HybridState, J: np.ndarray,
                  impulse: tuple[float, ...]) -> np.ndarray:
    """Common checks: J v+ = 0, v+ and impulses as projected here, no energy gain."""
    expected_v, expected_pi = _impact_expected(robot, before.contact, after.q, before.v, J)
    act = before.contact.mode.active
    assert np.max(np.abs(J[:, act] @ after.v[act])) <= 1e-10
    np.testing.assert_allclose(after.v, expected_v, rtol=0, atol=1e-10)
    np.testing.assert_allclose(impulse, expected_pi, rtol=1e-9, atol=1e-10)
    k_before = _kinetic(robot, before.contact, after.q, before.v)
    k_after = _kinetic(robot, after.contact, after.q, after.v)
    assert k_after <= k_before
    dv = before.v - after.v  # inelastic projection: the loss is 1/2 dv' M dv
    loss = _kinetic(robot, before.contact, after.q, dv)
    assert k_before - k_after == pytest.approx(loss, rel=1e-9, abs=1e-12)
    assert loss > 0.0
    np.testing.assert_array_equal(after.v[_locked(after.mode)], 0.0)
    return expected_pi


@pytest.mark.parametrize('side', SIDES)
@pytest.mark.parametrize(('heel_v', 'expected_swing'), [
    ((-0.3, -0.5), 'Hp'),  # heel moving backward: toe pick pins it
    ((1.5, -0.5), 'Hs'),  # heel still moving forward after the impact: glides
])
def test_heel_strike_impact_on_ice(robot, dynamics, side, heel_v, expected_swing):
    state = _heel_velocity_state(robot, dynamics, side, heel_v)
    vy_after = _heel_vy_after_normal_impact(robot, state)
    assert (vy_after > EPS_V) == (expected_swing == 'Hs'), vy_after  # the scenario is as named
    result = dynamics.evaluate(state.contact, state.q, state.v, np.zeros(N_COORDINATES))
    new, record = apply_transition(dynamics, ICE, state, GUARD['S1'], result)
    assert new.mode.support == 'F-S' and new.mode.swing == expected_swing
    assert record.event == 'S1' and record.from_mode == 1 and record.to_mode == new.mode.number
    J = _rows(robot, new.contact, new.q)
    pi = _check_impact(robot, dynamics, replace(state, contact=new.contact), new, J,
                       record.impulse)
    assert pi[0] >= 0.0  # the floor pushes
    assert new.t_touchdown == state.t
    np.testing.assert_allclose(new.q, state.q, rtol=0, atol=1e-14)  # positions continuous
    if expected_swing == 'Hp':
        heel = dynamics.frame_placement(new.contact, new.q, 'swing_heel').translation
        assert new.contact.heel_anchor_y == pytest.approx(heel[1], abs=1e-14)
    else:
        assert new.contact.heel_slide_dir == 1.0
        heel_v_after = dynamics.frame_velocity(new.contact, new.q, new.v, 'swing_heel')
        assert heel_v_after.linear[1] == pytest.approx(vy_after, abs=1e-10)


@pytest.mark.parametrize(('excess', 'expected_swing'), [(0.5 * EPS_V, 'Hp'), (2.0 * EPS_V, 'Hs')])
def test_heel_strike_dead_band(robot, dynamics, excess, expected_swing):
    """Forward heel speed after the impact within the 1e-4 m/s dead band pins the heel."""
    probe = _heel_velocity_state(robot, dynamics, 'right', (0.0, -0.5))
    coupling = _heel_vy_after_normal_impact(robot, probe)  # vy after, from vz alone
    state = _heel_velocity_state(robot, dynamics, 'right', (excess - coupling, -0.5))
    assert _heel_vy_after_normal_impact(robot, state) == pytest.approx(excess, abs=1e-9)
    result = dynamics.evaluate(state.contact, state.q, state.v, np.zeros(N_COORDINATES))
    new, _ = apply_transition(dynamics, ICE, state, GUARD['S1'], result)
    assert new.mode.swing == expected_swing


@pytest.mark.parametrize('side', SIDES)
@pytest.mark.parametrize('friction', [ICE, FrictionModel(MU_ICE, 'coulomb'),
                                      FrictionModel(1.0, 'coulomb')])
def test_heel_strike_with_the_heel_moving_up_is_rejected(robot, dynamics, side, friction):
    state = _heel_velocity_state(robot, dynamics, side, (0.0, 0.5))
    result = dynamics.evaluate(state.contact, state.q, state.v, np.zeros(N_COORDINATES))
    new, record = apply_transition(dynamics, friction, state, GUARD['S1'], result)
    assert new.mode.number == 1
    np.testing.assert_array_equal(new.q, state.q)
    np.testing.assert_array_equal(new.v, state.v)
    assert new.contact == state.contact
    assert record.impulse == () and record.to_mode == record.from_mode == 1


def test_heel_strike_on_a_normal_floor_is_symmetric(robot, dynamics):
    """Coulomb: a heel moving backward slides backward when |Pi_y| > mu Pi_z, else pins."""
    state = _heel_velocity_state(robot, dynamics, 'right', (-0.3, -0.5))
    vy_after = _heel_vy_after_normal_impact(robot, state)
    assert vy_after < -0.1
    pinned = replace(state.contact, mode=get_mode(9))
    _, pi_pin = _impact_expected(robot, pinned, state.q, state.v, _rows(robot, pinned, state.q))
    ratio = abs(pi_pin[1]) / pi_pin[0]
    assert 0.01 < ratio < 0.9  # slides at mu = 0.005, sticks at mu = 1
    result = dynamics.evaluate(state.contact, state.q, state.v, np.zeros(N_COORDINATES))
    low, _ = apply_transition(dynamics, FrictionModel(MU_ICE, 'coulomb'), state, GUARD['S1'],
                              result)
    assert low.mode.swing == 'Hs' and low.contact.heel_slide_dir == -1.0
    high, _ = apply_transition(dynamics, FrictionModel(1.0, 'coulomb'), state, GUARD['S1'],
                               result)
    assert high.mode.swing == 'Hp'


def _flat_heel_down_state(robot, dynamics, rng, support: str, swing: str, side: str,
                          ) -> HybridState:
    """Swing heel on the floor with the sole exactly flat (C_fr = 0), toe coming down."""
    flat_mode = mode_for(support, 'Fp')
    contact = ContactState(flat_mode, side, 'toe')
    q = np.zeros(N_COORDINATES)
    q[2:8] = 2.0 * KNEE_BENT + rng.uniform(-0.05, 0.05, 6)
    q[8:] = rng.uniform(-0.2, 0.2, 10)
    for i, (lower, upper) in JOINT_LIMITS.items():
        q[i] = np.clip(q[i], lower + 0.05, upper - 0.05)
    contact = replace(contact, heel_anchor_y=float(
        dynamics.frame_placement(contact, q, 'swing_heel').translation[1]))
    q = _on_constraints(dynamics, contact, q)
    contact = replace(contact, mode=mode_for(support, swing))
    v = np.zeros(N_COORDINATES)
    v[contact.mode.active] = rng.uniform(-1.0, 1.0, contact.mode.active.size)
    v, _ = _impact_expected(robot, contact, q, v, _rows(robot, contact, q))
    if v[1:8].sum() > 0.0:  # the projection is linear: -v also meets the constraints
        v = -v
    assert v[1:8].sum() < -1e-3
    return HybridState(2.0, q, v, contact)


@pytest.mark.parametrize('side', SIDES)
@pytest.mark.parametrize(('swing', 'flat'), [('Hp', 'Fp'), ('Hs', 'Fs')])
def test_foot_slap_impact(robot, dynamics, side, swing, flat):
    rng = np.random.default_rng([11, SIDES.index(side), len(swing + flat)])
    state = _flat_heel_down_state(robot, dynamics, rng, 'F-S', swing, side)
    result = dynamics.evaluate(state.contact, state.q, state.v, np.zeros(N_COORDINATES))
    assert guard_values(state, result, ICE)[
        [g.name for g in guards_of(state.mode)].index('S4')] == pytest.approx(0.0, abs=1e-12)
    new, record = apply_transition(dynamics, ICE, state, GUARD['S4'], result)
    assert new.mode == mode_for('F-S', flat)
    J = _rows(robot, new.contact, new.q)
    pi = _check_impact(robot, dynamics, replace(state, contact=new.contact), new, J,
                       record.impulse)
    assert pi[-1] > 0.0  # the floor pushes the toe up: positive pitch impulse (tau_n sign)
    assert pi[0] >= 0.0


@pytest.mark.parametrize(('mode', 'pivot', 'new_mode'), [
    (2, 'toe', 1), (2, 'heel', 1), (4, 'toe', 3), (10, 'toe', 9), (14, 'heel', 13)])
def test_support_slap_impact(robot, dynamics, mode, pivot, new_mode):
    """E3: q1 comes back to 0 (toe pivot from below, heel pivot from above)."""
    rng = np.random.default_rng([13, mode, len(pivot)])
    gait_mode = get_mode(mode)
    contact = ContactState(gait_mode, 'left', pivot)
    q = _posture(rng, legs=0.05, upper=0.2)
    q[Q1] = 0.0
    if gait_mode.constraints:
        contact = replace(contact, heel_anchor_y=float(
            dynamics.frame_placement(contact, q, 'swing_heel').translation[1]))
        q = _on_constraints(dynamics, contact, q)
    else:
        q[5:8] = (0.3, -0.6, 0.3)  # swing foot in the air
    v = np.zeros(N_COORDINATES)
    v[gait_mode.active] = rng.uniform(-0.5, 0.5, gait_mode.active.size)
    back = 1.0 if pivot == 'toe' else -1.0  # the sign of q1' that returns the sole to flat
    v[Q1] = back
    if gait_mode.constraints:
        v, _ = _impact_expected(robot, contact, q, v, _rows(robot, contact, q))
        if v[Q1] * back < 0.0:  # the projection is linear: -v also meets the constraints
            v = -v
        assert v[Q1] * back > 0.05
    state = HybridState(3.0, q, v, contact)
    result = dynamics.evaluate(contact, q, v, np.zeros(N_COORDINATES))
    new, record = apply_transition(dynamics, ICE, state, GUARD['E3'], result)
    assert new.mode.number == new_mode
    assert new.q[Q1] == 0.0 and new.v[Q1] == 0.0
    e_q1 = np.zeros((1, N_COORDINATES))
    e_q1[0, Q1] = 1.0
    J = np.vstack([e_q1, _rows(robot, contact, new.q)])
    pi = _check_impact(robot, dynamics, state, new, J, record.impulse)
    assert pi[0] * v[Q1] < 0.0  # the floor's impulse stops the rotation
    new_rows = _rows(robot, new.contact, new.q)
    assert np.max(np.abs(new_rows @ new.v), initial=0.0) <= 1e-10


# ----------------------------------------------------------------------------- ice rule
def _result(**values) -> DynamicsResult:
    """A DynamicsResult with only the fields a guard reads set."""
    fields = dict(qdd=np.zeros(N_COORDINATES), multipliers=np.zeros(3),
                  support_wrench=np.zeros(6), support_normal=600.0, support_friction=0.0,
                  zmp_y=0.0, heel_friction=0.0, applied=np.zeros(N_COORDINATES),
                  swing_heel=np.array([0.0, 0.0, 0.05]), swing_heel_velocity=np.zeros(3),
                  swing_toe_z=0.05)
    fields.update(values)
    return DynamicsResult(**fields)


def _state(mode: int, **contact) -> HybridState:
    q = np.zeros(N_COORDINATES)
    q[2:8] = KNEE_BENT
    return HybridState(0.0, q, np.zeros(N_COORDINATES), ContactState(get_mode(mode), **contact))


N_S = 600.0
# (reaction F_y as a multiple of mu N, due on ice, due on a symmetric Coulomb floor). The guards
# may carry small dead bands against chattering (docs/model.md §6.3), so the cases stay
# clear of the friction limit: mu N = 3 N here, the nearest case is 9 N beyond or 1.5 N inside.
TANGENTIAL_CASES = [(-20.0, True, True), (-4.0, True, True), (-0.5, False, False),
                    (0.0, False, False), (0.5, False, False), (4.0, False, True),
                    (1000.0, False, True)]


@pytest.mark.parametrize(('ratio', 'ice_due', 'coulomb_due'), TANGENTIAL_CASES)
def test_support_slip_guard_e4(ratio, ice_due, coulomb_due):
    """E4: on ice only a reaction pointing back beyond mu N starts a glide (toe pick)."""
    for mode in (1, 2, 9, 18):
        result = _result(support_normal=N_S, support_friction=ratio * MU_ICE * N_S)
        state = _state(mode)
        ice = GUARD_VALUES['E4'](state, result, ICE)
        coulomb = GUARD_VALUES['E4'](state, result, FrictionModel(MU_ICE, 'coulomb'))
        assert (ice > 0.0) == ice_due, (mode, ratio, ice)
        assert (coulomb > 0.0) == coulomb_due, (mode, ratio, coulomb)
        mirrored = _result(support_normal=N_S, support_friction=-ratio * MU_ICE * N_S)
        assert GUARD_VALUES['E4'](state, mirrored, FrictionModel(MU_ICE, 'coulomb')) == \
            pytest.approx(coulomb, abs=1e-12)  # symmetric


@pytest.mark.parametrize(('ratio', 'ice_due', 'coulomb_due'), TANGENTIAL_CASES)
def test_heel_slip_guard_s3(ratio, ice_due, coulomb_due):
    """S3: a pinned heel starts sliding under the same one-way rule on f_ny / f_nz."""
    f_nz = 200.0
    for mode in (9, 10, 17, 18):
        result = _result(multipliers=np.array([f_nz, ratio * MU_ICE * f_nz, 0.0]))
        state = _state(mode)
        assert (GUARD_VALUES['S3'](state, result, ICE) > 0.0) == ice_due
        coulomb = FrictionModel(MU_ICE, 'coulomb')
        assert (GUARD_VALUES['S3'](state, result, coulomb) > 0.0) == coulomb_due


@pytest.mark.parametrize(('mode', 'glide_mode'), [(1, 3), (2, 4), (9, 11), (18, 20)])
def test_e4_starts_a_forward_glide_on_ice_and_either_way_on_coulomb(dynamics, mode,
                                                                    glide_mode):
    state = _state(mode)
    back = _result(support_friction=-2.0 * MU_ICE * N_S)
    new, _ = apply_transition(dynamics, ICE, state, GUARD['E4'], back)
    assert new.mode.number == glide_mode and new.contact.support_slide_dir == 1.0
    assert new.v[Y0] == 0.0 and new.q[Y0] == state.q[Y0]
    coulomb = FrictionModel(MU_ICE, 'coulomb')
    forward = _result(support_friction=2.0 * MU_ICE * N_S)  # floor pushes forward: the
    new, _ = apply_transition(dynamics, coulomb, state, GUARD['E4'], forward)  # foot goes back
    assert new.mode.number == glide_mode and new.contact.support_slide_dir == -1.0


def test_s3_unpins_the_heel(dynamics):
    state = _state(17)
    new, _ = apply_transition(dynamics, ICE, state, GUARD['S3'],
                              _result(multipliers=np.array([100.0, -10.0, 0.0])))
    assert new.mode.number == 13 and new.contact.heel_slide_dir == 1.0
    coulomb = FrictionModel(MU_ICE, 'coulomb')
    new, _ = apply_transition(dynamics, coulomb, _state(9), GUARD['S3'],
                              _result(multipliers=np.array([100.0, 10.0, 0.0])))
    assert new.mode.number == 5 and new.contact.heel_slide_dir == -1.0


@pytest.mark.parametrize(('direction', 'speed', 'due'), [
    (1.0, 0.3, False), (1.0, 1e-6, False), (1.0, -1e-6, True), (-1.0, -0.3, False),
    (-1.0, 1e-6, True)])
def test_glide_stop_guard_e5(dynamics, direction, speed, due):
    """E5: a glide stops when its speed reaches zero (in its own slide direction)."""
    state = _state(3, support_slide_dir=direction)
    v = state.v.copy()
    v[Y0] = speed
    state = replace(state, v=v)
    assert (GUARD_VALUES['E5'](state, _result(), ICE) > 0.0) == due
    new, _ = apply_transition(dynamics, ICE, state, GUARD['E5'], _result())
    assert new.mode.number == 1 and new.v[Y0] == 0.0 and new.q[Y0] == state.q[Y0]


def test_ice_rule_with_real_reactions(robot, dynamics):
    """On a stuck support foot, F_y is m times the CoM acceleration along y (swing foot in
    the air); on ice E4 is due only when the body accelerates backward harder than mu (g +
    z_com''), never when it pushes forward against the toe pick."""
    contact = ContactState(get_mode(1), 'right')
    q = np.zeros(N_COORDINATES)
    q[2:8] = (-0.05, 0.1, -0.05, 0.3, -0.6, 0.3)
    model, data, _ = _model(robot, contact)
    gravity = pin.computeGeneralizedGravity(model, data, q)
    mass = robot.total_mass
    seen = set()
    for ankle in (-40.0, -5.0, -0.5, 0.5, 5.0, 40.0):
        tau = gravity.copy()
        tau[2] += ankle
        result = dynamics.evaluate(contact, q, np.zeros(N_COORDINATES), tau)
        jcom = pin.jacobianCenterOfMass(model, data, q)
        a_com = jcom @ result.qdd  # v = 0: no velocity-product term
        assert result.support_friction == pytest.approx(mass * a_com[1], rel=1e-9, abs=1e-9)
        assert result.support_normal == pytest.approx(mass * (G + a_com[2]), rel=1e-9)
        e4_ice = GUARD_VALUES['E4'](_state(1), result, ICE) > 0.0
        e4_coulomb = GUARD_VALUES['E4'](_state(1), result,
                                       FrictionModel(MU_ICE, 'coulomb')) > 0.0
        limit = MU_ICE * mass * (G + a_com[2])  # mu N_s
        push_back, push_forward = -mass * a_com[1] - limit, mass * a_com[1] - limit
        assert min(abs(push_back), abs(push_forward)) > 1.0  # clear of any dead band
        backward, forward = push_back > 0.0, push_forward > 0.0
        assert e4_ice == backward
        assert e4_coulomb == (backward or forward)
        seen.add((backward, forward))
    assert seen == {(True, False), (False, True), (False, False)}  # all three cases occur


def _wrench(m_x: float) -> np.ndarray:
    w = np.zeros(6)
    w[3] = m_x
    return w


# (guard, mode, contact options, state q changes, result fields, due). Force, moment and CoP
# cases stay clear of the guards' anti-chattering dead bands (about 1 N, 0.1 N m, 1 mm, 2 mm).
SIGN_CASES = [
    # E1/E2: CoP = M_x / N_s relative to the ankle; toe edge +0.20, heel edge -0.06
    ('E1', 1, {}, {}, dict(support_wrench=_wrench(0.18 * N_S)), False),
    ('E1', 1, {}, {}, dict(support_wrench=_wrench(0.22 * N_S)), True),
    ('E2', 1, {}, {}, dict(support_wrench=_wrench(-0.04 * N_S)), False),
    ('E2', 1, {}, {}, dict(support_wrench=_wrench(-0.08 * N_S)), True),
    ('E1', 3, {}, {}, dict(support_wrench=_wrench(0.25 * N_S)), True),
    # E3: toe pivot has q1 < 0 (heel up), heel pivot q1 > 0 (toe up)
    ('E3', 2, dict(pivot='toe'), {Q1: -0.01}, {}, False),
    ('E3', 2, dict(pivot='toe'), {Q1: 1e-6}, {}, True),
    ('E3', 2, dict(pivot='heel'), {Q1: 0.01}, {}, False),
    ('E3', 2, dict(pivot='heel'), {Q1: -1e-6}, {}, True),
    # E6 / S6: a contact force reaching zero
    ('E6', 1, {}, {}, dict(support_normal=10.0), False),
    ('E6', 1, {}, {}, dict(support_normal=-10.0), True),
    ('S6', 9, {}, {}, dict(multipliers=np.array([10.0, 0.0, 0.0])), False),
    ('S6', 9, {}, {}, dict(multipliers=np.array([-10.0, 0.0, 0.0])), True),
    # S1 / S7: heel or toe below the floor
    ('S1', 1, {}, {}, dict(swing_heel=np.array([0.0, 0.0, 1e-3])), False),
    ('S1', 1, {}, {}, dict(swing_heel=np.array([0.0, 0.0, -1e-6])), True),
    ('S7', 1, {}, {}, dict(swing_toe_z=1e-3), False),
    ('S7', 1, {}, {}, dict(swing_toe_z=-0.01), True),
    # S2: a sliding heel stops (velocity reaches 0 in its slide direction)
    ('S2', 5, {}, {}, dict(swing_heel_velocity=np.array([0.0, 0.1, 0.0])), False),
    ('S2', 5, {}, {}, dict(swing_heel_velocity=np.array([0.0, -1e-6, 0.0])), True),
    ('S2', 5, dict(heel_slide_dir=-1.0), {},
     dict(swing_heel_velocity=np.array([0.0, -0.1, 0.0])), False),
    # S4: the swing sole pitch (sum q1..q7) comes down to 0 from above (toe up > 0)
    ('S4', 9, {}, {7: 0.05 + 0.1}, {}, False),
    ('S4', 9, {}, {7: 0.05 - 1e-6}, {}, True),
    # S5: tau_n < 0 would need the floor to pull the toe down
    ('S5', 17, {}, {}, dict(multipliers=np.array([100.0, 0.0, 2.0])), False),
    ('S5', 17, {}, {}, dict(multipliers=np.array([100.0, 0.0, -2.0])), True),
]


@pytest.mark.parametrize(('name', 'mode', 'contact', 'changes', 'fields', 'due'), SIGN_CASES)
def test_guard_signs(name, mode, contact, changes, fields, due):
    state = _state(mode, **contact)
    q = state.q.copy()
    for i, value in changes.items():
        q[i] = value
    state = replace(state, q=q)
    result = _result(**{'support_normal': N_S, **fields})
    value = GUARD_VALUES[name](state, result, ICE)
    assert (value > 0.0) == due, (name, value)
    position = [g.name for g in guards_of(state.mode)].index(name)
    assert guard_values(state, result, ICE)[position] == value


@pytest.mark.parametrize(('support', 'swing', 'named'), [
    ('F-X', 'A', "'F-X'"), ('F-S', 'Hx', "'Hx'"), ('A', 'F-S', "'A'"), ('f-s', 'a', "'f-s'")])
def test_mode_for_rejects_unknown_codes_naming_them(support, swing, named):
    with pytest.raises(SimulationError, match=named):
        mode_for(support, swing)
