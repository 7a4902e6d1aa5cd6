"""The hybrid simulation loop: ice glide and toe pick (docs/model.md §5.1, §14.2), run health.

Every simulation of this file runs on the shipped ``Simulator`` (native) and on the oracle's
Python loop (``oracle.simulator.ReferenceSimulator``), the two formulations of the period. It
goes through the ``runs`` fixture, which records the state after
each control period and checks at teardown that the support foot never slid backward: y0 never
decreases within a step (y0 is re-based on the new support foot at an exchange), and a gliding
support never moves backward.
"""

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
import pytest

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.dynamics import DynamicsParameters
from iceskate_sim.model.robot import N_COORDINATES, Y0
from iceskate_sim.physics.hybrid import FrictionModel, guards_of
from iceskate_sim.physics.integrators import GUARD_MARGIN, IntegratorConfig
from iceskate_sim.physics.simulation import Simulator, SimulatorConfig, initial_state
from oracle.automaton import GUARD_VALUES, guard_values
from oracle.dynamics import GaitDynamics
from oracle.native_probes import NativeProbes
from oracle.simulator import ReferenceSimulator

N = N_COORDINATES
G = 9.81
MU = 0.005
ICE = FrictionModel(MU, 'ice')
E4 = GUARD_VALUES['E4']


@dataclass
class Run:
    """A simulator and the samples (t, y0, yd0, mode, step) recorded after every period."""

    sim: Simulator | ReferenceSimulator
    samples: list[tuple[float, float, float, int, int]] = field(default_factory=list)

    def record(self) -> None:
        s = self.sim.state
        self.samples.append((s.t, float(s.q[Y0]), float(s.v[Y0]), s.mode.number,
                             s.step_index))

    def advance(self, tau: np.ndarray):
        result = self.sim.advance(tau)
        self.record()
        return result


@pytest.fixture(params=['oracle', 'native'])
def runs(robot, request):
    """``start(config, state)`` -> Run on the oracle's loop, then on the native simulator (every
    test that uses it runs on both); at teardown: no backward slide in any of them."""
    made: list[Run] = []
    simulator = ReferenceSimulator if request.param == 'oracle' else Simulator

    def start(config: SimulatorConfig, state) -> Run:
        run = Run(simulator(robot, config, state))
        run.record()
        made.append(run)
        return run

    yield start
    for run in made:
        _assert_no_backward_slide(run.samples)


def _assert_no_backward_slide(samples: list[tuple[float, float, float, int, int]]) -> None:
    _, y0, yd0, _, step = (np.array(x) for x in zip(*samples, strict=True))
    drop = np.diff(y0)[step[1:] == step[:-1]]
    assert drop.size == 0 or drop.min() >= 0.0, (
        f'y0 decreased by {-drop.min():.3e} m within a step (toe pick violated)')
    assert np.all(yd0 >= -1e-8), f'support slid backward at {yd0.min():.3e} m/s'


def test_the_backward_slide_check_can_fail():
    with pytest.raises(AssertionError, match='y0 decreased'):
        _assert_no_backward_slide([(0.0, 0.10, 0.0, 1, 0), (0.01, 0.0999, 0.0, 1, 0)])
    with pytest.raises(AssertionError, match='slid backward'):
        _assert_no_backward_slide([(0.0, 0.10, 0.0, 3, 0), (0.01, 0.10, -1e-3, 3, 0)])
    # a support exchange re-bases y0 on the other foot: not a slide
    _assert_no_backward_slide([(0.0, 0.10, 0.0, 9, 0), (0.01, -0.2, 0.0, 1, 1)])


def _gravity(robot, q: np.ndarray, side: str = 'right', pivot: str = 'toe') -> np.ndarray:
    model = robot.support_model(side, pivot).model
    return pin.computeGeneralizedGravity(model, model.createData(), q).copy()


# ------------------------------------------------------------------------------ ice glide
STANCE = np.zeros(N)
STANCE[2:8] = (-0.05, 0.1, -0.05, 0.3, -0.6, 0.3)  # swing foot ~5 cm up, sole flat
STANCE[12] = STANCE[15] = 0.2  # elbows off their stops
GLIDE_POSTURE = STANCE.copy()
GLIDE_POSTURE[2] = -0.12  # leaning forward: the CoP sits near the middle of the sole (+0.08 m)
KP, KD = 100.0, 20.0  # s^-2, s^-1: joint-space PD of the computed torque


_ORACLE_TERMS: dict[DynamicsParameters, GaitDynamics] = {}


def _oracle_terms(robot, params: DynamicsParameters) -> GaitDynamics:
    """The oracle's model terms (its damping and soft stops) for ``params``, made once."""
    terms = _ORACLE_TERMS.get(params)
    if terms is None or terms.robot is not robot:
        terms = _ORACLE_TERMS[params] = GaitDynamics(robot, params)
    return terms


