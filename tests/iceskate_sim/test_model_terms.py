"""The shipped model terms of every Table 2 mode (``iceskate_sim.model.dynamics.ModelTerms``:
M, h, g, the head pose; docs/model.md §2.5, §4, §14.2) and the input checks of the native
eq. (7) (``NativeGaitDynamics``, probed). The oracle's eq. (7) itself:
tests/oracle/test_dynamics.py.

Each property is checked against an independent computation: RNEA instead of CRBA, masses and
centres of mass for the shoulder coupling, finite differences for the head Jacobian.
"""

import itertools
import math

import numpy as np
import pinocchio as pin
import pytest

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.dynamics import ContactState, DynamicsParameters
from iceskate_sim.model.modes import MODES, get_mode
from iceskate_sim.model.robot import N_COORDINATES
from oracle.fixtures import mode_cases as _cases
from oracle.fixtures import random_torques as _tau
from oracle.native_probes import NativeProbes

ALL_MODES = sorted(MODES)
SIDES = ('right', 'left')
PIVOTS = ('toe', 'heel')


# --------------------------------------------------------------------------- (a) mass matrix
@pytest.mark.parametrize(('number', 'side', 'pivot'), _cases(ALL_MODES))
def test_mass_matrix_is_symmetric_positive_definite(dynamics, random_state, number, side,
                                                    pivot, assert_close):
    mode = get_mode(number)
    contact = ContactState(mode, side, pivot)
    model = dynamics.robot.support_model(side, pivot).model
    for _ in range(3):
        q, _v = random_state(mode, scale=1.0)
        M = dynamics.mass_matrix(contact, q)
        assert M.shape == (mode.n_coordinates,) * 2
        np.testing.assert_array_equal(M, M.T)
        np.linalg.cholesky(M)  # raises unless positive definite
        assert np.linalg.eigvalsh(M)[0] > 1e-4
        # column j of M is the RNEA torque of a unit acceleration at rest, minus gravity
        data = model.createData()
        zero = np.zeros(N_COORDINATES)
        gravity = pin.rnea(model, data, q, zero, zero).copy()
        columns = [pin.rnea(model, data, q, zero, np.eye(N_COORDINATES)[j]) - gravity
                   for j in mode.active]
        reference = np.array(columns).T[mode.active]
        assert_close(M, reference, rtol=1e-12, what='M against RNEA columns')


# ---------------------------------------------------------- (b) inverse-dynamics identity
@pytest.mark.parametrize(('number', 'side', 'pivot'), _cases(ALL_MODES))
def test_rnea_equals_m_qdd_plus_h_plus_g(dynamics, random_state, rng, number, side, pivot,
                                         assert_close):
    mode = get_mode(number)
    contact = ContactState(mode, side, pivot)
    model = dynamics.robot.support_model(side, pivot).model
    q, v = random_state(mode)
    result = dynamics.evaluate(contact, q, v, _tau(rng))
    qdd = result.qdd
    assert np.all(qdd[[i for i in range(N_COORDINATES) if i not in mode.active]] == 0.0)
    rnea = pin.rnea(model, model.createData(), q, v, qdd)[mode.active]
    M = dynamics.mass_matrix(contact, q)
    h = dynamics.bias_terms(contact, q, v)
    g = dynamics.gravity_terms(contact, q)
    assert_close(M @ qdd[mode.active] + h + g, rnea, rtol=1e-10, what='M qdd + h + g')
    # and gravity alone is RNEA at rest: g(q) = rnea(q, 0, 0)
    zero = np.zeros(N_COORDINATES)
    assert_close(g, pin.rnea(model, model.createData(), q, zero, zero)[mode.active],
                 rtol=1e-12, what='g(q)')


# --------------------------------------------- (g) shoulder coupling sign (docs/model.md §2.5)
def _arm_moment(model: pin.Model, first_joint: int) -> float:
    """x_com * sum m l_c of the arm chain q_first..q_first+2, from masses and CoMs at zero."""
    data = model.createData()
    pin.forwardKinematics(model, data, np.zeros(N_COORDINATES))
    yaw_axis = data.oMi[model.getJointId('q8')].translation
    shoulder = data.oMi[model.getJointId(f'q{first_joint}')].translation
    total = 0.0
    for i in range(first_joint, first_joint + 3):
        jid = model.getJointId(f'q{i}')
        inertia = model.inertias[jid]
        com = data.oMi[jid].act(inertia.lever)
        total += inertia.mass * (com[0] - yaw_axis[0]) * (shoulder[2] - com[2])
    return total


@pytest.mark.parametrize(('side', 'pivot'), list(itertools.product(SIDES, PIVOTS)))
def test_shoulder_yaw_coupling_sign_pattern(dynamics, rng, side, pivot, assert_close):
    contact = ContactState(get_mode(4), side, pivot)  # all 18 coordinates active
    model = dynamics.robot.support_model(side, pivot).model
    M = dynamics.mass_matrix(contact, np.zeros(N_COORDINATES))
    right, left = _arm_moment(model, 11), _arm_moment(model, 14)
    # one arm chain: s * (2.3 * 0.155 + 1.4 * 0.43 + 0.4 * 0.64), s = 0.20
    assert right == pytest.approx(0.20 * (2.3 * 0.155 + 1.4 * 0.43 + 0.4 * 0.64), abs=1e-12)
    assert left == pytest.approx(-right, abs=1e-12)
    assert_close(M[11, 8], right, atol=1e-12, what='M[11,8]')
    assert_close(M[14, 8], left, atol=1e-12, what='M[14,8]')
    for _ in range(5):
        q = np.zeros(N_COORDINATES)
        q[1:] = rng.uniform(-0.1, 0.1, N_COORDINATES - 1)
        M = dynamics.mass_matrix(contact, q)
        assert M[11, 8] > 0.0 > M[14, 8], (M[11, 8], M[14, 8])


