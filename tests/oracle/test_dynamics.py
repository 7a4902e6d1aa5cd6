"""The oracle's constrained equations of motion (``oracle.dynamics.GaitDynamics``) in every
Table 2 mode (docs/model.md §2.5, §2.6, §4, §14.2); the shipped model terms it builds on
(``ModelTerms``: M, h, g, the head pose) and the native kernel's input checks are
tests/iceskate_sim/test_model_terms.py.

Each property is checked against an independent computation: Pinocchio's Jacobian time
variation (itself checked against finite differences), the RNEA equations of motion,
whole-body momentum balance for the support wrench, a fresh evaluation for the kept terms.
"""

from dataclasses import fields
import itertools
import math

import numpy as np
import pinocchio as pin
import pytest

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.dynamics import ContactState, DynamicsParameters, DynamicsResult
from iceskate_sim.model.modes import MODES, get_mode
from iceskate_sim.model.robot import N_COORDINATES
from oracle.dynamics import GaitDynamics
from oracle.fixtures import mode_cases as _cases
from oracle.fixtures import random_torques as _tau

LWA = pin.LOCAL_WORLD_ALIGNED
G = 9.81
MASS = 64.2
ALL_MODES = sorted(MODES)
CONSTRAINED_MODES = [n for n in ALL_MODES if MODES[n].constraints]
SIDES = ('right', 'left')
PIVOTS = ('toe', 'heel')
HEEL_Y, TOE_Y = -0.06, 0.20
# docs/model.md §2.6 soft stops in Table-2 coordinates (knee upper bound: the URDF's 2.5 rad)
STOPS = {3: (0.0, 2.5), 6: (-2.5, 0.0), 8: (-1.0, 1.0), 9: (-0.8, 0.8), 10: (-0.8, 0.8),
         12: (0.0, 2.5), 13: (-1.0, 1.0), 15: (0.0, 2.5), 16: (-1.0, 1.0), 17: (-0.8, 0.8)}
DAMPING = np.array([0.0, 10, 10, 10, 10, 10, 10, 10, 10, 10, 10, 0.03, 1.0, 2.0, 0.03, 1.0,
                    2.0, 0.5])
K_STOP, C_STOP = 1.0e4, 100.0


def _swing(side: str) -> str:
    return 'left' if side == 'right' else 'right'


def _kinematics(model: pin.Model, q: np.ndarray, v: np.ndarray, qdd: np.ndarray) -> pin.Data:
    """A fresh data object with frames, Jacobians and their time variation at (q, v, qdd)."""
    data = model.createData()
    pin.forwardKinematics(model, data, q, v, qdd)
    pin.updateFramePlacements(model, data)
    pin.computeJointJacobians(model, data, q)
    pin.computeJointJacobiansTimeVariation(model, data, q, v)
    return data


def _frame_acceleration(model, data, fid, v, qdd):
    """Classical (world-aligned) acceleration of a frame: J qdd + Jdot v."""
    jac = pin.getFrameJacobian(model, data, fid, LWA)
    djac = pin.getFrameJacobianTimeVariation(model, data, fid, LWA)
    return jac @ qdd + djac @ v, jac


def _expected_applied(q, v, tau, mode, params: DynamicsParameters) -> np.ndarray:
    """Inputs + Table 1 damping + soft stops, written from docs/model.md §2.6."""
    applied = np.array(tau, dtype=float)
    applied[0] = 0.0  # y0 is unactuated
    if not mode.q1_active:
        applied[1] = 0.0
    if params.damping:
        applied -= DAMPING * v
    if params.joint_limits:
        for i, (lower, upper) in STOPS.items():
            if q[i] < lower:
                applied[i] -= K_STOP * (q[i] - lower) + C_STOP * v[i]
            elif q[i] > upper:
                applied[i] -= K_STOP * (q[i] - upper) + C_STOP * v[i]
    return applied