def _rigid_torque(robot, sim: Simulator, reference: np.ndarray,
                  ankle_acceleration: float | None = None) -> np.ndarray:
    """Computed torque for joint accelerations qdd_j = KP (ref - q) - KD v (about 0: the body
    moves rigidly), with the support's y0 row (docs/model.md §4.4) solved for yd0'':

        m yd0'' + M_0j qdd_j + h_0 = -mu s0 N_s,   N_s = m (g + z_com''),

    and tau_j = M_j0 yd0'' + M_jj qdd_j + h_j + g_j - passive_j. With the joints at rest this
    gives yd0'' = -mu g s0. ``ankle_acceleration`` replaces the ankle's PD (a forward lean).
    """
    s = sim.state
    c = s.contact
    sm = robot.support_model(c.side, c.pivot)
    model, data = sm.model, sm.model.createData()
    M = pin.crba(model, data, s.q)
    M = np.triu(M) + np.triu(M, 1).T
    nle = pin.nonLinearEffects(model, data, s.q, s.v)
    passive = _oracle_terms(robot, sim.dynamics.params).passive_forces(s.q, s.v)
    act = c.mode.active
    joints = act[act > 1]
    qdd = KP * (reference - s.q) - KD * s.v
    if ankle_acceleration is not None:
        qdd[2] = ankle_acceleration
    qdd[1] = 0.0
    if c.mode.y0_active:
        jcom = pin.jacobianCenterOfMass(model, data, s.q)
        pin.centerOfMass(model, data, s.q, s.v, np.zeros(N))
        zdd_drift = data.acom[0][2]
        k = MU * c.support_slide_dir * robot.total_mass
        qdd[Y0] = (-k * (G + jcom[2, joints] @ qdd[joints] + zdd_drift)
                   - M[Y0, joints] @ qdd[joints] - nle[Y0]) / M[Y0, Y0]
    else:
        qdd[Y0] = 0.0
    tau = np.zeros(N)
    tau[joints] = M[np.ix_(joints, act)] @ qdd[act] + nle[joints] - passive[joints]
    return tau


def _solver(sim) -> GaitDynamics | NativeProbes:
    """Eq. (7) of ``sim``: the oracle's own dynamics, or the shipped kernel's probe."""
    dynamics = sim.dynamics
    return dynamics if isinstance(dynamics, GaitDynamics) else NativeProbes.of(dynamics)


def test_ice_glide_decelerates_at_mu_g_and_sticks(robot, runs):
    """Mode 3 from yd0 = 0.5 m/s with the body held rigid: yd0'' = -mu g until yd0 = 0, then
    E5 (stuck, mode 1); a forward lean that kicks back on the foot is held by the toe pick."""
    v = np.zeros(N)
    v[Y0] = 0.5
    # Joint velocities stay ~0, so joint damping does nothing here; off, it does not force
    # the 0.25 ms step that the hands' damping (d/I ~ 3e3 1/s) needs with explicit RK4.
    config = SimulatorConfig(control_period=0.01, integrator=IntegratorConfig('rk4', step=5e-3),
                             friction=ICE, dynamics=DynamicsParameters(damping=False))
    run = runs(config, initial_state(GLIDE_POSTURE, 3, v=v))
    sim = run.sim
    assert sim.result.swing_heel[2] > 0.02 and sim.result.swing_toe_z > 0.02

    def advance(tau: np.ndarray):
        # a valid scenario: the new input makes no guard due at once (no CoP jump off the
        # sole, no friction or normal-force limit), so every event is a located crossing
        s = sim.state
        start = _solver(sim).evaluate(s.contact, s.q, s.v, tau)
        assert np.all(guard_values(s, start, ICE) <= GUARD_MARGIN), s.summary()
        return run.advance(tau)

    t_stop = 0.5 / (MU * G)  # 10.19 s
    while not sim.events and sim.time < t_stop + 0.5:
        advance(_rigid_torque(robot, sim, GLIDE_POSTURE))
    assert sim.ended is None
    assert [(e.event, e.from_mode, e.to_mode) for e in sim.events] == [('E5', 3, 1)]
    assert sim.events[0].t == pytest.approx(t_stop, abs=1e-6)

    t, _, yd0, mode, _ = (np.array(x) for x in zip(*run.samples, strict=True))
    gliding = np.flatnonzero(mode[1:] == 3)  # periods that ended while still gliding
    assert gliding.size >= 1000
    deceleration = -np.diff(yd0)[gliding] / np.diff(t)[gliding]
    np.testing.assert_allclose(deceleration, MU * G, rtol=1e-6)
    assert yd0[0] - yd0[gliding[-1] + 1] == pytest.approx(MU * G * t[gliding[-1] + 1],
                                                          rel=1e-6)
    assert sim.state.mode.number == 1 and sim.state.v[Y0] == 0.0

    # stuck: lean forward (ankle accelerating at 0.7 rad/s^2): the floor must push the foot
    # forward (F_y ~ 40 N > 10 mu N: the foot kicks back) while the CoP stays on the sole. A
    # symmetric floor would let the foot slide back; on ice the toe pick holds it: E4 is not
    # due, the mode stays 1 and y0 does not move.
    y_stuck = sim.state.q[Y0]
    coulomb = FrictionModel(MU, 'coulomb')
    for _ in range(20):
        result = advance(_rigid_torque(robot, sim, GLIDE_POSTURE, ankle_acceleration=-0.7))
        assert sim.state.mode.number == 1
        assert sim.state.q[Y0] == y_stuck and sim.state.v[Y0] == 0.0
        assert result.support_friction > 10.0 * MU * result.support_normal > 0.0
        assert -0.04 < result.zmp_y - y_stuck < 0.18
        assert E4(sim.state, result, ICE) < 0.0
        assert E4(sim.state, result, coulomb) > 0.0
    assert [e.event for e in sim.events] == ['E5']


