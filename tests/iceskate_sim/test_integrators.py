"""The integrators: convergence order, one step, event location, and the determinism of whole
runs on the shipped simulator; the Rosenbrock-W method ros34pw2 (native only) against the same
references: its order, its error against its tolerance, its event time.

Each order, step and event test runs on two engines: 'oracle', the oracle's ``Integrator`` on
the mode-1 dynamics (support flat and stuck, swing foot in the air) of
``GaitDynamics.evaluate`` with the oracle automaton's guards (``guard_values``), and 'native',
the shipped kernel's segment (``NativeProbes.integrate_segment``: the same mode, input and
guards in C++). The reference solutions are the oracle's DOP853 at tolerances far below the
errors they judge, and the tests check that margin too.
"""

import math

import numpy as np
import pinocchio as pin
import pytest

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import HeldCommand
from iceskate_sim.model.dynamics import ContactState, DynamicsParameters
from iceskate_sim.model.modes import get_mode
from iceskate_sim.model.robot import N_COORDINATES
from iceskate_sim.physics.hybrid import FrictionModel, HybridState, guards_of
from iceskate_sim.physics.integrators import GUARD_MARGIN, IntegratorConfig
from iceskate_sim.physics.simulation import Simulator, SimulatorConfig, initial_state
from oracle.automaton import guard_values
from oracle.dynamics import GaitDynamics
from oracle.integrators import Integrator, ReferenceIntegratorConfig
from oracle.native_probes import NativeProbes

N = N_COORDINATES
MODE = get_mode(1)
# No friction event in these single-mode segments: the support may not start gliding.
STICKY = FrictionModel(1.0, 'coulomb')
ENGINES = ('oracle', 'native')


class Problem:
    """Mode-1 dynamics under a constant input on one engine: the (rhs, guards) pair of the
    oracle's integrators ('oracle'), or the shipped kernel's segment ('native')."""

    def __init__(self, robot, q: np.ndarray, tau: np.ndarray, joint_limits: bool = False,
                 engine: str = 'oracle'):
        params = DynamicsParameters(joint_limits=joint_limits)
        self.engine = engine
        self.dynamics = (GaitDynamics if engine == 'oracle' else NativeProbes)(robot,
                                                                                       params)
        self.contact = ContactState(MODE, 'right', 'toe')
        self.tau = tau
        self.q = q
        self.names = [g.name for g in guards_of(MODE)]

    def rhs(self, t: float, x: np.ndarray, implicit_step: float = 0.0):
        if implicit_step > 0.0:  # implicit_euler's step: (M + h D) a = f - D v
            qdd = self.dynamics.implicit_acceleration(self.contact, x[:N], x[N:], self.tau,
                                                      None, None, None, implicit_step)
            return np.concatenate([x[N:], qdd]), None
        result = self.dynamics.evaluate(self.contact, x[:N], x[N:], self.tau)
        return np.concatenate([x[N:], result.qdd]), result

    def guards(self, t: float, x: np.ndarray, result) -> np.ndarray:
        return guard_values(HybridState(t, x[:N], x[N:], self.contact), result, STICKY)

    def run(self, config: IntegratorConfig, x0: np.ndarray, t_end: float):
        """The segment from (0, x0) to t_end or the first guard crossing, on this engine."""
        if self.engine == 'native':
            return self.dynamics.integrate_segment(
                HybridState(0.0, x0[:N].copy(), x0[N:].copy(), self.contact),
                HeldCommand.torque_only(self.tau), None, config, STICKY, {}, t_end)
        return Integrator(config).integrate_segment(self.rhs, self.guards, 0.0, x0, t_end)


def _gravity(robot, q: np.ndarray) -> np.ndarray:
    model = robot.support_model('right', 'toe').model
    return pin.computeGeneralizedGravity(model, model.createData(), q).copy()


def _swing_lifted() -> np.ndarray:
    """Bent support leg, swing foot 0.1 m up and forward, elbows slightly bent."""
    q = np.zeros(N)
    q[2:8] = (-0.05, 0.1, -0.05, 0.35, -0.8, 0.45)
    q[11], q[14], q[12], q[15] = 0.2, -0.2, 0.3, 0.3
    return q


def _max_damping_rate(problem: Problem, q: np.ndarray) -> float:
    """Largest eigenvalue of M^-1 D: the stiffest (damping) mode of the segment [1/s]."""
    M = problem.dynamics.mass_matrix(problem.contact, q)
    D = np.diag(problem.dynamics.robot.damping[MODE.active])
    return float(np.max(np.linalg.eigvals(np.linalg.solve(M, D)).real))


