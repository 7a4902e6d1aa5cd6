"""The native eq. (7) against the Python reference: every mode, side, pivot and friction case.

``oracle.dynamics.GaitDynamics`` is the readable reference; ``NativeGaitDynamics`` (called
through ``oracle.native_probes``) solves the same system in C++ (``iceskate_native.Dynamics``).
The reference factorises the whole matrix by LU of partial pivoting; the kernel solves it as a
saddle point (the mass matrix's Cholesky factor, a rank-one update, the constraints' Schur
complement), and by LU only when one of those steps fails (e.g. an indefinite mass block).
They agree to rounding: each quantity to 1e-11 of its scale (the dynamics matrix has
condition numbers up to ~1e4 here, and most entries agree to ~1e-13).
"""

import itertools
import pathlib

import numpy as np
import pytest

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.dynamics import ContactState, DynamicsParameters
from iceskate_sim.model.modes import MODES, get_mode
from iceskate_sim.model.robot import JOINT_LIMITS, PIVOTS, SIDES, load_robot
from oracle.dynamics import GaitDynamics
from oracle.native_probes import NativeProbes

#: a fast-stepping skate gait (test data): many events in a short window
FAST_SKATE = pathlib.Path(__file__).resolve().parents[1] / 'data' / 'fast_skate.yaml'

SEED = 20190605
TOLERANCE = 1e-11
VECTORS = ('qdd', 'multipliers', 'support_wrench', 'applied', 'passive', 'swing_heel',
           'swing_heel_velocity')
CASES = list(itertools.product(sorted(MODES), SIDES, PIVOTS))


@pytest.fixture(scope='module')
def robot():
    return load_robot()


@pytest.fixture(scope='module')
def engines(robot):
    """(reference, native) with the same parameters (Baumgarte on, to check its terms too)."""
    params = DynamicsParameters(baumgarte=5.0)
    return GaitDynamics(robot, params), NativeProbes(robot, params)


def state(mode, rng, into_stops=False):
    """A bent-knee posture with noise; locked coordinates held with zero velocity."""
    q = np.zeros(18)
    q[2:8] = (-0.05, 0.1, -0.05, 0.05, -0.1, 0.05)
    q[2:] += rng.uniform(-0.15, 0.15, 16)
    if into_stops:  # push two joints 0.05 rad into their soft stops
        q[3] = JOINT_LIMITS[3][0] - 0.05
        q[17] = JOINT_LIMITS[17][1] + 0.05
    q[0] = rng.uniform(-1.0, 1.0)
    q[1] = rng.uniform(-0.2, 0.2) if mode.q1_active else 0.0
    v = np.zeros(18)
    v[mode.active] = rng.uniform(-1.0, 1.0, mode.active.size)
    return q, v


def assert_same(a, b, what):
    """Vectors to TOLERANCE of their largest entry; the support forces to TOLERANCE of the
    wrench they come from (N_s is m g less the swing contact: cancellation); the CoP where N_s
    carries at least 50 N (it divides by N_s)."""
    for name in VECTORS:
        x, y = getattr(a, name), getattr(b, name)
        scale = max(1.0, float(np.max(np.abs(x))))
        assert np.max(np.abs(x - y)) <= TOLERANCE * scale, f'{what}: {name} {x} vs {y}'
    wrench = max(1.0, float(np.max(np.abs(a.support_wrench))))
    for name, scale in (('support_normal', wrench), ('support_friction', wrench),
                        ('heel_friction', abs(a.multipliers[0])), ('swing_toe_z', 1.0),
                        ('zmp_y', 1.0 if a.support_normal > 50.0 else np.inf)):
        x, y = getattr(a, name), getattr(b, name)
        if np.isnan(x):
            assert np.isnan(y), f'{what}: {name}'
        else:
            assert abs(x - y) <= TOLERANCE * max(1.0, scale), f'{what}: {name} {x} vs {y}'