# ------------------------------------------------------------------------------ (h) bad input
@pytest.fixture
def rest_state():
    q = np.zeros(N_COORDINATES)
    q[2:8] = (-0.05, 0.1, -0.05, 0.05, -0.1, 0.05)
    return q, np.zeros(N_COORDINATES), np.zeros(N_COORDINATES)


@pytest.fixture
def native(robot):
    """The shipped kernel (``NativeGaitDynamics``, probed) whose input checks these tests pin."""
    return NativeProbes(robot, DynamicsParameters())


def test_wrong_length_q_is_rejected(native, rest_state):
    q, v, tau = rest_state
    with pytest.raises(SimulationError, match=r'q has 17 entries, expected 18'):
        native.evaluate(ContactState(get_mode(1)), q[:17], v, tau)
    with pytest.raises(SimulationError, match=r'v has 19 entries, expected 18'):
        native.evaluate(ContactState(get_mode(1)), q, np.zeros(19), tau)
    with pytest.raises(SimulationError, match=r'tau has 16 entries, expected 18'):
        native.evaluate(ContactState(get_mode(1)), q, v, tau[:16])


def test_non_finite_input_is_rejected(native, rest_state):
    q, v, tau = rest_state
    v = v.copy()
    v[5] = np.nan
    with pytest.raises(SimulationError, match=r'v\[5\] is nan: every entry must be finite'):
        native.evaluate(ContactState(get_mode(1)), q, v, tau)
    q = q.copy()
    q[9] = np.inf
    with pytest.raises(SimulationError, match=r'q\[9\] is inf: every entry must be finite'):
        native.evaluate(ContactState(get_mode(1)), q, np.zeros(N_COORDINATES), tau)
    tau = tau.copy()
    tau[3] = np.nan
    with pytest.raises(SimulationError, match=r'tau\[3\] is nan: every entry must be finite'):
        native.evaluate(ContactState(get_mode(1)), rest_state[0], rest_state[1], tau)


@pytest.mark.parametrize(('number', 'index'), [(1, 0), (1, 1), (2, 0), (3, 1), (17, 1)])
def test_velocity_of_a_locked_coordinate_is_rejected(native, rest_state, number, index):
    q, v, tau = rest_state
    v = v.copy()
    v[index] = 0.01
    with pytest.raises(SimulationError,
                       match=rf'mode {number} .*locked coordinate {index} must have zero'):
        native.evaluate(ContactState(get_mode(number)), q, v, tau)


@pytest.mark.parametrize('number', [0, 21])
def test_unknown_mode_number_is_rejected(number):
    with pytest.raises(SimulationError, match=f'unknown gait mode {number}'):
        get_mode(number)


def test_unknown_side_or_pivot_is_rejected(native, rest_state):
    q, v, tau = rest_state
    for side, pivot, named in (('middle', 'toe', "'middle'"), ('left', 'ball', "'ball'")):
        contact = ContactState(get_mode(1), side, pivot)
        with pytest.raises(SimulationError, match=named):
            native.evaluate(contact, q, v, tau)
        with pytest.raises(SimulationError, match=named):
            native.head_pose(contact, q)


# ------------------------------------------------------------------------------ (j) head pose
@pytest.mark.parametrize(('number', 'side', 'pivot'),
                         [(1, 'right', 'toe'), (2, 'left', 'heel'), (3, 'right', 'heel'),
                          (4, 'left', 'toe'), (12, 'right', 'toe'), (20, 'left', 'heel')])
def test_head_jacobian_is_the_derivative_of_psi(dynamics, random_state, number, side, pivot,
                                                assert_close):
    mode = get_mode(number)
    contact = ContactState(mode, side, pivot)
    for yaw in (0.0, 0.6, -0.9):
        q, _v = random_state(mode)
        q[8] = yaw
        _psi, jac = dynamics.head_pose(contact, q)
        assert jac.shape == (3, N_COORDINATES)
        fd = np.zeros((3, N_COORDINATES))
        eps = 1e-6
        for i in mode.active:
            step = np.zeros(N_COORDINATES)
            step[i] = eps
            fd[:, i] = (dynamics.head_pose(contact, q + step)[0]
                        - dynamics.head_pose(contact, q - step)[0]) / (2 * eps)
        assert_close(jac, fd, atol=1e-7, what=f'J_H at yaw {yaw}')


@pytest.mark.parametrize('side', SIDES)
def test_head_pose_at_simple_postures(dynamics, side, assert_close):
    contact = ContactState(get_mode(1), side)
    q = np.zeros(N_COORDINATES)
    q[0] = 0.4
    assert_close(dynamics.head_pose(contact, q)[0], [0.4, 1.70, 0.0], atol=1e-12, what='psi')
    q[17] = 0.3  # neck pitch back: the head top moves back and down, pitch = +0.3
    psi = dynamics.head_pose(contact, q)[0]
    assert_close(psi, [0.4 - 0.24 * math.sin(0.3), 1.46 + 0.24 * math.cos(0.3), 0.3],
                 atol=1e-12, what='psi with neck pitch')
    q[8] = 0.7  # torso yaw does not change the pitch of a head that pitches about its x axis
    psi_yawed = dynamics.head_pose(contact, q)[0]
    assert psi_yawed[1] == pytest.approx(psi[1], abs=1e-12)
    assert abs(psi_yawed[2]) < 0.3
