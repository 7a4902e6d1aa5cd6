"""Many control periods in one native call (``iceskate_native.ControlLoop``, through
``Session.run_periods``) against the same session advanced one period per call, and the
commands of controller nodes (``oracle.commands.stack_commands``, as values) held one period at
a time by the same loop (``Session.hold``, the path of the ROS simulator node). The columns
derived for the recording (head quaternion and pitch, pivot code, root link pose) and the live
view equal what Pinocchio gives in Python.

All run the same C++ laws, sums, zero-order hold and periods, so the runs must agree bit for
bit: every trajectory column, the event log, the counters, the bag's messages and the way a run
stops on a failure of the physics or of a controller, whatever the block size.
"""

from __future__ import annotations

from dataclasses import replace
import math
import pathlib

import numpy as np
import pinocchio as pin
import pytest
from rosbags.rosbag2 import Reader

from gait_manager.errors import GaitManagerError
from iceskate_bringup.composition import ControlStack
from iceskate_bringup.scene import load_scene, scene_sources
import iceskate_native
from iceskate_native.sample import SAMPLE_COLUMNS
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.modes import MODES
from iceskate_sim.model.robot import PIVOTS, SIDES, Robot
from iceskate_sim.physics.hybrid import Transition
from iceskate_sim.physics.native_control import native_observation
from iceskate_sim.physics.simulation import Simulator
from iceskate_sim.run.scene import Push, Scene
from iceskate_sim.run.session import Session
from oracle.commands import held_of_controllers, stack_commands, values_of
from oracle.tf import tf_rows


def _scene(name: str, duration: float, bag: bool = False, **simulator: object) -> Scene:
    scene = load_scene(name)
    return replace(scene, duration=duration, record_bag=bag,
                   simulator=replace(scene.simulator, **simulator))


def _last_event_before(sim: Simulator, t: float) -> Transition | None:
    """The latest transition at or before time t (None before the first)."""
    return next((event for event in reversed(sim.events) if event.t <= t), None)


def _stepped(scene: Scene, out: pathlib.Path | None = None) -> Session:
    """The session advanced one period per native call."""
    return _blocks(scene, 1, out)


def _blocks(scene: Scene, block: int, out: pathlib.Path | None = None) -> Session:
    session = Session(scene, out, out / 'bag' if out is not None and scene.record_bag else None)
    stack = ControlStack(scene, session.robot, session.observation())
    while not session.done:
        assert session.run_periods(stack, block) > 0 or session.done
    session.finish()
    return session


def _held(scene: Scene, out: pathlib.Path | None = None) -> Session:
    """The session as the simulator node drives it: each controller node's command received
    (as values) and held one period at a time, the samples recorded a block at a time."""
    session = Session(scene, out, out / 'bag' if out is not None and scene.record_bag else None)
    stack = ControlStack(scene, session.robot, session.observation())
    inbox = session.command_inbox(tuple(scene_sources(scene).values()))
    while not session.done:
        commands = stack_commands(stack, session.observation())
        for index, command in enumerate(commands.values()):
            inbox.receive(index, values_of(command))
        assert session.hold()
        session.flush(whole=False)
    session.finish()
    return session


def _assert_identical(a: Session, b: Session) -> None:
    x, y = a.trajectory.arrays(), b.trajectory.arrays()
    assert x.keys() == y.keys() and len(a.trajectory) == len(b.trajectory) > 0
    for key in x:
        assert x[key].dtype == y[key].dtype, key
        assert np.array_equal(x[key], y[key], equal_nan=True), key
    assert a.sim.events == b.sim.events
    assert a.sim.stats == b.sim.stats
    assert (a.sim.ended, a.periods, a.trajectory.sources) == (
        b.sim.ended, b.periods, b.trajectory.sources)
    skip = {'wall_time_s', 'real_time_factor'}
    assert ({k: v for k, v in a.metrics.items() if k not in skip}
            == {k: v for k, v in b.metrics.items() if k not in skip})