# ------------------------------------------------- (c) constraints hold at acceleration level
@pytest.mark.parametrize(('number', 'side', 'pivot'), _cases(CONSTRAINED_MODES))
@pytest.mark.parametrize('heel_dir', [1.0, -1.0])
def test_solution_satisfies_active_constraints(robot, random_state, rng, number, side, pivot,
                                               heel_dir, assert_close):
    mode = get_mode(number)
    dynamics = GaitDynamics(robot, DynamicsParameters(mu=0.3))
    contact = ContactState(mode, side, pivot, heel_anchor_y=0.1, heel_slide_dir=heel_dir)
    sm = robot.support_model(side, pivot)
    q, v = random_state(mode)
    qdd = dynamics.evaluate(contact, q, v, _tau(rng)).qdd
    data = _kinematics(sm.model, q, v, qdd)
    heel_acc, jac = _frame_acceleration(sm.model, data, sm.frame_ids['swing_heel'], v, qdd)
    foot_acc, _ = _frame_acceleration(sm.model, data, sm.frame_ids[f'{_swing(side)}_foot'], v,
                                      qdd)
    scale = np.abs(jac).max() * np.abs(qdd).max()  # size of the terms that must cancel
    residual = {'hz': heel_acc[2], 'hy': heel_acc[1], 'fr': foot_acc[3]}
    for name in mode.constraints:
        assert abs(residual[name]) <= 1e-10 * max(1.0, scale), (name, residual[name], scale)
    # the C_fr row of the paper (sum of q1..q7) is the swing sole's pitch rate
    if 'fr' in mode.constraints:
        assert_close(qdd[1:8].sum(), 0.0, atol=1e-10 * max(1.0, scale), what='sum qdd1..7')


@pytest.mark.parametrize(('number', 'side'), list(itertools.product([6, 20], SIDES)))
def test_jacobian_time_variation_matches_finite_differences(robot, random_state, number, side,
                                                            assert_close):
    """The reference of the previous test: Jdot v = d/dt (J(q) v) along q + t v."""
    sm = robot.support_model(side, 'toe')
    fid = sm.frame_ids['swing_heel']
    q, v = random_state(number)
    data = _kinematics(sm.model, q, v, np.zeros(N_COORDINATES))
    djac_v = pin.getFrameJacobianTimeVariation(sm.model, data, fid, LWA) @ v

    def jac_v(qq):
        d = sm.model.createData()
        pin.computeJointJacobians(sm.model, d, qq)
        pin.updateFramePlacements(sm.model, d)
        return pin.getFrameJacobian(sm.model, d, fid, LWA) @ v

    eps = 1e-5
    fd = (jac_v(q + eps * v) - jac_v(q - eps * v)) / (2 * eps)
    assert_close(djac_v, fd, rtol=1e-7, what='Jdot v')


def test_baumgarte_terms_pull_a_violated_constraint_back(robot, random_state, rng,
                                                         assert_close):
    alpha = 50.0
    dynamics = GaitDynamics(robot, DynamicsParameters(baumgarte=alpha))
    mode = get_mode(17)
    contact = ContactState(mode, 'right', 'toe', heel_anchor_y=-0.02)
    sm = robot.support_model('right', 'toe')
    q, v = random_state(mode, scale=0.1)
    qdd = dynamics.evaluate(contact, q, v, _tau(rng)).qdd
    data = _kinematics(sm.model, q, v, qdd)
    heel_acc, jac = _frame_acceleration(sm.model, data, sm.frame_ids['swing_heel'], v, qdd)
    heel = data.oMf[sm.frame_ids['swing_heel']].translation
    position = {'hz': heel[2], 'hy': heel[1] + 0.02, 'fr': q[1:8].sum()}
    velocity = {'hz': jac[2] @ v, 'hy': jac[1] @ v, 'fr': v[1:8].sum()}
    acceleration = {'hz': heel_acc[2], 'hy': heel_acc[1], 'fr': qdd[1:8].sum()}
    for name in mode.constraints:
        assert abs(position[name]) > 1e-3  # the random posture violates every constraint
        expected = -2 * alpha * velocity[name] - alpha ** 2 * position[name]
        assert_close(acceleration[name], expected, rtol=1e-9, what=name)
    # the residual helper reports the same positions and velocities
    pos, vel = dynamics.constraint_residuals(contact, q, v)
    assert_close(pos, [position[c] for c in mode.constraints], atol=1e-12, what='C(q)')
    assert_close(vel, [velocity[c] for c in mode.constraints], atol=1e-12, what='J qd')



