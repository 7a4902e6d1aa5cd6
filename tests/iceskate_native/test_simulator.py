"""Whole control periods in C++ against the Python oracle.

``Simulator`` runs every period in C++ (``iceskate_native.HybridSimulator``,
``Simulator.kernel``): integration, event location, transitions with their impacts and re-rooting,
contact-consistent modes, projection and health checks. The same scene with the same
controllers must give the same event log (events, modes, sides, steps; times and impulses to
round-off) and the same trajectory as the oracle's period loop in Python
(``oracle.simulator``). Both solve eq. (7) with LU factorisations that round differently, so
the states agree to round-off amplified by the gait over the run, not bit for bit.
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial
import pathlib

import numpy as np
import pytest

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.scene import load_scene
from iceskate_sim.errors import SimulationError
from iceskate_sim.physics.hybrid import FrictionModel
from iceskate_sim.physics.integrators import IntegratorConfig
from iceskate_sim.run.scene import Push, Scene
from iceskate_sim.run.session import Session
from oracle.automaton import rerooted_command
from oracle.commands import held_of_controllers, stack_commands
from oracle.integrators import ReferenceIntegratorConfig
from oracle.simulator import ReferenceRun, run_reference

#: a fast-stepping skate gait (test data): many events in a short window
FAST_SKATE = pathlib.Path(__file__).resolve().parents[1] / 'data' / 'fast_skate.yaml'


def _scene(name: str | pathlib.Path, duration: float, **simulator: object) -> Scene:
    scene = load_scene(name)
    config = replace(scene.simulator, **simulator)
    return replace(scene, duration=duration, simulator=config, record_bag=False)


def _run(scene: Scene) -> Session:
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    while not session.done:
        session.run_periods(stack, 1000)
    session.finish()
    assert session.error is None, session.error
    return session


def _reference(scene: Scene, integrator: IntegratorConfig | None = None) -> ReferenceRun:
    """``scene`` on the oracle with the same controllers."""
    session = Session(scene)  # the robot and the controllers' initial observation
    stack = ControlStack(scene, session.robot, session.observation())
    return run_reference(scene, session.robot, partial(stack_commands, stack), integrator)


def _runs(scene: Scene) -> tuple[ReferenceRun, Session]:
    return _reference(scene), _run(scene)


def _assert_same_run(reference: ReferenceRun, native: Session, tolerance: float,
                     same_steps: bool = True) -> None:
    """The same event log and counters, and states within ``tolerance`` (``same_steps``: the
    integrator took the same number of steps; not so for two different step-size controls)."""
    def log(events: list) -> list[tuple]:
        return [(e.event, e.from_mode, e.to_mode, e.side, e.step_index, e.cause) for e in events]

    assert log(native.sim.events) == log(reference.sim.events)
    for a, b in zip(reference.sim.events, native.sim.events, strict=True):
        assert b.t == pytest.approx(a.t, abs=tolerance)
        assert np.allclose(b.impulse, a.impulse, rtol=1e-5, atol=tolerance)
    y = native.trajectory.arrays()
    assert np.array_equal(reference.mode, y['mode'])
    assert np.array_equal(reference.side, y['side'])
    assert np.max(np.abs(reference.q - y['q'])) < tolerance
    assert np.max(np.abs(reference.v - y['v'])) < 100 * tolerance
    a, b = reference.sim.stats, native.sim.stats
    assert (b.control_periods, b.suppressed_cycles, b.resolved_cycles) == (
        a.control_periods, a.suppressed_cycles, a.resolved_cycles)
    assert b.steps == a.steps or not same_steps
    assert b.max_constraint_drift == pytest.approx(a.max_constraint_drift, rel=1e-3)
    assert b.max_constraint_residual < 1e-9 and a.max_constraint_residual < 1e-9
    assert native.sim.ended == reference.sim.ended


@pytest.mark.parametrize(('name', 'duration'), [
    ('skate', 2.0), ('skate_no_yaw', 1.4), ('walk', 1.5), ('stand', 0.5)])
def test_native_periods_follow_the_python_oracle(name: str, duration: float) -> None:
    runs = _runs(_scene(name, duration))
    assert len(runs[0].sim.events) > (10 if name != 'stand' else -1)
    _assert_same_run(*runs, tolerance=1e-7)


def test_a_command_held_across_an_exchange_is_rerooted_with_the_tree() -> None:
    """The period of the first support exchange: at its end the simulator applies the
    controllers' command re-rooted (the same motors: the oracle's map of the command)."""
    scene = _scene('skate', 2.0)
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    side = session.sim.state.contact.side
    while session.sim.state.contact.side == side:
        assert not session.done, 'no exchange in the run'
        commands = stack_commands(stack, session.observation())
        session.run_periods(stack, 1)
    sim = session.sim
    held = rerooted_command(held_of_controllers(commands.values()))
    result = sim.result
    np.testing.assert_allclose(result.applied - result.passive,
                               held.torque(sim.state.q, sim.state.v), rtol=0.0, atol=1e-9)


@pytest.mark.parametrize(('method', 'step', 'duration'), [
    ('symplectic_euler', 1e-4, 0.6), ('rk4', 2.5e-4, 0.8)])
def test_native_periods_with_the_other_fixed_step_methods(method: str, step: float,
                                                          duration: float) -> None:
    scene = load_scene(FAST_SKATE)
    integrator = replace(scene.simulator.integrator, method=method, step=step)
    runs = _runs(_scene(FAST_SKATE, duration, integrator=integrator))
    assert len(runs[0].sim.events) > 20
    _assert_same_run(*runs, tolerance=1e-6)


def test_native_periods_with_rk45_follow_the_python_rk45() -> None:
    """The adaptive pair (scipy's RK45 in the oracle, Boost.Odeint's runge_kutta_dopri5
    natively; their error norms differ: RMS against max): the same event
    log, and trajectories that agree to what the tolerance lets each stray (measured at
    rtol 1e-8 over 0.6 s: event times 5e-10 s, q 2e-8)."""
    scene = load_scene(FAST_SKATE)
    integrator = replace(scene.simulator.integrator, method='rk45', step=1e-3, rtol=1e-8,
                         atol=1e-8)
    runs = _runs(_scene(FAST_SKATE, 0.6, integrator=integrator))
    assert len(runs[0].sim.events) > 20
    _assert_same_run(*runs, tolerance=2e-7, same_steps=False)


def test_native_ros34pw2_periods_converge_to_a_tight_reference() -> None:
    """The Rosenbrock-W method ros34pw2 (native only) against the oracle's DOP853 at rtol 1e-11
    on the fast gait: the same event log, and event times and states to what the tolerance
    lets it stray."""
    scene = load_scene(FAST_SKATE)
    integrator = replace(scene.simulator.integrator, method='ros34pw2', step=1e-3, rtol=1e-7,
                         atol=1e-9)
    native = _run(_scene(FAST_SKATE, 0.6, integrator=integrator))
    reference = _reference(_scene(FAST_SKATE, 0.6), ReferenceIntegratorConfig(
        'dop853', step=1e-3, rtol=1e-11, atol=1e-13))
    events = [(e.event, e.from_mode, e.to_mode, e.side) for e in native.sim.events]
    assert events == [(e.event, e.from_mode, e.to_mode, e.side) for e in reference.sim.events]
    assert len(events) > 20
    times = np.array([e.t for e in native.sim.events])
    assert np.max(np.abs(times - [e.t for e in reference.sim.events])) < 1e-6
    y = native.trajectory.arrays()
    assert np.array_equal(reference.mode, y['mode'])
    assert np.max(np.abs(reference.q - y['q'])) < 1e-6


def test_a_one_millisecond_ros34pw2_step_comes_to_rest_on_a_soft_stop() -> None:
    """With its error control off (rtol = atol = 1: one 1 ms step a period) ros34pw2 meets the
    right elbow's stop at q12 = 0 about 0.175 s into skate: the stop's stiffness (1e4 N m/rad)
    and damping are in the matrix of every step that would cross it, so the elbow comes to rest
    on it as with rk45 at rtol 1e-11 (with a matrix of the stops already engaged only, the
    elbow rebounds: 1.8e-2 rad)."""
    loose = replace(load_scene('skate').simulator.integrator, method='ros34pw2', step=1e-3,
                    rtol=1.0, atol=1.0)
    tight = replace(loose, method='rk45', rtol=1e-11, atol=1e-13)
    runs = [_run(_scene('skate', 0.3, integrator=i)).trajectory.arrays() for i in (loose, tight)]
    elbow = runs[1]['q'][:, 12]
    assert np.any(elbow[:150] > 1e-3) and np.all(elbow[180:] < 0.0)  # it lands and stays
    assert np.max(np.abs(runs[0]['q'] - runs[1]['q'])) < 1e-3
    assert np.max(np.abs(runs[0]['q'][180:, 12] - elbow[180:])) < 1e-4


def test_native_periods_under_coulomb_friction_and_a_push() -> None:
    """Symmetric friction (slide directions from the reactions) and an external force."""
    push = Push(start=0.3, duration=0.1, frame='chest', force=(0.0, -60.0, 0.0))
    scene = _scene('skate', 1.0, friction=FrictionModel(mu=0.02, rule='coulomb'))
    runs = _runs(replace(scene, pushes=(push,)))
    assert any(e.event in ('E4', 'S3') for e in runs[0].sim.events)
    _assert_same_run(*runs, tolerance=1e-7)


@pytest.mark.parametrize('method', ['implicit_euler', 'rk45', 'ros34pw2'])
def test_native_reset_starts_the_same_run_again(method: str) -> None:
    """Bit for bit, the adaptive method's step-size history included."""
    integrator = replace(load_scene('skate').simulator.integrator, method=method)
    session = _run(_scene('skate', 0.6, integrator=integrator))
    first = session.trajectory.arrays()
    events = list(session.sim.events)
    session.reset()
    stack = ControlStack(session.scene, session.robot, session.observation())
    while not session.done:
        session.run_periods(stack, 1000)
    assert session.sim.events == events
    assert np.array_equal(session.trajectory.arrays()['q'], first['q'])