@pytest.mark.parametrize(('name', 'duration'), [
    ('skate', 2.0), ('skate_no_yaw', 1.0), ('walk', 1.5), ('stand', 2.5)])
def test_blocks_equal_the_session_stepped_period_by_period(name: str, duration: float) -> None:
    scene = _scene(name, duration)
    _assert_identical(_stepped(scene), _blocks(scene, 250))


def test_a_push_and_any_block_size_give_the_same_run() -> None:
    # stand pushes the chest at 2.0 s for 0.1 s: the 'push' source appears mid-run
    scene = _scene('stand', 2.2)
    reference = _stepped(scene)
    assert 'push' in reference.trajectory.sources
    for block in (1, 7, 1000):
        _assert_identical(reference, _blocks(scene, block))
    _assert_identical(reference, _held(scene))


@pytest.mark.parametrize(('name', 'duration', 'every'), [('skate', 2.0, 1), ('walk', 0.6, 3)])
def test_commands_held_one_period_at_a_time_equal_the_session_stepped(
        name: str, duration: float, every: int) -> None:
    scene = replace(_scene(name, duration), record_every=every)
    _assert_identical(_stepped(scene), _held(scene))


def _placements(robot: Robot, side: int, pivot: int, q: np.ndarray) -> tuple[pin.SE3, np.ndarray]:
    """Python's head-top placement and /tf rows (``oracle.tf``) in the support model of side and
    pivot (indices) at q."""
    support = robot.support_model(SIDES[side], PIVOTS[pivot])
    data = support.new_data()
    pin.forwardKinematics(support.model, data, q)
    head = pin.updateFramePlacement(support.model, data, support.frame_ids['head_top']).copy()
    return head, tf_rows(robot, SIDES[side], PIVOTS[pivot], q)


def _heights(robot: Robot, side: int, pivot: int, q: np.ndarray,
             frames: tuple[str, ...]) -> list[float]:
    """World heights [m] of ``frames`` in the support model of side and pivot at q."""
    support = robot.support_model(SIDES[side], PIVOTS[pivot])
    data = support.new_data()
    pin.framesForwardKinematics(support.model, data, q)
    return [float(data.oMf[support.frame_ids[frame]].translation[2]) for frame in frames]


def _assert_tf(row: np.ndarray, expected: np.ndarray) -> None:
    """A sample's /tf rows against ``oracle.tf``'s: the root link's world pose the same
    numbers, the joints' transforms to rounding (SE3 composed in another order)."""
    row = row.reshape(expected.shape)
    assert np.array_equal(row[0], expected[0])
    np.testing.assert_allclose(row, expected, rtol=0.0, atol=1e-14)


def _assert_head(row: dict, k: int, head: pin.SE3) -> None:
    rotation = head.rotation
    assert np.array_equal(row['head_position'][k], head.translation)
    assert np.array_equal(row['head_orientation'][k], pin.Quaternion(rotation).coeffs())
    assert row['head_pitch'][k] == np.arctan2(-rotation[1, 2], rotation[2, 2])