@pytest.mark.parametrize(('number', 'side', 'pivot'), CASES)
def test_evaluate_agrees_in_every_mode_side_and_pivot(engines, number, side, pivot):
    reference, native = engines
    mode = get_mode(number)
    rng = np.random.default_rng([SEED, number, SIDES.index(side), PIVOTS.index(pivot)])
    for slide in (1.0, -1.0):  # both friction directions, support and swing heel
        q, v = state(mode, rng)
        contact = ContactState(mode, side, pivot, heel_anchor_y=0.12, support_slide_dir=slide,
                               heel_slide_dir=-slide)
        tau = rng.normal(0.0, 5.0, 18)
        assert_same(reference.evaluate(contact, q, v, tau), native.evaluate(contact, q, v, tau),
                    f'mode {number} {side} {pivot} slide {slide}')


@pytest.mark.parametrize('number', [1, 8, 12, 16, 20])
def test_impedance_push_and_soft_stops_agree(engines, number):
    reference, native = engines
    mode = get_mode(number)
    rng = np.random.default_rng([SEED, number, 7])
    q, v = state(mode, rng, into_stops=True)
    contact = ContactState(mode, 'left', 'heel', heel_anchor_y=-0.05)
    tau = rng.normal(0.0, 5.0, 18)
    push = ('chest', np.array([5.0, 40.0, -10.0]))
    stiffness, damping = rng.uniform(0.0, 800.0, 18), rng.uniform(0.0, 16.0, 18)
    a = reference.evaluate(contact, q, v, tau, push, stiffness, damping)
    b = native.evaluate(contact, q, v, tau, push, stiffness, damping)
    assert_same(a, b, f'mode {number}')
    assert np.any(a.passive != -reference._damping * v)  # the stops are engaged
    for h in (1e-4, 1e-3):
        x = reference.implicit_acceleration(contact, q, v, tau, push, stiffness, damping, h)
        y = native.implicit_acceleration(contact, q, v, tau, push, stiffness, damping, h)
        assert np.max(np.abs(x - y)) <= TOLERANCE * max(1.0, float(np.max(np.abs(x))))


@pytest.mark.parametrize(('number', 'side', 'pivot'), CASES[::3])
def test_implicit_acceleration_agrees(engines, number, side, pivot):
    reference, native = engines
    mode = get_mode(number)
    rng = np.random.default_rng([SEED, number, 11])
    q, v = state(mode, rng)
    contact = ContactState(mode, side, pivot, heel_anchor_y=0.02)
    tau = rng.normal(0.0, 5.0, 18)
    stiffness, damping = rng.uniform(0.0, 800.0, 18), rng.uniform(0.0, 16.0, 18)
    x = reference.implicit_acceleration(contact, q, v, tau, None, stiffness, damping, 1e-3)
    y = native.implicit_acceleration(contact, q, v, tau, None, stiffness, damping, 1e-3)
    assert np.max(np.abs(x - y)) <= TOLERANCE * max(1.0, float(np.max(np.abs(x))))


@pytest.mark.parametrize(('number', 'side', 'pivot'), CASES[1::3])
def test_the_linearized_system_is_the_one_evaluate_solves(engines, number, side, pivot):
    """``linearize``'s matrix (what ros34pw2 builds its steps on) is eq. (7)'s system: eq. (7)
    is affine in the input, so two inputs that differ by dtau at one state give accelerations
    and multipliers that differ by the system's solution for [dtau over the active joints; 0]
    (y0's row takes no joint input)."""
    _, native = engines
    mode = get_mode(number)
    rng = np.random.default_rng([SEED, number, SIDES.index(side), PIVOTS.index(pivot), 3])
    q, v = state(mode, rng)
    contact = ContactState(mode, side, pivot, heel_anchor_y=0.1, support_slide_dir=1.0,
                           heel_slide_dir=-1.0)
    tau = rng.normal(0.0, 5.0, 18)
    dtau = rng.normal(0.0, 5.0, 18)
    dtau[0] = 0.0
    a = native.evaluate(contact, q, v, tau)
    b = native.evaluate(contact, q, v, tau + dtau)
    matrix, n, nc, _, _ = native.linearize(contact, q, v, tau)
    slots = [('hz', 'hy', 'fr').index(c) for c in mode.constraints]
    assert (n, nc) == (mode.active.size, len(slots))
    unknowns = np.concatenate([(b.qdd - a.qdd)[mode.active],
                               (b.multipliers - a.multipliers)[slots]])
    expected = np.concatenate([dtau[mode.active], np.zeros(nc)])
    scale = max(1.0, float(np.max(np.abs(matrix)) * np.max(np.abs(unknowns))))
    assert np.max(np.abs(matrix @ unknowns - expected)) <= TOLERANCE * scale