def test_an_end_only_the_method_reaches_is_a_divergence() -> None:
    """rk4 at 1 ms is unstable on skate's light damped links: its state runs away into a
    'flight' 0.7 ms into the run, which rk45 at rtol 1e-8 from that period's start does not
    reach: a divergence with its advice, never a fall; rk4 at 0.1 ms walks on."""
    integrator = replace(load_scene('skate').simulator.integrator, method='rk4', step=1e-3)
    scene = _scene('skate', 0.05, integrator=integrator)
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    while not session.done:
        session.run_periods(stack, 1000)
    session.finish()
    assert session.sim.ended is None and session.sim.time < 1e-3
    assert session.error is not None and session.error.end == 'diverged', session.error
    assert "a flight that rk45 at rtol 1e-8 does not reach from the period's start" in str(
        session.error)
    assert 'take a smaller integrator.step, or an implicit method' in str(session.error)
    fine = replace(integrator, step=1e-4)
    assert _run(_scene('skate', 0.05, integrator=fine)).sim.ended is None


def test_native_period_errors_cross_as_simulation_errors() -> None:
    """Input the kernel refuses comes back as one SimulationError sentence, not a crash."""
    sim = Session(_scene('stand', 0.1)).sim
    with pytest.raises(SimulationError, match="unknown frame 'no_such_frame'"):
        sim.advance(np.zeros(18), ('no_such_frame', np.zeros(3)))
    with pytest.raises(SimulationError, match='push_force'):
        sim.advance(np.zeros(18), ('chest', np.array([0.0, np.nan, 0.0])))