# ------------------------------------------------------------ (d) equations-of-motion residual
@pytest.mark.parametrize(('number', 'side', 'pivot'), _cases(ALL_MODES))
@pytest.mark.parametrize('limits', ['inside', 'engaged'])
def test_equations_of_motion_residual(robot, random_state, rng, number, side, pivot, limits,
                                      assert_close):
    mu = 0.3
    params = DynamicsParameters(mu=mu)
    dynamics = GaitDynamics(robot, params)
    mode = get_mode(number)
    sm = robot.support_model(side, pivot)
    model = sm.model
    for support_dir, heel_dir in ((1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)):
        contact = ContactState(mode, side, pivot, heel_anchor_y=0.05,
                               support_slide_dir=support_dir, heel_slide_dir=heel_dir)
        q, v = random_state(mode)
        if limits == 'engaged':  # beyond the knee, yaw, elbow and neck stops
            q[3], q[6], q[8], q[12], q[17] = -0.05, 0.04, 1.1, -0.1, 0.9
        tau = _tau(rng)
        result = dynamics.evaluate(contact, q, v, tau)
        expected_applied = _expected_applied(q, v, tau, mode, params)
        assert_close(result.applied, expected_applied, rtol=1e-14, what='applied forces')
        qdd = result.qdd
        data = _kinematics(model, q, v, qdd)
        lhs = pin.rnea(model, model.createData(), q, v, qdd)  # M qdd + h + g
        j_heel = pin.getFrameJacobian(model, data, sm.frame_ids['swing_heel'], LWA)
        j_foot = pin.getFrameJacobian(model, data, sm.frame_ids[f'{_swing(side)}_foot'], LWA)
        f_nz, f_ny, tau_n = result.multipliers
        heel_friction = -mu * heel_dir * f_nz if mode.swing_sliding else 0.0
        assert result.heel_friction == pytest.approx(heel_friction, abs=1e-12)
        constraint = np.zeros(N_COORDINATES)
        if 'hz' in mode.constraints:
            constraint += j_heel[2] * f_nz + j_heel[1] * heel_friction
        if 'hy' in mode.constraints:
            constraint += j_heel[1] * f_ny
        if 'fr' in mode.constraints:
            constraint += j_foot[3] * tau_n  # pitch moment on the swing foot
        for name, value in zip(('f_nz', 'f_ny', 'tau_n'), (f_nz, f_ny, tau_n), strict=True):
            if name not in mode.multipliers:
                assert value == 0.0, name
        support = np.zeros(N_COORDINATES)
        if mode.y0_active:  # Coulomb friction on the gliding support foot
            support[0] = -mu * support_dir * result.support_normal
        residual = (lhs - expected_applied - constraint - support)[mode.active]
        assert_close(residual, np.zeros(mode.n_coordinates), atol=1e-9 * max(
            1.0, np.abs(lhs).max(), np.abs(constraint).max()), what='EOM residual')