def test_the_linearized_system_holds_the_stiff_terms(robot, engines):
    """Its stiffness and damping per coordinate: Table 1's damping and the commanded impedance,
    and a soft stop's where q is past it or q + lookahead v will be; none on y0."""
    _, native = engines
    mode = get_mode(3)  # y0 active: the support glides
    contact = ContactState(mode, 'right', 'toe')
    rng = np.random.default_rng([SEED, 5])
    q, v = state(mode, rng)
    q[17] = JOINT_LIMITS[17][1] + 0.05  # past its upper stop
    q[3], v[3] = JOINT_LIMITS[3][0] + 0.01, -1.0  # 10 ms before its lower stop
    stiffness, damping = rng.uniform(0.0, 800.0, 18), rng.uniform(0.0, 16.0, 18)
    tau = np.zeros(18)
    params = native.params
    for lookahead, stops in ((0.0, [17]), (0.02, [3, 17])):
        _, _, _, k, d = native.linearize(contact, q, v, tau, stiffness, damping, lookahead)
        expected_k, expected_d = stiffness.copy(), robot.damping + damping
        expected_k[stops] += params.limit_stiffness
        expected_d[stops] += params.limit_damping
        expected_k[0] = expected_d[0] = 0.0
        np.testing.assert_array_equal(k, expected_k)
        np.testing.assert_allclose(d, expected_d, rtol=0.0, atol=1e-12)


@pytest.mark.parametrize('number', [1, 4, 8, 16, 20])
def test_an_implicit_step_whose_mass_block_is_indefinite_agrees(engines, number):
    """A negative impedance damping (a controller may send one) can leave M + h D without a
    Cholesky factor: the kernel then solves the system by LU, and still agrees."""
    reference, native = engines
    mode = get_mode(number)
    rng = np.random.default_rng([SEED, number, 13])
    q, v = state(mode, rng)
    contact = ContactState(mode, 'right', 'toe', heel_anchor_y=0.02)
    tau = rng.normal(0.0, 5.0, 18)
    damping = np.zeros(18)
    damping[9] = -1e5  # h d = -100 N m s^2/rad: far below the mass matrix's own scale
    stiffness = np.zeros(18)
    x = reference.implicit_acceleration(contact, q, v, tau, None, stiffness, damping, 1e-3)
    y = native.implicit_acceleration(contact, q, v, tau, None, stiffness, damping, 1e-3)
    assert np.max(np.abs(x - y)) <= TOLERANCE * max(1.0, float(np.max(np.abs(x))))


def test_the_singular_straight_posture_is_refused_by_both(engines):
    contact = ContactState(get_mode(17), 'right', 'toe')
    q, v, tau = np.zeros(18), np.zeros(18), np.zeros(18)
    for engine in engines:
        with pytest.raises(SimulationError, match='rank-deficient'):
            engine.evaluate(contact, q, v, tau)


@pytest.mark.parametrize(('change', 'match'), [
    ({'q': np.zeros(17)}, 'q has 17 entries, expected 18'),
    ({'v': np.full(18, np.nan)}, r'v\[0\] is nan'),
    ({'tau': np.array([np.inf] * 18)}, r'tau\[0\] is inf'),
    ({'push': ('no_such_link', np.zeros(3))}, "unknown frame 'no_such_link'"),
    ({'push': ('chest', np.zeros(2))}, 'push_force has 2 entries, expected 3'),
    ({'v': np.eye(18)[0]}, 'locked coordinate 0 must have zero velocity'),
])
def test_bad_input_is_a_simulation_error_naming_it(engines, change, match):
    _, native = engines
    args = {'q': np.zeros(18), 'v': np.zeros(18), 'tau': np.zeros(18), 'push': None}
    args['q'][2:8] = (-0.05, 0.1, -0.05, 0.05, -0.1, 0.05)
    args.update(change)
    with pytest.raises(SimulationError, match=match):
        native.evaluate(ContactState(get_mode(5), 'right', 'toe'), args['q'], args['v'],
                        args['tau'], args['push'])


