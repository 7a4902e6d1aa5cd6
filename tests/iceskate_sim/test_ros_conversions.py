"""ros_conversions: stamps, Observation from GaitState, EffortCommand <-> ControllerCommand.

The messages are rosbags objects (the conversions are duck-typed on fields, so rclpy messages
behave the same; the integration tests feed those). A GaitState is the one the simulator sends:
``SampleMessages.encode`` of a native loop's sample (``live()``, or a block of a short run of the
fast skating gait), deserialized by rosbags.
"""

from dataclasses import replace
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.robot import COORDINATE_NAMES, PIVOTS, SIDES, load_robot
from iceskate_sim.model.stamps import ns_to_sec_nanosec, seconds_to_ns, set_stamp
from iceskate_sim.physics.simulation import Simulator, SimulatorConfig, initial_state
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.recording.messages import Events, SampleMessages
from iceskate_sim.ros.conversions import command_from_message
from oracle.commands import ControllerCommand, JointCommand, command_of
from oracle.messages import (
    command_fields,
    observation_from_gait_state,
    stamp_to_ns,
    stamp_to_seconds,
)

GAIT_STATE = 'iceskate_interfaces/msg/GaitState'
FAST_SKATE = Path(__file__).resolve().parents[1] / 'data' / 'fast_skate.yaml'


@pytest.fixture(scope='module')
def typestore():
    return make_typestore()


@pytest.fixture(scope='module')
def messages(typestore) -> SampleMessages:
    return SampleMessages(typestore, load_robot().tf_frames)


@pytest.fixture(scope='module')
def simulator() -> Simulator:
    q = np.zeros(18)
    q[2:8] = (-0.05, 0.1, -0.05, 0.05, -0.1, 0.05)
    return Simulator(load_robot(), SimulatorConfig(), initial_state(q, 17))


def header(typestore, stamp_ns: int):
    """A std_msgs/Header stamped ``stamp_ns`` (rosbags object)."""
    sec, nanosec = ns_to_sec_nanosec(stamp_ns)
    return typestore.types['std_msgs/msg/Header'](
        stamp=typestore.types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec),
        frame_id='')


def empty_command(typestore, source):
    """An EffortCommand (rosbags object) of ``source`` with every array empty."""
    empty = np.zeros(0)
    return typestore.types['iceskate_interfaces/msg/EffortCommand'](
        header=header(typestore, 2_000_000), source=source, run_token='', joint_names=[],
        effort=empty,
        stiffness=empty, damping=empty, position_reference=empty, source_names=[],
        source_efforts=empty, head_target=empty)


def effort_message(typestore, source='posture', names=None, effort=None, **impedance):
    names = list(COORDINATE_NAMES) if names is None else names
    effort = np.arange(len(names), dtype=float) if effort is None else np.asarray(effort)
    msg = empty_command(typestore, source)
    msg.joint_names, msg.effort = names, effort
    for key, value in impedance.items():
        setattr(msg, key, np.asarray(value, dtype=float))
    return msg


def test_stamps_round_trip_in_integer_nanoseconds():
    assert seconds_to_ns(0.003000000000000001) == 3_000_000
    assert ns_to_sec_nanosec(2_500_000_001) == (2, 500_000_001)
    stamp = set_stamp(SimpleNamespace(sec=0, nanosec=0), 7_000_000_123)
    assert (stamp.sec, stamp.nanosec) == (7, 123)
    assert stamp_to_ns(stamp) == 7_000_000_123
    assert stamp_to_seconds(stamp) == pytest.approx(7.000000123, abs=1e-15)


def test_seconds_to_ns_raises_on_negative_or_nan_time():
    with pytest.raises(SimulationError, match='finite time >= 0'):
        seconds_to_ns(-1e-3)
    with pytest.raises(SimulationError, match='finite time >= 0'):
        seconds_to_ns(float('nan'))


def decoded(typestore, data: bytes):
    return typestore.deserialize_cdr(data, GAIT_STATE)


def gait_state_message(typestore, messages, simulator):
    """The simulator's gait_state, through CDR (as a subscriber gets it): the message of its
    native loop's live sample."""
    live = simulator.control_loop(None, [], (), np.zeros(3)).kernel.live()
    events = Events.of(live['last_event'], simulator.events)
    return decoded(typestore, messages.encode(live, events, ('/gait_state',))['/gait_state'][0])