# ------------------------------------------------------------------- convergence order
def _smooth_segment(robot, rng) -> tuple[Problem, Problem, np.ndarray, float]:
    """The smooth segment of the order tests: (oracle problem, native problem, x0, duration).
    The input holds the initial posture (gravity) up to small offsets, so it moves smoothly."""
    q = _swing_lifted()
    tau = _gravity(robot, q)
    tau[2:] += rng.uniform(-5.0, 5.0, N - 2)
    v = np.zeros(N)
    v[2:] = rng.uniform(-0.3, 0.3, N - 2)
    return (Problem(robot, q, tau), Problem(robot, q, tau, engine='native'),
            np.concatenate([q, v]), 0.2)


@pytest.mark.parametrize('engine', ENGINES)
@pytest.mark.parametrize(('method', 'order'), [('rk4', 4), ('symplectic_euler', 1),
                                               ('implicit_euler', 1)])
def test_convergence_order_on_a_smooth_segment(robot, rng, method, order, engine):
    problem, _, x0, duration = _smooth_segment(robot, rng)  # the reference: the oracle's DOP853
    engine_problem = _on(problem, engine)
    q = x0[:N]

    ref = problem.run(ReferenceIntegratorConfig('dop853', step=duration, rtol=1e-13,
                                                atol=1e-13), x0, duration)
    check = problem.run(ReferenceIntegratorConfig('dop853', step=duration, rtol=1e-12,
                                                  atol=1e-12), x0, duration)
    assert ref.fired is None and check.fired is None  # one smooth mode, no event
    assert np.max(np.abs(ref.x[:N] - q)) > 0.05  # it does move
    ref_error = np.max(np.abs(ref.x - check.x))

    # asymptotic regime: h lambda_max <= 0.35 for the stiffest (damping) mode, far inside the
    # stability intervals of both methods (2.79 for RK4, 2 for the explicit velocity update of
    # semi-implicit Euler; at h lambda = 1.4 the local RK4 slope is still ~4.9), and
    # h = duration / n so that every step is a full step
    lam = _max_damping_rate(problem, q)
    n0 = math.ceil(duration * lam / 0.35)
    steps = [duration / (n0 * 2 ** k) for k in range(3)]
    errors = []
    for h in steps:
        seg = engine_problem.run(IntegratorConfig(method, step=h), x0, duration)
        assert seg.fired is None
        assert seg.t == pytest.approx(duration, abs=1e-12)
        errors.append(float(np.max(np.abs(seg.x - ref.x))))
    assert errors[-1] > 10.0 * ref_error, (errors, ref_error)  # the reference is good enough
    slope = float(np.polyfit(np.log(steps), np.log(errors), 1)[0])
    assert abs(slope - order) <= 0.3, (
        f'{engine} {method}: log-log slope {slope:.3f}, expected {order} (steps {steps}, errors '
        f'{errors})')


def test_ros34pw2_converges_at_third_order(robot, rng):
    """The Rosenbrock-W method with its error control off (rtol = atol = 1: every step its
    largest) is of order 3 although its matrix holds only the stiffness and damping of the
    Jacobian (a W-method keeps its order for any matrix); its steps are not bound by the
    stiffest mode (h lambda = 0.35 to 1.4 here, where explicit RK4 needs h lambda < 2.79)."""
    problem, native, x0, duration = _smooth_segment(robot, rng)
    ref = problem.run(ReferenceIntegratorConfig('dop853', step=duration, rtol=1e-13,
                                                atol=1e-13), x0, duration)
    check = problem.run(ReferenceIntegratorConfig('dop853', step=duration, rtol=1e-12,
                                                  atol=1e-12), x0, duration)
    ref_error = np.max(np.abs(ref.x - check.x))
    steps = [duration / n for n in (200, 400, 800)]
    errors = []
    for h in steps:
        seg = native.run(IntegratorConfig('ros34pw2', step=h, rtol=1.0, atol=1.0), x0,
                         duration)
        assert seg.fired is None and seg.steps == round(duration / h)
        errors.append(float(np.max(np.abs(seg.x - ref.x))))
    assert errors[-1] > 10.0 * ref_error, (errors, ref_error)
    slope = float(np.polyfit(np.log(steps), np.log(errors), 1)[0])
    assert abs(slope - 3.0) <= 0.3, (slope, errors)