# ------------------------------------------------------------------------------- health
def _standing(robot) -> tuple[np.ndarray, np.ndarray]:
    q = STANCE.copy()
    return q, _gravity(robot, q)


@pytest.mark.parametrize('bad', [float('nan'), float('inf')])
def test_non_finite_torque_is_rejected(robot, runs, bad):
    q, tau = _standing(robot)
    run = runs(SimulatorConfig(), initial_state(q, 1))
    run.advance(tau)
    tau[5] = bad
    with pytest.raises(SimulationError, match='torque'):
        run.sim.advance(tau)
    with pytest.raises(SimulationError, match='torque'):
        run.sim.advance(np.zeros(N - 1))


@pytest.mark.parametrize(('method', 'step', 'period'), [
    ('rk4', 3e-4, 1e-3), ('symplectic_euler', 4e-4, 1e-3), ('rk4', 2e-3, 1e-3)])
def test_control_period_must_be_a_multiple_of_the_fixed_step(method, step, period):
    with pytest.raises(SimulationError, match='multiple'):
        SimulatorConfig(control_period=period, integrator=IntegratorConfig(method, step=step))


def test_valid_control_periods_are_accepted():
    SimulatorConfig(control_period=1e-3, integrator=IntegratorConfig('rk4', step=1e-4))
    SimulatorConfig(control_period=1e-2, integrator=IntegratorConfig('symplectic_euler',
                                                                     step=2.5e-4))
    SimulatorConfig(control_period=1e-3, integrator=IntegratorConfig('rk45', step=3e-4))


def _spinning(robot, runs, joint: int, rate: float) -> tuple[Run, np.ndarray]:
    q, tau = _standing(robot)
    v = np.zeros(N)
    v[joint] = rate
    return runs(SimulatorConfig(), initial_state(q, 1, v=v)), tau


@pytest.mark.parametrize(('joint', 'rate'), [
    *[(joint, rate) for joint in (8, 13, 17) for rate in (1e4, 1e8, 1e20, 1e100)]])
def test_absurd_velocity_never_returns_nan(robot, runs, joint, rate):
    """Either the run ends physically (flight, toe first ...) or it raises SimulationError;
    whatever advance() returns is finite."""
    run, tau = _spinning(robot, runs, joint, rate)
    try:
        for _ in range(10):
            result = run.advance(tau)
            assert np.all(np.isfinite(result.qdd)) and np.all(np.isfinite(result.multipliers))
            assert np.all(np.isfinite(run.sim.state.q)) and np.all(np.isfinite(run.sim.state.v))
            if run.sim.ended:
                break
        assert run.sim.ended is not None
    except SimulationError:
        pass


def test_blow_up_raises_simulation_error(robot, runs):
    run, tau = _spinning(robot, runs, 13, 1e100)  # a wrist at 1e100 rad/s overflows RK4
    with pytest.raises(SimulationError):
        for _ in range(10):
            run.advance(tau)
    assert run.sim.ended is None


def test_blow_up_error_names_time_and_mode(robot, runs):
    run, tau = _spinning(robot, runs, 13, 1e100)
    with pytest.raises(SimulationError) as error:
        for _ in range(10):
            run.advance(tau)
    assert 't=' in str(error.value) and 'mode' in str(error.value), str(error.value)
    if isinstance(run.sim, Simulator):  # the shipped one: metrics.json's end, not a fall
        assert error.value.end == 'diverged'