def test_the_samples_carry_the_head_quaternion_and_pitch_pivot_and_tf() -> None:
    scene = _scene('skate', 2.5)  # toe and heel pivots, support exchanges
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    sim = session.sim
    loop = sim.control_loop(stack.kinematics, list(stack.controllers.values()), scene.pushes,
                            session.psi_initial)
    block, error = sim.run_loop(loop, session.n_periods)
    n = len(block['t'])
    assert error is None and n == session.n_periods
    assert list(block) == [*SAMPLE_COLUMNS, 'sources', 'efforts']  # the table's, in its order
    pairs = len(session.robot.tf_frames)
    for name, column in SAMPLE_COLUMNS.items():
        assert block[name].shape == (n, *column.shape(pairs)), name
        assert block[name].dtype == column.dtype, name
    for key, shape, dtype in [('head_orientation', (n, 4), np.float64),
                              ('head_pitch', (n,), np.float64), ('pivot', (n,), np.int32),
                              ('tf', (n, 7 * pairs), np.float64)]:
        assert (block[key].shape, block[key].dtype) == (shape, dtype), key
    robot = session.robot
    assert robot.tf_frames[0] == ('world', 'pelvis')  # the URDF's root link
    codes = block['pivot']
    assert set(codes.tolist()) == {0, 1, 2}
    # the head is observed before the transitions due at t_k, the sample's state after them
    transition_at = np.isin(block['t'], [event.t for event in sim.events])
    rows = {*range(0, n, 97), *np.flatnonzero(transition_at).tolist(),
            *(int(np.flatnonzero(codes == code)[0]) for code in (0, 1, 2))}
    for k in sorted(rows):
        side, mode = int(block['side'][k]), int(block['mode'][k])
        assert (codes[k] > 0) == MODES[mode].q1_active, k
        # a flat sole (code 0) lies in the toe's or the heel's support model, the same to
        # rounding: the sample is that of one of them
        pivots = [int(codes[k]) - 1] if codes[k] else [0, 1]
        head, tf = next(placed for placed in (_placements(robot, side, pivot, block['q'][k])
                                              for pivot in pivots)
                        if np.array_equal(placed[1][0], block['tf'][k][:7]))
        _assert_tf(block['tf'][k], tf)
        if not transition_at[k]:
            _assert_head(block, k, head)
        rotation = pin.Quaternion(block['head_orientation'][k]).toRotationMatrix()
        assert block['head_pitch'][k] == pytest.approx(
            math.atan2(-rotation[1, 2], rotation[2, 2]), abs=1e-12)
        swing = _heights(robot, side, pivots[0], block['q'][k], ('swing_heel', 'swing_toe'))
        assert block['swing_clearance'][k] == pytest.approx(min(swing), abs=1e-12), k
    # the swing sole rises off the ice in every step and comes down to it
    clearance = block['swing_clearance']
    assert clearance.min() > -2e-3 and clearance.max() > 0.02
    for step in np.unique(block['step_index'])[1:-1]:
        assert np.abs(clearance[block['step_index'] == step]).min() < 1e-3, step


def test_the_live_view_is_a_sample_of_the_current_state_under_the_held_command() -> None:
    scene = _scene('skate', 0.5)
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    inbox = session.command_inbox(tuple(scene_sources(scene).values()))
    sim = session.sim
    for period in range(300):  # past the first transitions
        commands = stack_commands(stack, session.observation())
        for index, command in enumerate(commands.values()):
            inbox.receive(index, values_of(command))
        session.hold()
        block = inbox.kernel.take_block()
        if period % 50 == 49 or period == 0:
            live = inbox.kernel.live()
            assert live.keys() == block.keys()
            assert all(len(value) == 1 for value in live.values() if isinstance(value, np.ndarray))
            state, result = sim.state, sim.result
            contact = state.contact
            side, pivot = SIDES.index(contact.side), PIVOTS.index(contact.pivot)
            for key, expected in [
                    ('t', state.t), ('t_exchange', state.t_exchange),
                    ('t_touchdown', state.t_touchdown), ('heel_anchor_y', contact.heel_anchor_y),
                    ('mode', contact.mode.number), ('side', side),
                    ('pivot', pivot + 1 if contact.mode.q1_active else 0),
                    ('swing_clearance', min(result.swing_heel[2], result.swing_toe_z)),
                    ('step_index', state.step_index), ('q', state.q), ('v', state.v),
                    ('qdd', result.qdd), ('passive', result.passive),
                    ('applied', result.applied), ('multipliers', result.multipliers),
                    ('support_normal', result.support_normal),
                    ('support_friction', result.support_friction), ('zmp_y', result.zmp_y),
                    ('head_target', block['head_target'][-1]), ('present', 1)]:
                assert np.array_equal(live[key][0], expected, equal_nan=True), key
            held = held_of_controllers(commands.values()).torque(state.q, state.v)
            assert live['sources'] == ['held'] and np.array_equal(live['efforts'][0][0], held)
            head, tf = _placements(session.robot, side, pivot, state.q)
            assert np.array_equal(head.translation, sim.dynamics.frame_placement(
                sim.state.contact, sim.state.q, 'head_top').translation)
            _assert_head(live, 0, head)
            _assert_tf(live['tf'][0], tf)
            last = int(live['last_event'][0])
            assert (sim.events[last] if last >= 0 else None) == _last_event_before(sim, state.t)
    assert sim.events  # transitions happened