def test_an_unknown_mode_is_refused_by_the_kernel(engines):
    _, native = engines
    with pytest.raises(ValueError, match='unknown gait mode 21'):
        native.kernel.evaluate(21, 0, 0, 0.0, 1.0, 1.0, np.zeros(18), np.zeros(18),
                                np.zeros(18))


def test_a_bad_mode_table_is_refused(robot):
    import iceskate_native
    from iceskate_sim.physics.native import native_robot
    models, frames = native_robot(robot)
    rows = [(m.number, m.y0_active, m.q1_active, m.swing_sliding, [int(i) for i in m.active],
             list(m.constraints)) for m in MODES.values()]
    rows[4] = rows[4][:5] + (['hy', 'hz'],)
    with pytest.raises(ValueError, match='heel-height constraint must come first'):
        iceskate_native.Dynamics(models, frames, rows, robot.damping, robot.total_mass, [],
                                 (0.005, 0.0, True, 1e4, 100.0, True))


def test_the_kernel_takes_the_mode_table_it_is_given_whatever_its_size(robot):
    """The core keeps no count of the modes: a table with a 21st row (mode 20's coordinates
    and constraints) is taken whole, and its mode 21 evaluates as mode 20 does."""
    import iceskate_native
    from iceskate_sim.physics.native import MODE_ROWS, native_robot
    models, frames = native_robot(robot)
    rows = [*MODE_ROWS, (21, *MODE_ROWS[19][1:])]
    options = (0.005, 0.0, True, 1e4, 100.0, True)
    kernel = iceskate_native.Dynamics(models, frames, rows, robot.damping, robot.total_mass, [],
                                      options)
    shipped = iceskate_native.Dynamics(models, frames, MODE_ROWS, robot.damping,
                                       robot.total_mass, [], options)
    q = np.zeros(18)
    q[2:8] = (-0.05, 0.1, -0.05, 0.05, -0.1, 0.05)
    args = (0, 0, 0.0, 1.0, 1.0, q, np.zeros(18), np.zeros(18))
    assert np.array_equal(kernel.evaluate(21, *args)[0], shipped.evaluate(20, *args)[0])
    with pytest.raises(ValueError, match='unknown gait mode 22; the mode table has modes 1-21'):
        kernel.evaluate(22, *args)
    with pytest.raises(ValueError, match='the mode table is empty'):
        iceskate_native.Dynamics(models, frames, [], robot.damping, robot.total_mass, [],
                                 options)


# ------------------------------------------------------------------ guards and segments
@pytest.mark.parametrize(('number', 'side', 'pivot'), CASES[::2])
@pytest.mark.parametrize('rule', ['ice', 'coulomb'])
def test_guard_values_agree(engines, number, side, pivot, rule):
    from iceskate_sim.model.command import HeldCommand
    from iceskate_sim.physics.hybrid import FrictionModel, HybridState, guards_of
    from oracle.automaton import guard_values
    reference, native = engines
    mode = get_mode(number)
    rng = np.random.default_rng([SEED, number, 13])
    q, v = state(mode, rng)
    contact = ContactState(mode, side, pivot, heel_anchor_y=0.1)
    command = HeldCommand.torque_only(rng.normal(0.0, 5.0, 18))
    friction = FrictionModel(0.005, rule)
    s = HybridState(0.25, q, v, contact)
    expected = guard_values(s, reference.evaluate(contact, q, v, command.bias), friction)
    names = [g.name for g in guards_of(mode)]
    rested = {names[0]: 0.3}  # the first guard rests until after t: reads -1
    expected[0] = -1.0
    got = native.guard_values(s, command, None, friction, rested)
    assert np.max(np.abs(got - expected)) <= TOLERANCE * max(1.0, float(np.max(np.abs(expected))))