def assert_observation(obs, expected) -> None:
    assert obs.t == expected.t and obs.mode == expected.mode and obs.side == expected.side
    np.testing.assert_array_equal(obs.q, expected.q)
    np.testing.assert_array_equal(obs.v, expected.v)
    assert (obs.pivot, obs.step_index, obs.t_exchange, obs.heel_anchor_y) == (
        expected.pivot, expected.step_index, expected.t_exchange, expected.heel_anchor_y)
    assert obs.t_touchdown == expected.t_touchdown or (
        math.isnan(obs.t_touchdown) and math.isnan(expected.t_touchdown))


def test_observation_from_gait_state_equals_the_simulators(typestore, messages, simulator):
    obs = observation_from_gait_state(gait_state_message(typestore, messages, simulator))
    assert_observation(obs, simulator.observation())


@pytest.fixture(scope='module')
def skate_run(messages, native_loop_run):
    """1.5 s of the fast skating gait: (its block of samples and their /gait_state bytes, its
    final live gait_state bytes and the simulator's observation then)."""
    from iceskate_bringup.scene import load_scene
    scene = replace(load_scene(FAST_SKATE), duration=1.5)
    block, loop, sim = native_loop_run(scene, 1500)
    encoded = messages.encode(block, Events.of(block['last_event'], sim.events),
                              ('/gait_state',))['/gait_state']
    live = loop.kernel.live()
    final = messages.encode(live, Events.of(live['last_event'], sim.events),
                            ('/gait_state',))['/gait_state'][0]
    return block, encoded, final, sim.observation()


def test_observation_from_gait_state_after_a_run_equals_the_simulators(typestore, skate_run):
    _, _, final, expected = skate_run
    assert expected.t == 1.5 and expected.step_index >= 2
    assert_observation(observation_from_gait_state(decoded(typestore, final)), expected)


def test_the_observation_of_every_sample_of_a_run_holds_its_state(typestore, skate_run):
    """Each sample's GaitState gives back its state: times at the stamps' nanoseconds, the
    pivot 'toe' while the sole is flat (GaitState's PIVOT_NONE, see ``conversions``)."""
    block, encoded, _, _ = skate_run
    seen = set()
    for k in range(0, len(encoded), 3):
        obs = observation_from_gait_state(decoded(typestore, encoded[k]))
        assert seconds_to_ns(obs.t) == seconds_to_ns(block['t'][k])
        np.testing.assert_array_equal(obs.q, block['q'][k])
        np.testing.assert_array_equal(obs.v, block['v'][k])
        mode = int(block['mode'][k])
        pivot = PIVOTS[max(int(block['pivot'][k]) - 1, 0)]  # 'toe' while flat (0)
        assert (obs.mode, obs.side, obs.pivot, obs.step_index) == (
            mode, SIDES[block['side'][k]], pivot, block['step_index'][k])
        assert seconds_to_ns(obs.t_exchange) == seconds_to_ns(block['t_exchange'][k])
        assert obs.heel_anchor_y == block['heel_anchor_y'][k]
        touchdown = block['t_touchdown'][k]
        if math.isnan(touchdown):
            assert math.isnan(obs.t_touchdown)
        else:
            assert seconds_to_ns(obs.t_touchdown) == seconds_to_ns(touchdown)
        seen.add((mode, obs.pivot, math.isnan(obs.t_touchdown), obs.side))
    modes = {m for m, *_ in seen}
    assert len(modes) >= 4 and {s for *_, s in seen} == set(SIDES)
    assert {t for _, _, t, _ in seen} == {True, False}


@pytest.mark.parametrize('field, value, match', [
    ('position', np.zeros(17), r'position has 17 entries; it needs 18'),
    ('velocity', np.zeros(0), r'velocity has 0 entries'),
    ('position', np.r_[np.zeros(3), np.nan, np.zeros(14)], r"position is not finite at \['q3'\]"),
    ('velocity', np.r_[np.inf, np.zeros(17)], r"velocity is not finite at \['y0'\]"),
    ('support_side', 2, 'support_side must be 0 or 1'),
    ('pivot', 7, 'pivot must be 0, 1 or 2'),
])
def test_observation_from_gait_state_raises_naming_the_field(typestore, messages, simulator,
                                                             field, value, match):
    msg = gait_state_message(typestore, messages, simulator)
    setattr(msg, field, value)
    with pytest.raises(SimulationError, match=match):
        observation_from_gait_state(msg)