# --------------------------------------------------------------- (e) support wrench and N_s
@pytest.mark.parametrize(('number', 'side', 'pivot'), _cases(ALL_MODES))
def test_support_reaction_from_momentum_balance(robot, random_state, rng, number, side, pivot,
                                                assert_close):
    mu = 0.3
    dynamics = GaitDynamics(robot, DynamicsParameters(mu=mu))
    mode = get_mode(number)
    sm = robot.support_model(side, pivot)
    model = sm.model
    for support_dir, heel_dir in ((1.0, 1.0), (-1.0, -1.0)):
        contact = ContactState(mode, side, pivot, support_slide_dir=support_dir,
                               heel_slide_dir=heel_dir)
        q, v = random_state(mode)
        result = dynamics.evaluate(contact, q, v, _tau(rng))
        qdd = result.qdd
        data = model.createData()
        pin.centerOfMass(model, data, q, v, qdd)
        com, com_acc = data.com[0].copy(), data.acom[0].copy()
        pin.framesForwardKinematics(model, data, q)
        f_nz, f_ny, tau_n = result.multipliers
        scale = MASS * G
        # N_s = m (g + zdd_com) - f_nz   (docs/model.md §4.4)
        expected_normal = MASS * (G + com_acc[2]) - f_nz
        assert result.support_normal == pytest.approx(expected_normal, abs=1e-9 * scale)
        assert result.support_normal == result.support_wrench[2]
        assert result.support_friction == result.support_wrench[1]
        if mode.y0_active:
            assert result.support_friction == pytest.approx(
                -mu * support_dir * result.support_normal, abs=1e-9 * scale)
        # whole-body Newton: m (c_dd + g e_z) = support force + swing-heel force
        heel = data.oMf[sm.frame_ids['swing_heel']].translation
        swing_force = np.array([0.0, f_ny + result.heel_friction, f_nz])
        force = result.support_wrench[:3]
        assert_close(force + swing_force, MASS * (com_acc + [0.0, 0.0, G]), atol=1e-9 * scale,
                     what='linear momentum balance')
        # whole-body Euler about the CoM: the support moment is taken at (x_support, y0, 0);
        # the q1 input/damping is a floor moment on the foot reported beside the contact
        origin = np.array([data.oMf[sm.frame_ids['support_heel']].translation[0], q[0], 0.0])
        if not mode.q1_active:
            assert_close(origin, data.oMf[sm.frame_ids['support_heel']].translation
                         + [0.0, -HEEL_Y, 0.0], atol=1e-12, what='support point')
        moment = result.support_wrench[3:] + np.cross(origin - com, force)
        moment += np.cross(heel - com, swing_force) + [tau_n, 0.0, 0.0]
        if mode.q1_active:
            moment[0] += result.applied[1]
        pin.computeCentroidalMomentumTimeVariation(model, data, q, v, qdd)
        assert_close(moment, data.dhg.angular, atol=1e-9 * scale, what='angular momentum')


# ------------------------------------------------------------------------ (f) centre of pressure
@pytest.mark.parametrize(('number', 'side', 'pivot'),
                         _cases([n for n in ALL_MODES if MODES[n].q1_active]))
def test_cop_is_the_pivot_edge_when_tipping(dynamics, random_state, rng, number, side, pivot):
    mode = get_mode(number)
    contact = ContactState(mode, side, pivot)
    seen_positive = 0
    for _ in range(4):
        q, v = random_state(mode, speed=0.3)
        result = dynamics.evaluate(contact, q, v, _tau(rng))
        if result.support_normal > 0.0:
            seen_positive += 1
            edge = TOE_Y if pivot == 'toe' else HEEL_Y
            assert result.zmp_y == pytest.approx(q[0] + edge, abs=1e-9)
            assert result.zmp_y == pytest.approx(dynamics.pivot_y(contact, q), abs=1e-9)
        else:
            assert math.isnan(result.zmp_y)
    assert seen_positive  # the check was not vacuous


@pytest.mark.parametrize(('lean', 'where'), [(0.0, 'inside'), (-0.35, 'ahead'),
                                             (0.2, 'behind'), (-0.15, 'inside')])