def _heel_lift(robot):
    """Mode 17 (double support) with the swing hip pushed so that the heel lifts (guard S5 or
    the like fires about 2 ms in): the engines, the start state, the held command and the
    Python right-hand side and guards for the oracle's ``Integrator.integrate_segment``."""
    from iceskate_sim.model.command import HeldCommand
    from iceskate_sim.physics.hybrid import FrictionModel, HybridState
    from oracle.automaton import guard_values
    params = DynamicsParameters()
    reference, native = GaitDynamics(robot, params), NativeProbes(robot, params)
    q = np.zeros(18)
    q[2:8] = (-0.05, 0.1, -0.05, 0.05, -0.1, 0.05)
    contact = ContactState(get_mode(17), 'right', 'toe')
    contact.heel_anchor_y = float(reference.frame_placement(contact, q, 'swing_heel')
                                  .translation[1])
    tau = np.zeros(18)
    tau[5], tau[6] = 60.0, -40.0
    friction = FrictionModel()

    def rhs(t, x, implicit_step=0.0):
        if implicit_step > 0.0:
            qdd = reference.implicit_acceleration(contact, x[:18], x[18:], tau, None, None,
                                                  None, implicit_step)
            return np.concatenate([x[18:], qdd]), None
        result = reference.evaluate(contact, x[:18], x[18:], tau)
        return np.concatenate([x[18:], result.qdd]), result

    def guards(t, x, result):
        return guard_values(HybridState(t, x[:18], x[18:], contact), result, friction)

    start = HybridState(0.0, q, np.zeros(18), contact)
    return native, start, HeldCommand.torque_only(tau), friction, rhs, guards


@pytest.mark.parametrize('method', ['symplectic_euler', 'implicit_euler', 'rk4'])
def test_a_native_segment_equals_the_python_one_with_its_event(robot, method):
    """The segment stops at the same guard, at the same time (to the event tolerance), in the
    same state."""
    from iceskate_sim.physics.hybrid import guards_of
    from iceskate_sim.physics.integrators import IntegratorConfig
    from oracle.integrators import Integrator
    native, start, command, friction, rhs, guards = _heel_lift(robot)
    config = IntegratorConfig(method=method, step=1e-4, event_tolerance=1e-10)
    x0 = np.concatenate([start.q, start.v])
    expected = Integrator(config).integrate_segment(rhs, guards, 0.0, x0, 0.2)
    got = native.integrate_segment(start, command, None, config, friction, {}, 0.2)
    assert expected.fired is not None, 'the reference found no event: the test needs one'
    assert got.fired == expected.fired, guards_of(start.mode)[expected.fired].name
    # both locate the zero to the event tolerance (Brent in scipy, TOMS 748 natively)
    dt = got.t - expected.t
    assert abs(dt) <= 2 * config.event_tolerance
    assert got.steps == expected.steps
    # the states differ by what the motion covers in that time, and rounding
    rate = np.abs(np.concatenate([expected.x[18:], expected.result.qdd]))
    assert np.all(np.abs(got.x - expected.x) <= 2.0 * rate * abs(dt) + 1e-11)


def test_native_rk45_locates_the_event_of_a_tight_reference(robot):
    """Dormand-Prince 5(4) natively (Boost.Odeint's stepper and step-size control, the event
    on its dense output) against DOP853 at 1e-12 in Python: the same guard, its time and the
    state there to what the tolerance leaves (measured: 1.3e-13 s, 3.4e-13 at rtol 1e-9)."""
    from iceskate_sim.physics.integrators import IntegratorConfig
    from oracle.integrators import Integrator, ReferenceIntegratorConfig
    native, start, command, friction, rhs, guards = _heel_lift(robot)
    x0 = np.concatenate([start.q, start.v])
    tight = ReferenceIntegratorConfig('dop853', step=1.0, rtol=1e-12, atol=1e-12,
                                      event_tolerance=1e-13)
    expected = Integrator(tight).integrate_segment(rhs, guards, 0.0, x0, 0.2)
    assert expected.fired is not None and expected.t < 0.01
    for rtol, bound in ((1e-6, 1e-9), (1e-9, 2e-12)):
        config = IntegratorConfig('rk45', step=1.0, rtol=rtol, atol=rtol, event_tolerance=1e-13)
        got = native.integrate_segment(start, command, None, config, friction, {}, 0.2)
        assert got.fired == expected.fired
        assert abs(got.t - expected.t) <= bound, (rtol, got.t - expected.t)
        assert np.max(np.abs(got.x[:18] - expected.x[:18])) <= 3.0 * bound