def test_a_run_ends_as_completed_fell_diverged_or_interrupted(robot):
    """metrics.json's end names how a run ended; fell only for a physical end."""
    from iceskate_sim.errors import RunInterrupted
    from iceskate_sim.run.metrics import Trajectory, compute_metrics
    q, _ = _standing(robot)
    sim = Simulator(robot, SimulatorConfig(), initial_state(q, 1))
    scene = type('Scene', (), {'name': 'x', 'pushes': ()})()
    trajectory = Trajectory()
    cases = {'completed': None, 'diverged': SimulationError('boom', end='diverged'),
             'interrupted': RunInterrupted(2, 0.5), 'failed': SimulationError('bad')}
    for end, error in cases.items():
        metrics = compute_metrics(scene, sim, trajectory, 1.0, error)
        assert (metrics['end'], metrics['fell']) == (end, False), metrics


def _until_ended(run: Run, tau: np.ndarray, max_periods: int) -> None:
    for _ in range(max_periods):  # bounded: never hangs
        run.advance(tau)
        if run.sim.ended:
            return


def _head_height(sim) -> float:
    """Height of the head-top frame in the simulator's current state [m]."""
    return sim.dynamics.frame_placement(sim.state.contact, sim.state.q, 'head_top').translation[2]


def test_unpowered_robot_falls_and_the_run_ends(robot, runs):
    """Single support, no torque at all: the knees buckle and the head drops below 1.2 m."""
    q = np.zeros(N)
    q[2:8] = (-0.05, 0.1, -0.05, 1.2, -0.3, 0.3)  # swing leg raised in front, toe up
    config = SimulatorConfig(control_period=1e-2, integrator=IntegratorConfig('rk4', step=1e-4))
    run = runs(config, initial_state(q, 1))
    assert _head_height(run.sim) > 1.6
    _until_ended(run, np.zeros(N), 300)
    assert run.sim.ended is not None and 'fall' in run.sim.ended
    assert run.sim.time < 2.0
    assert _head_height(run.sim) < config.fall_height
    assert np.all(np.isfinite(run.sim.state.q)) and np.all(np.isfinite(run.sim.state.v))
    with pytest.raises(SimulationError, match='ended'):
        run.sim.advance(np.zeros(N))


def _spinning_backward(robot, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """The whole body pitching backward about the support ankle at ``rate`` [rad/s]."""
    q = STANCE.copy()
    v = np.zeros(N)
    v[2] = rate
    return q, v


def test_support_pulled_up_ends_in_flight(robot, runs):
    """At 3.5 rad/s the CoM's centripetal acceleration (omega^2 r ~ 11 m/s^2 at r ~ 0.9 m)
    exceeds g: the floor would have to pull the support foot down (N_s < 0), swing foot in
    the air: flight, which the paper's model cannot represent."""
    q, v = _spinning_backward(robot, 3.5)
    config = SimulatorConfig(control_period=1e-3, integrator=IntegratorConfig('rk4', step=1e-4))
    run = runs(config, initial_state(q, 1, v=v))
    _until_ended(run, np.zeros(N), 300)
    assert run.sim.ended is not None and 'flight' in run.sim.ended
    assert run.sim.time < 0.3


def test_start_in_flight_ends_the_run_cleanly(robot, runs):
    q, v = _spinning_backward(robot, 5.0)
    state = initial_state(q, 1, v=v)
    result = GaitDynamics(robot).evaluate(state.contact, q, v, np.zeros(N))
    assert result.support_normal < -100.0  # N_s < 0 from the start
    run = runs(SimulatorConfig(), state)
    assert run.sim.ended is not None and 'flight' in run.sim.ended


def test_a_guard_made_due_by_a_new_input_fires_at_once(robot, runs):
    """Standing on a flat support, then a -150 N m ankle step: the CoP jumps behind the heel
    edge (E2 due at the start of the period, nothing else); the support must tip onto its
    heel right there, and no guard may be left due at the end of the period."""
    q, tau = _standing(robot)
    config = SimulatorConfig(control_period=1e-2, integrator=IntegratorConfig('rk4', step=1e-4))
    run = runs(config, initial_state(q, 1))
    for _ in range(3):
        run.advance(tau)
    assert run.sim.events == []
    t_step = run.sim.time
    kick = tau.copy()
    kick[2] -= 150.0
    state = run.sim.state
    result = _solver(run.sim).evaluate(state.contact, state.q, state.v, kick)
    assert result.support_normal > 50.0
    assert result.zmp_y - state.q[Y0] < -0.5  # far behind the heel edge (-0.06 m) at once
    due = guard_values(state, result, config.friction) > GUARD_MARGIN
    assert [g.name for g, d in zip(guards_of(state.mode), due, strict=True) if d] == ['E2']
    run.advance(kick)
    events = [(e.event, e.t) for e in run.sim.events]
    assert events and events[0][0] == 'E2' and events[0][1] == pytest.approx(t_step, abs=1e-9)
    values = guard_values(run.sim.state, run.sim.result, config.friction)
    assert np.all(values <= GUARD_MARGIN)  # nothing due is left pending