@pytest.mark.parametrize('side', SIDES)
def test_cop_of_a_flat_foot_in_static_balance_is_under_the_com(dynamics, side, lean, where):
    """Gravity-compensated and at rest (mode 1): qdd = 0, N_s = m g, CoP = CoM projection."""
    contact = ContactState(get_mode(1), side, 'toe')
    q = np.zeros(N_COORDINATES)
    q[0] = 0.3
    q[2:8] = (-0.05, 0.1, -0.05, 0.05, -0.1, 0.05)
    q[2] += lean  # support ankle: negative leans forward
    v = np.zeros(N_COORDINATES)
    tau = np.zeros(N_COORDINATES)
    tau[2:] = dynamics.gravity_terms(contact, q)
    result = dynamics.evaluate(contact, q, v, tau)
    assert np.abs(result.qdd).max() < 1e-9
    assert result.support_normal == pytest.approx(MASS * G, rel=1e-12)
    com_y = dynamics.center_of_mass(contact, q)[1]
    assert result.zmp_y == pytest.approx(com_y, abs=1e-9)
    heel, toe = dynamics.support_polygon_y(contact, q)
    assert (heel, toe) == pytest.approx((q[0] + HEEL_Y, q[0] + TOE_Y), abs=1e-15)
    position = ('behind' if result.zmp_y < heel else 'ahead' if result.zmp_y > toe
                else 'inside')
    assert position == where, (result.zmp_y, heel, toe)


# ------------------------------------------------------------ (i) singular double support
@pytest.mark.parametrize('number', [13, 15, 17, 19])
def test_straight_double_support_is_rank_deficient(dynamics, number):
    """Legs straight, support sole flat: every joint axis lies above the heel, so the
    heel-height row is -0.06 x the sole-pitch row (docs/model.md §4.5) when C_hz and C_fr act."""
    q = np.zeros(N_COORDINATES)
    zero = np.zeros(N_COORDINATES)
    with pytest.raises(SimulationError, match='rank-deficient') as info:
        dynamics.evaluate(ContactState(get_mode(number)), q, zero, zero)
    assert f'mode {number}' in str(info.value)


@pytest.mark.parametrize(('number', 'pivot'), [(5, 'toe'), (9, 'toe'), (14, 'toe'),
                                               (18, 'toe'), (18, 'heel')])
def test_straight_legs_are_regular_without_c_fr_or_with_q1(dynamics, number, pivot):
    """Without C_fr, or with q1 (its axis is on a sole edge, not above the ankle), the
    straight posture is not singular."""
    zero = np.zeros(N_COORDINATES)
    result = dynamics.evaluate(ContactState(get_mode(number), pivot=pivot), zero, zero, zero)
    assert np.all(np.isfinite(result.multipliers))
    assert abs(result.multipliers[0]) < 2 * MASS * G  # weight-sized, not a singular 1e17


@pytest.mark.parametrize('number', [13, 17])
@pytest.mark.parametrize('side', SIDES)
def test_bent_knee_double_support_solves(dynamics, side, number, assert_close):
    a = 0.05
    q = np.zeros(N_COORDINATES)
    q[2:8] = (-a, 2 * a, -a, a, -2 * a, a)
    zero = np.zeros(N_COORDINATES)
    mode = get_mode(number)
    contact = ContactState(mode, side, heel_anchor_y=HEEL_Y)  # heels side by side
    position, _velocity = dynamics.constraint_residuals(contact, q, zero)
    assert_close(position, np.zeros(len(mode.constraints)), atol=1e-12,
                 what='constraints of the bent stance')
    result = dynamics.evaluate(contact, q, zero, zero)
    f_nz = result.multipliers[0]  # (f_nz, f_ny, tau_n)
    assert np.all(np.isfinite(result.multipliers)) and np.all(np.isfinite(result.qdd))
    # the swing foot carries part of the weight, not a singular 1e17
    assert 0.0 < f_nz < MASS * G
    assert 0.0 < result.support_normal < MASS * G