@pytest.mark.slow
@pytest.mark.parametrize('name', ['skate', 'skate_no_yaw', 'walk', 'stand'])
def test_the_shipped_scenes_follow_the_python_oracle_to_the_end(name: str) -> None:
    """The whole scene as ``run_scene`` runs it (no bag) and on the oracle: the same event log
    and states equal to what round-off grows to over the run (measured before the oracle left
    the product: distance 4e-9 m, arm swing 3e-9 rad)."""
    scene = replace(load_scene(name), record_bag=False)
    _assert_same_run(*_runs(scene), tolerance=1e-6)


def _kernel_arguments(session: Session) -> dict:
    """What ``Simulator`` hands the native HybridSimulator, by name."""
    from iceskate_sim.model.modes import MODES
    from iceskate_sim.physics.hybrid import guards_of
    from iceskate_sim.physics.integrators import GUARD_MARGIN
    from iceskate_sim.physics.native import GUARD_CONSTANTS
    sim = session.sim
    return {'dynamics': sim.dynamics.kernel, 'initial': sim.state,
            'config': sim.config, 'constants': GUARD_CONSTANTS, 'margin': GUARD_MARGIN,
            'guards': [[g.name for g in guards_of(MODES[n])] for n in sorted(MODES)]}


def test_the_kernel_reads_its_settings_by_name_and_names_a_bad_one() -> None:
    """The run's settings cross into C++ by name, from ``SimulatorConfig`` (their one
    declaration, with the defaults): a changed field changes the run, a missing or bad one is
    refused by name."""
    import types

    import iceskate_native
    from iceskate_sim.physics.native import GUARD_CONSTANTS
    session = Session(_scene('stand', 0.2))
    args = _kernel_arguments(session)
    kernel = iceskate_native.HybridSimulator(**args)
    state, expected = kernel.state, session.sim.kernel.state
    assert state.keys() == expected.keys()
    assert all(np.array_equal(state[name], expected[name], equal_nan=True) for name in state)
    low = replace(args['config'], fall_height=5.0)  # the head is below 5 m at once: a fall
    fallen = iceskate_native.HybridSimulator(**{**args, 'config': low})
    assert kernel.ended == fallen.ended == 0
    kernel.advance(np.zeros(18))
    fallen.advance(np.zeros(18))
    assert (kernel.ended, fallen.ended) == (0, 3)  # running; fallen
    missing = types.SimpleNamespace(**{name: getattr(args['config'], name)
                                       for name in ('control_period', 'integrator', 'friction')})
    with pytest.raises(ValueError, match='simulator settings: residual_bound'):
        iceskate_native.HybridSimulator(**{**args, 'config': missing})
    bad_rule = replace(args['config'], friction=types.SimpleNamespace(mu=0.005, rule='sand'))
    with pytest.raises(ValueError, match="simulator settings: friction.rule 'sand' is not one"):
        iceskate_native.HybridSimulator(**{**args, 'config': bad_rule})
    with pytest.raises(ValueError, match='guard constants: toe_scuff is nan'):
        iceskate_native.HybridSimulator(**{**args, 'constants': replace(
            GUARD_CONSTANTS, toe_scuff=float('nan'))})


def test_a_state_crosses_by_name_both_ways() -> None:
    """The kernel's state comes out as HybridState's fields by name and goes back in read by
    name: the round trip is exact, a bad field is refused by its name."""
    session = Session(_scene('skate', 0.3))
    stack = ControlStack(session.scene, session.robot, session.observation())
    while not session.done:
        session.run_periods(stack, 100)
    sim = session.sim
    before = sim.kernel.state
    assert list(before) == ['t', 'q', 'v', 'mode', 'side', 'pivot', 'heel_anchor_y',
                            'support_slide_dir', 'heel_slide_dir', 'step_index', 't_exchange',
                            't_touchdown']
    sim.set_state(sim.state)  # the Python view, read back by name
    after = sim.kernel.state
    assert all(np.array_equal(before[name], after[name], equal_nan=True) for name in before)
    bad = replace(sim.state, contact=replace(sim.state.contact, side='middle'))
    with pytest.raises(SimulationError, match="state: contact.side 'middle' is not one of "
                                              "right, left"):
        sim.set_state(bad)