def test_the_observation_does_not_alias_the_message(typestore, messages, simulator):
    msg = gait_state_message(typestore, messages, simulator)
    msg.position = msg.position.copy()  # writable, as an rclpy message's array is
    obs = observation_from_gait_state(msg)
    msg.position[:] = 1.0
    assert not np.any(obs.q == 1.0)


def test_command_round_trips_with_and_without_impedance_and_breakdown(typestore):
    plain = JointCommand(np.linspace(-1, 1, 18))
    pd = JointCommand(np.ones(18), np.full(18, 800.0), np.full(18, 80.0), np.linspace(0, 1, 18))
    q, v = np.linspace(-0.2, 0.3, 18), np.linspace(1.0, -1.0, 18)
    for sources in ({'posture': pd}, {'posture': pd, 'yaw': plain}, {}):
        answer = (ControllerCommand.of(sources, q, v) if sources
                  else ControllerCommand(plain, {}))
        msg = empty_command(typestore, 'gait_manager')
        for key, value in command_fields(answer).items():
            setattr(msg, key, value)
        back = command_of(command_from_message(msg))
        np.testing.assert_array_equal(back.command.effort, answer.command.effort)
        assert back.command.has_impedance == answer.command.has_impedance
        if answer.command.has_impedance:
            np.testing.assert_array_equal(back.command.reference, answer.command.reference)
        assert list(back.source_efforts) == list(answer.source_efforts)
        for name, tau in answer.source_efforts.items():
            np.testing.assert_array_equal(back.source_efforts[name], tau)


def test_command_with_a_subset_of_names_in_any_order(typestore):
    msg = effort_message(typestore, names=['q3', 'y0'], effort=[2.0, 5.0])
    msg.source_names, msg.source_efforts = ['posture', 'yaw'], np.array([1.0, 2.0, 3.0, 4.0])
    answer = command_of(command_from_message(msg))
    command = answer.command
    assert command.effort[3] == 2.0 and command.effort[0] == 5.0
    assert np.count_nonzero(command.effort) == 2
    assert answer.source_efforts['yaw'][3] == 3.0 and answer.source_efforts['yaw'][0] == 4.0
    assert np.count_nonzero(answer.source_efforts['posture']) == 2


@pytest.mark.parametrize('change, match', [
    ({'effort': [float('nan')] + [0.0] * 17}, r"effort is not finite at \['y0'\]"),
    ({'effort': [0.0] * 17}, 'effort has 17 entries for 18 joint names'),
    ({'names': ['y0', 'q1', 'knee']}, r"unknown joint names \['knee'\]"),
    ({'names': ['q1', 'q1'], 'effort': [0.0, 0.0]}, r"repeated joint names \['q1'\]"),
    ({'stiffness': [1.0] * 18}, 'all empty or all given'),
    ({'stiffness': [-1.0] * 18, 'damping': [0.0] * 18, 'position_reference': [0.0] * 18},
     'must be >= 0'),
    ({'stiffness': [1.0] * 18, 'damping': [0.0] * 3, 'position_reference': [0.0] * 18},
     'damping has 3 entries'),
    ({'source_names': ['posture'], 'source_efforts': [0.0] * 17},
     'source_efforts has 17 entries for 1 source names x 18 joint names'),
    ({'source_names': ['yaw', 'yaw'], 'source_efforts': [0.0] * 36},
     r"repeated source names in \['yaw', 'yaw'\]"),
    ({'source_names': ['yaw'], 'source_efforts': [float('inf')] + [0.0] * 17},
     'source_efforts is not finite'),
])
def test_command_from_message_raises_naming_the_problem(typestore, change, match):
    names = change.pop('names', None)
    effort = change.pop('effort', None if names is None else [0.0] * len(names))
    breakdown = {k: change.pop(k) for k in ('source_names', 'source_efforts') if k in change}
    msg = effort_message(typestore, names=names, effort=effort, **change)
    if breakdown:
        msg.source_names = breakdown['source_names']
        msg.source_efforts = np.asarray(breakdown['source_efforts'], dtype=float)
    with pytest.raises(SimulationError, match="source 'posture'.*" + match):
        command_from_message(msg)