def test_ros34pw2_error_follows_its_tolerance(robot, rng):
    """Under step-size control on its embedded order-2 estimate the global error falls about
    in proportion to the tolerance and the step count grows as tol^(-1/3)."""
    problem, native, x0, duration = _smooth_segment(robot, rng)
    ref = problem.run(ReferenceIntegratorConfig('dop853', step=duration, rtol=1e-13,
                                                atol=1e-13), x0, duration)
    tolerances = np.array([1e-5, 1e-6, 1e-7, 1e-8])
    errors, steps = [], []
    for rtol in tolerances:
        seg = native.run(IntegratorConfig('ros34pw2', step=1.0, rtol=rtol, atol=rtol), x0,
                         duration)
        errors.append(float(np.max(np.abs(seg.x - ref.x))))
        steps.append(seg.steps)
    error_slope = np.polyfit(np.log(tolerances), np.log(errors), 1)[0]
    step_slope = np.polyfit(np.log(tolerances), np.log(steps), 1)[0]
    assert 0.65 <= error_slope <= 1.1, (errors, error_slope)
    assert -0.42 <= step_slope <= -0.25, (steps, step_slope)
    assert errors[-1] <= 1e-6


@pytest.mark.parametrize('engine', ENGINES)
@pytest.mark.parametrize('method', ['rk4', 'symplectic_euler', 'implicit_euler'])
def test_one_step_is_the_method_by_definition(robot, rng, method, engine):
    """One fixed step from (q, v): semi-implicit Euler updates v first and moves q with the new
    v (what separates it from explicit Euler, which has the same order); implicit Euler does
    the same with the damping taken implicitly, (M + h D) a = f - D v (the oracle's
    ``implicit_acceleration``); RK4 is the classic four-stage tableau."""
    q = _swing_lifted()
    tau = _gravity(robot, q)
    tau[2:] += rng.uniform(-5.0, 5.0, N - 2)
    problem = Problem(robot, q, tau, engine=engine)
    v = np.zeros(N)
    v[2:] = rng.uniform(-0.3, 0.3, N - 2)
    x0 = np.concatenate([q, v])
    h = 1e-3

    def f(x: np.ndarray) -> np.ndarray:
        result = problem.dynamics.evaluate(problem.contact, x[:N], x[N:], tau)
        return np.concatenate([x[N:], result.qdd])

    if method in ('symplectic_euler', 'implicit_euler'):
        a = f(x0)[N:] if method == 'symplectic_euler' else GaitDynamics(
            robot, problem.dynamics.params).implicit_acceleration(
                problem.contact, q, v, tau, None, None, None, h)
        v1 = v + h * a
        expected = np.concatenate([q + h * v1, v1])
    else:
        k1 = f(x0)
        k2 = f(x0 + 0.5 * h * k1)
        k3 = f(x0 + 0.5 * h * k2)
        k4 = f(x0 + h * k3)
        expected = x0 + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    seg = problem.run(IntegratorConfig(method, step=h), x0, h)
    assert seg.fired is None and seg.steps == 1 and seg.t == pytest.approx(h, abs=1e-15)
    np.testing.assert_allclose(seg.x, expected, rtol=0, atol=1e-13)


# ------------------------------------------------------------------------ event location
@pytest.fixture(scope='module')
def falling_heel(robot):
    """Mode 1, swing toe up and heel 18 mm above the floor, moving down at 0.3 m/s, the swing
    leg unpowered (the rest held by gravity compensation): the heel strikes first (S1)."""
    q = np.zeros(N)
    q[2:8] = (-0.05, 0.1, -0.05, 0.3, -0.55, 0.45)
    q[12] = q[15] = 0.2
    tau = _gravity(robot, q)
    tau[5:8] = 0.0
    problem = Problem(robot, q, tau)
    sm = robot.support_model('right', 'toe')
    data = sm.model.createData()
    pin.framesForwardKinematics(sm.model, data, q)
    jac = pin.computeFrameJacobian(sm.model, data, q, sm.frame_ids['swing_heel'],
                                   pin.LOCAL_WORLD_ALIGNED)
    heel = data.oMf[sm.frame_ids['swing_heel']].translation
    toe = data.oMf[sm.frame_ids['swing_toe']].translation
    assert 0.01 < heel[2] < 0.03 and toe[2] > heel[2] + 0.03
    v = np.zeros(N)
    v[5:8] = np.linalg.pinv(jac[1:3, 5:8]) @ np.array([0.0, -0.3])
    x0 = np.concatenate([q, v])
    ref = problem.run(ReferenceIntegratorConfig('dop853', step=1.0, rtol=1e-12, atol=1e-12,
                                       event_tolerance=1e-13), x0, 1.0)
    assert ref.fired is not None and problem.names[ref.fired] == 'S1'
    return problem, x0, ref


def _on(problem: Problem, engine: str) -> Problem:
    """The same segment on ``engine``."""
    return Problem(problem.dynamics.robot, problem.q, problem.tau, engine=engine)