def test_the_inbox_refuses_bad_commands_and_forgets_on_request() -> None:
    scene = _scene('skate', 0.1)
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    inbox = session.command_inbox(tuple(scene_sources(scene).values()))
    good = values_of(stack_commands(stack, session.observation())['gait_manager'])
    assert good.stiffness.size == 18  # with an impedance
    for bad, match in [
            (good._replace(effort=np.zeros(17)), 'effort has 17 entries, expected 18'),
            (good._replace(source_efforts=good.source_efforts[:-18]),
             r'source_efforts has \d+ entries, expected \d+ \(18 per source'),
            (good._replace(head_target=np.zeros(2)), 'head_target has 2 entries'),
            (good._replace(effort=np.full(18, math.inf)), r'effort\[0\] is inf'),
            (good._replace(damping=-good.damping - 1.0), 'stiffness and damping must be >= 0'),
            (good._replace(reference=np.full(18, math.nan)), r'position_reference\[0\] is nan'),
            (good._replace(reference=np.zeros(0)), 'position_reference has 0 entries')]:
        with pytest.raises(SimulationError, match='command: ' + match):
            inbox.receive(1, bad)
    with pytest.raises(SimulationError, match='controller index 2 is not below the 2'):
        inbox.receive(2, good)
    # nothing kept: the period holds no command, as a session that never received one
    reference = Session(scene)
    reference.command_inbox(tuple(scene_sources(scene).values()))
    assert reference.hold()
    reference.flush()
    inbox.receive(1, good)
    inbox.kernel.forget()
    session.hold()
    session.flush()
    assert np.array_equal(session.trajectory.arrays()['q'], reference.trajectory.arrays()['q'])
    assert np.array_equal(session.trajectory.arrays()['applied'],
                          reference.trajectory.arrays()['applied'])


def test_the_bag_of_blocks_holds_the_same_messages(tmp_path: pathlib.Path) -> None:
    scene = _scene('stand', 2.15, bag=True)  # the push acts over the last 0.15 s
    _stepped(scene, tmp_path / 'stepped')
    _blocks(scene, 333, tmp_path / 'blocks')

    def messages(bag: pathlib.Path) -> list[tuple[str, int, bytes]]:
        with Reader(bag) as reader:
            return [(c.topic, t, bytes(data)) for c, t, data in reader.messages()]

    stepped, blocks = messages(tmp_path / 'stepped' / 'bag'), messages(tmp_path / 'blocks' / 'bag')
    # by default the bag at 250 Hz (every 4th period, across blocks of 333), /tf at 125 Hz
    assert (scene.bag_every, scene.tf_every) == (4, 2)
    assert len(blocks) == 1 + 5 * 538 + 269 and blocks == stepped


def test_a_physics_failure_ends_both_paths_alike() -> None:
    # a residual bound below the projection's round-off: the first constrained period fails
    scene = _scene('walk', 1.5, residual_bound=1e-18)
    stepped, blocks = _stepped(scene), _blocks(scene, 250)
    assert stepped.error is not None and 'constraint residual' in str(stepped.error)
    assert str(blocks.error) == str(stepped.error)
    _assert_identical(stepped, blocks)


def test_a_controller_error_comes_after_the_samples_before_it() -> None:
    # knee and ankle at 1e308 rad (soft stops off): the balance law's sum overflows
    scene = _scene('skate', 1.0, dynamics=replace(load_scene('skate').simulator.dynamics,
                                                    joint_limits=False))
    for run in ('stepped', 'blocks'):
        session = Session(scene)
        stack = ControlStack(scene, session.robot, session.observation())
        q = session.sim.state.q.copy()
        q[2:4] = 1e308
        session.sim.set_state(replace(session.sim.state, q=q))
        with pytest.raises(GaitManagerError, match='balance command is not finite'):
            session.run_periods(stack, 1 if run == 'stepped' else 10)
        assert len(session.trajectory) == 0 and session.sim.stats.control_periods == 0