@pytest.mark.parametrize(('number', 'side', 'pivot'), _cases(ALL_MODES))
def test_kept_terms_and_systems_give_a_fresh_evaluation_bit_for_bit(robot, random_state, rng,
                                                                     number, side, pivot):
    """``evaluate`` keeps the input-free terms of its last states (a period evaluates one state
    under two commands and the implicit step; an event search alternates two states), and
    ``implicit_acceleration`` reuses the system ``evaluate`` assembled just before for the same
    state and inputs. Under any sequence of evaluations and implicit steps over three states,
    two slide directions, repeated or new inputs, a push and soft stops, each result equals
    that of a new GaitDynamics exactly, and results cannot alter the kept terms."""
    mode = get_mode(number)
    contacts = [ContactState(mode, side, pivot, heel_anchor_y=0.1, heel_slide_dir=direction)
                for direction in (-1.0, 1.0)]
    params = DynamicsParameters(baumgarte=20.0)
    kept = GaitDynamics(robot, params)
    states = [random_state(mode), random_state(mode), random_state(mode, within_limits=False,
                                                                    scale=1.5)]
    inputs = None
    for i in (0, 0, 1, 0, 1, 2, 0, 2, 2, 1, 1, 0, 2, 2):
        q, v = states[i]
        contact = contacts[int(rng.integers(2))]
        if inputs is None or rng.random() < 0.5:  # else the same inputs again
            inputs = (_tau(rng), *rng.uniform(0.0, 50.0, (2, N_COORDINATES)))
        push = ('chest', rng.normal(0.0, 20.0, 3)) if rng.random() < 0.2 else None
        if rng.random() < 0.5:
            got = kept.evaluate(contact, q, v, inputs[0], push, *inputs[1:])
            want = GaitDynamics(robot, params).evaluate(contact, q, v, inputs[0], push,
                                                        *inputs[1:])
            for field in fields(DynamicsResult):
                np.testing.assert_array_equal(getattr(got, field.name),
                                              getattr(want, field.name), err_msg=field.name)
            with pytest.raises(ValueError, match='read-only'):
                got.passive[0] = 1.0
        step = float(rng.choice([1e-3, 4e-4]))
        if rng.random() < 0.3:  # the same state and inputs in the other slide direction
            contact = contacts[1] if contact is contacts[0] else contacts[0]
        got = kept.implicit_acceleration(contact, q, v, inputs[0], push, *inputs[1:], step)
        want = GaitDynamics(robot, params).implicit_acceleration(contact, q, v, inputs[0], push,
                                                                 *inputs[1:], step)
        np.testing.assert_array_equal(got, want, err_msg='implicit acceleration')


@pytest.mark.parametrize(('number', 'side', 'pivot'), _cases(ALL_MODES))
def test_implicit_acceleration_without_damping_is_the_exact_one(robot, random_state, rng,
                                                                number, side, pivot):
    """With no damping at all (joints, soft stops inside their range, impedance) the implicit
    step's matrix M + h D is M: its accelerations are ``evaluate``'s, bit for bit, whether the
    system is reused or assembled anew; with damping they differ by O(h)."""
    mode = get_mode(number)
    contact = ContactState(mode, side, pivot)
    q, v = random_state(mode)
    tau, stiffness = _tau(rng), rng.uniform(0.0, 50.0, N_COORDINATES)
    undamped = GaitDynamics(robot, DynamicsParameters(damping=False))
    exact = undamped.evaluate(contact, q, v, tau, None, stiffness, np.zeros(N_COORDINATES))
    for dynamics in (undamped, GaitDynamics(robot, DynamicsParameters(damping=False))):
        np.testing.assert_array_equal(dynamics.implicit_acceleration(
            contact, q, v, tau, None, stiffness, np.zeros(N_COORDINATES), 1e-3), exact.qdd)
    damped = GaitDynamics(robot, DynamicsParameters())
    gap = [np.max(np.abs(damped.implicit_acceleration(contact, q, v, tau, None, stiffness,
                                                      np.full(N_COORDINATES, 5.0), h)
                         - damped.evaluate(contact, q, v, tau, None, stiffness,
                                           np.full(N_COORDINATES, 5.0)).qdd))
           for h in (2e-6, 1e-6)]
    assert gap[0] > 0.0
    assert gap[1] == pytest.approx(gap[0] / 2.0, rel=0.05)  # first order in h