def _check_located(problem: Problem, seg, tolerance: float) -> None:
    """The located state is on the due side of the heel's zero, within the tolerance."""
    assert problem.names[seg.fired] == 'S1'
    z, zdot = seg.result.swing_heel[2], seg.result.swing_heel_velocity[2]
    assert zdot < -0.05
    value = problem.guards(seg.t, seg.x, seg.result)[seg.fired]
    assert value > GUARD_MARGIN  # due
    # Brent brackets the zero of (guard - margin) to `tolerance` and then steps onto the due
    # side by at most about twice that: |z| <= margin + 3 tolerance |zdot|
    assert -z <= GUARD_MARGIN + 3.0 * tolerance * abs(zdot) + 1e-15, z


def test_event_reference_locates_the_heel_on_the_floor(falling_heel):
    problem, _, ref = falling_heel
    _check_located(problem, ref, 1e-13)
    assert abs(ref.result.swing_heel[2]) < 2e-9  # ~0: the margin 1e-9 m plus 1e-14 m


@pytest.mark.parametrize(('method', 'engine'), [('rk45', 'oracle'), ('rk45', 'native'),
                                               ('dop853', 'oracle'), ('ros34pw2', 'native')])
def test_adaptive_event_time_agrees_with_the_reference(falling_heel, method, engine):
    problem, x0, ref = falling_heel
    problem = _on(problem, engine)
    seg = problem.run(ReferenceIntegratorConfig(method, step=1.0, rtol=1e-9, atol=1e-9), x0,
                      1.0)
    _check_located(problem, seg, IntegratorConfig().event_tolerance)
    assert abs(seg.t - ref.t) <= 1e-8, seg.t - ref.t
    assert np.max(np.abs(seg.x[:N] - ref.x[:N])) <= 1e-7


@pytest.mark.parametrize('engine', ENGINES)
def test_rk4_event_time_error_is_its_own_integration_error(falling_heel, engine):
    """RK4's event time converges at fourth order: from t(h) and t(h/2), Richardson gives the
    error of t(h/2) as (t(h) - t(h/2)) / 15; allow twice that plus the location tolerance."""
    problem, x0, ref = falling_heel
    problem = _on(problem, engine)
    tolerance = 1e-13
    times = []
    for h in (2e-4, 1e-4):
        seg = problem.run(IntegratorConfig('rk4', step=h, event_tolerance=tolerance), x0, 1.0)
        _check_located(problem, seg, tolerance)
        times.append(seg.t)
    estimate = abs(times[0] - times[1]) / 15.0
    bound = 2.0 * estimate + 1e-12
    assert abs(times[1] - ref.t) <= bound, (times[1] - ref.t, bound)
    assert abs(times[0] - ref.t) <= 2.0 * 16.0 * estimate + 1e-12
    assert abs(times[1] - ref.t) < abs(times[0] - ref.t)


# --------------------------------------------------------------------------- determinism
def _simulator(robot, method: str, step: float) -> Simulator:
    """An unpowered fall from single support, swing leg raised in front (heel strike, slip),
    on the shipped simulator."""
    q = np.zeros(N)
    q[2:8] = (-0.05, 0.1, -0.05, 1.2, -0.3, 0.3)
    config = SimulatorConfig(control_period=1e-2,
                             integrator=IntegratorConfig(method, step=step))
    return Simulator(robot, config, initial_state(q, 1))


def _drive(sim: Simulator, periods: int = 40) -> Simulator:
    for k in range(periods):
        tau = np.zeros(N)
        tau[2:5] = 5.0 * math.sin(0.3 * k)  # a varying input, the same in every run
        sim.advance(tau)
        if sim.ended:
            break
    return sim


def _assert_identical(a: Simulator, b: Simulator) -> None:
    assert a.time == b.time
    assert np.array_equal(a.state.q, b.state.q)
    assert np.array_equal(a.state.v, b.state.v)
    assert a.state.contact == b.state.contact
    assert a.events == b.events  # times, modes and impulses compared exactly
    assert a.ended == b.ended
    assert a.stats == b.stats


@pytest.mark.parametrize(('method', 'step'), [('rk4', 1e-4), ('rk45', 1e-2), ('ros34pw2', 1e-2)])
def test_runs_are_bit_identical(robot, method, step):
    first = _drive(_simulator(robot, method, step))
    second = _drive(_simulator(robot, method, step))
    assert {e.event for e in first.events} >= {'S1'}, 'the run should cross events'
    _assert_identical(first, second)
    first.reset()  # reset() starts the same run again, adaptive step history included
    _assert_identical(_drive(first), second)


# -------------------------------------------------------------------------- configuration
@pytest.mark.parametrize('changes', [dict(method='euler'), dict(step=0.0), dict(rtol=-1.0),
                                     dict(atol=float('nan')), dict(event_tolerance=0.0)])
def test_bad_integrator_settings_are_rejected(changes):
    with pytest.raises(SimulationError):
        IntegratorConfig(**changes)