def test_the_loop_refuses_bad_arguments_in_one_sentence() -> None:
    scene = _scene('skate', 0.1)
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    controllers = list(stack.controllers.values())
    sim = session.sim
    with pytest.raises(SimulationError, match="native control loop: unknown frame 'nose'"):
        sim.control_loop(stack.kinematics, controllers, (Push(0.0, 1.0, 'nose', (1, 0, 0)),),
                         session.psi_initial)
    with pytest.raises(SimulationError, match=r'native control loop: push force\[0\] is nan'):
        sim.control_loop(stack.kinematics, controllers,
                         (Push(0.0, 1.0, 'chest', (math.nan, 0, 0)),), session.psi_initial)
    with pytest.raises(SimulationError, match='head_origin has 2 entries, expected 3'):
        sim.control_loop(stack.kinematics, controllers, (), np.zeros(2))
    with pytest.raises(SimulationError, match='native control loop: controller 1 is a object, '
                       'not an iceskate_native.*Controller'):
        sim.control_loop(stack.kinematics, [controllers[0], object()], (), session.psi_initial)
    loop = sim.control_loop(stack.kinematics, controllers, (), session.psi_initial)
    with pytest.raises(ValueError, match='number of periods must be >= 0'):
        loop.kernel.run(-1)
    for pairs in ([('world', 'nose')], [('nose', 'pelvis')]):  # a link it lacks
        with pytest.raises(ValueError, match="unknown frame 'nose'"):
            iceskate_native.ControlLoop(session.sim.kernel, None, [], [],
                                        session.psi_initial, pairs)
    with pytest.raises(ValueError, match='child must be a link, not the world'):
        iceskate_native.ControlLoop(session.sim.kernel, None, [], [], session.psi_initial,
                                    [('pelvis', 'world')])
    assert isinstance(loop.kernel, iceskate_native.ControlLoop)


class _Seen(iceskate_native.Controller):
    """Answers zero and keeps every observation it is given (as tuples of its fields)."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: list[tuple] = []

    def compute(self, obs: iceskate_native.Observation,
                kinematics: iceskate_native.Kinematics) -> np.ndarray:
        self.seen.append(_fields(obs))
        return np.zeros(18)


def _fields(obs) -> tuple:
    return (obs.t, *obs.q, *obs.v, obs.mode, obs.side, obs.pivot, obs.step_index,
            obs.t_exchange, obs.heel_anchor_y, obs.t_touchdown)


def test_the_controllers_see_the_simulators_observation_of_each_instant() -> None:
    """The observation is built in one place: the loop gives its controllers what
    ``HybridSimulator.observation`` gives Python at the same state, to the bit."""
    scene = _scene('skate', 2.5)  # both sides, toe and heel pivots, flat soles
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    seen = _Seen()
    sim = session.sim
    loop = sim.control_loop(stack.kinematics, [*stack.controllers.values(), seen], scene.pushes,
                            session.psi_initial)
    expected, pivots = [], set()
    while len(expected) < session.n_periods:
        obs = sim.kernel.observation()
        expected.append(_fields(obs))
        pivots.add((obs.pivot, MODES[obs.mode].q1_active))
        _, error = sim.run_loop(loop, 1)
        assert error is None
    assert pivots == {(0, False), (0, True), (1, True)}
    assert np.array_equal(np.array(seen.seen), np.array(expected), equal_nan=True)
    python = session.observation()  # the Python view: the same state, side and pivot named
    native = sim.kernel.observation()
    assert (python.side, python.pivot) == (SIDES[native.side], PIVOTS[native.pivot])
    assert np.array_equal(_fields(native_observation(python)), _fields(native),
                          equal_nan=True)