def test_native_rk45_error_follows_its_tolerance(robot):
    """On a smooth stretch (stopping before the event) the global error of the native rk45 is
    proportional to the tolerance (log-log slope 1) and the step count grows as tol^(-1/5), the
    signature of an error estimate of local order 5."""
    from iceskate_sim.physics.integrators import IntegratorConfig
    from oracle.integrators import Integrator, ReferenceIntegratorConfig
    native, start, command, friction, rhs, guards = _heel_lift(robot)
    x0 = np.concatenate([start.q, start.v])
    t_end = 1.9e-3  # the heel lifts at about 2.15 ms
    tight = ReferenceIntegratorConfig('dop853', step=1.0, rtol=1e-13, atol=1e-13)
    expected = Integrator(tight).integrate_segment(rhs, guards, 0.0, x0, t_end)
    assert expected.fired is None
    tolerances = np.array([1e-6, 1e-7, 1e-8, 1e-9, 1e-10])
    errors, steps = [], []
    for rtol in tolerances:
        config = IntegratorConfig('rk45', step=1.0, rtol=rtol, atol=rtol)
        got = native.integrate_segment(start, command, None, config, friction, {}, t_end)
        assert got.fired is None and got.t == t_end
        errors.append(float(np.max(np.abs(got.x - expected.x))))
        steps.append(got.steps)
    error_slope = np.polyfit(np.log(tolerances), np.log(errors), 1)[0]
    step_slope = np.polyfit(np.log(tolerances), np.log(steps), 1)[0]
    assert 0.85 <= error_slope <= 1.15, (errors, error_slope)
    assert -0.25 <= step_slope <= -0.15, (steps, step_slope)
    assert errors[-1] <= 1e-9


def test_a_segment_without_event_reaches_the_end(robot):
    from iceskate_sim.model.command import HeldCommand
    from iceskate_sim.physics.hybrid import FrictionModel, HybridState
    from iceskate_sim.physics.integrators import IntegratorConfig
    native = NativeProbes(robot)
    q = np.zeros(18)
    q[2:8] = (-0.05, 0.1, -0.05, 0.05, -0.1, 0.05)
    contact = ContactState(get_mode(17), 'right', 'toe')
    contact.heel_anchor_y = float(native.frame_placement(contact, q, 'swing_heel')
                                  .translation[1])
    segment = native.integrate_segment(
        HybridState(0.0, q, np.zeros(18), contact), HeldCommand.torque_only(np.zeros(18)),
        None, IntegratorConfig(method='implicit_euler', step=1e-3), FrictionModel(), {}, 0.01)
    assert segment.fired is None and segment.t == 0.01 and segment.steps == 10
    with pytest.raises(SimulationError, match="method must be one of .*got 'dop853'"):
        IntegratorConfig(method='dop853')


@pytest.mark.parametrize(('row', 'match'), [
    (lambda r: (r[0], r[1], not r[2], *r[3:]), 'q1 active and the coordinate list disagree'),
    (lambda r: (r[0], not r[1], *r[2:]), 'y0 active and the coordinate list disagree'),
])
def test_a_mode_table_that_contradicts_itself_is_refused(robot, row, match):
    import iceskate_native
    from iceskate_sim.physics.native import native_robot
    models, frames = native_robot(robot)
    rows = [(m.number, m.y0_active, m.q1_active, m.swing_sliding, [int(i) for i in m.active],
             list(m.constraints)) for m in MODES.values()]
    rows[3] = row(rows[3])
    with pytest.raises(ValueError, match=match):
        iceskate_native.Dynamics(models, frames, rows, robot.damping, robot.total_mass, [],
                                 (0.005, 0.0, True, 1e4, 100.0, True))


def test_non_finite_physical_options_are_refused(robot):
    import iceskate_native
    from iceskate_sim.physics.native import native_robot
    models, frames = native_robot(robot)
    rows = [(m.number, m.y0_active, m.q1_active, m.swing_sliding, [int(i) for i in m.active],
             list(m.constraints)) for m in MODES.values()]
    with pytest.raises(ValueError, match='must be finite and >= 0'):
        iceskate_native.Dynamics(models, frames, rows, robot.damping, robot.total_mass, [],
                                 (float('nan'), 0.0, True, 1e4, 100.0, True))
    with pytest.raises(ValueError, match='joint limit 3 is not finite'):
        iceskate_native.Dynamics(models, frames, rows, robot.damping, robot.total_mass,
                                 [(3, 0.0, float('inf'))], (0.005, 0.0, True, 1e4, 100.0, True))
