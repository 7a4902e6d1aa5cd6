"""LockstepSession (ROS-free): the simulator side of the graph gives the headless run.

The state goes through JointState/GaitState CDR bytes and back, as over ROS; each controller
answers with one ControllerCommand (its sources summed, with the breakdown).
"""

from dataclasses import replace
import json
from pathlib import Path
import time

import numpy as np
import pytest

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.runner import run
from iceskate_bringup.scene import load_scene, scene_sources
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.stamps import seconds_to_ns
from iceskate_sim.ros.lockstep import UNCONTROLLED_BATCH, LockstepSession
from iceskate_sim.run.session import Session
from oracle.commands import ControllerCommand, JointCommand, stack_commands, values_of
from oracle.messages import observation_from_gait_state

TINY = Path(__file__).resolve().parents[1] / 'integration' / 'data' / 'tiny_stand.yaml'


@pytest.fixture(scope='module')
def scene():
    return replace(load_scene(TINY), duration=0.01)


def make_session(scene, out=None, bag=None, lockstep=True):
    """The simulator side of the graph for ``scene`` (as the simulator node builds it)."""
    return LockstepSession(Session(scene, out, bag), scene_sources(scene), lockstep)


def controllers(scene, session):
    """The controller side of the graph, from messages (what the two nodes compute)."""
    stack = ControlStack(scene, session.robot, session.session.observation())
    return lambda obs: {node: values_of(command)
                        for node, command in stack_commands(stack, obs).items()}


def zero(scene, controller, value=0.0):
    """A command of ``controller`` applying ``value`` everywhere, with its breakdown."""
    sources = scene_sources(scene)[controller]
    return values_of(ControllerCommand(JointCommand(np.full(18, value)),
                                       {s: np.zeros(18) for s in sources}))


def drive(session, answer):
    ts = session.messages.typestore
    while not session.session.done:
        obs = observation_from_gait_state(ts.deserialize_cdr(
            session.state_bytes(('/gait_state',))['/gait_state'],
            'iceskate_interfaces/msg/GaitState'))
        for controller, command in answer(obs).items():
            assert session.offer(controller, seconds_to_ns(obs.t), command)
        assert session.missing() == []
        session.step()
        session.session.flush()
    return session.session.finish()


def test_lockstep_session_reproduces_the_headless_run(scene, tmp_path):
    run(scene, tmp_path / 'headless', progress=False)
    session = make_session(scene, tmp_path / 'ros', tmp_path / 'ros' / 'bag')
    metrics = drive(session, controllers(scene, session))
    a = np.load(tmp_path / 'ros' / 'trajectory.npz')
    b = np.load(tmp_path / 'headless' / 'trajectory.npz')
    assert sorted(a.files) == sorted(b.files)
    for key in a.files:
        scale = max(1.0, float(np.max(np.abs(b[key])))) if b[key].size else 1.0
        assert np.max(np.abs(a[key] - b[key]), initial=0.0) <= 1e-12 * scale, key
    headless = json.loads((tmp_path / 'headless' / 'metrics.json').read_text())
    assert metrics['sources'] == headless['sources'] == ['visual_lifting', 'posture',
                                                          'weight_transfer']
    assert metrics['sim_time_s'] == headless['sim_time_s']
    assert (tmp_path / 'ros' / 'bag' / 'metadata.yaml').is_file()


def test_sources_not_given_are_taken_from_the_first_commands(scene, tmp_path):
    """Controllers named without their sources (by hand, no parameter file): the breakdown of
    each one's first command is taken before the first period; the run equals the one with
    the sources given."""
    given = make_session(scene, tmp_path / 'given')
    expected = drive(given, controllers(scene, given))
    learned = LockstepSession(Session(scene, tmp_path / 'learned'),
                              dict.fromkeys(scene_sources(scene)))
    assert learned.sources == ('visual_lifting', 'gait_manager')  # one each until they answer
    metrics = drive(learned, controllers(scene, learned))
    assert learned.sources == given.sources == ('visual_lifting', 'posture', 'weight_transfer')
    assert metrics['sources'] == expected['sources']
    a, b = (np.load(tmp_path / name / 'trajectory.npz') for name in ('learned', 'given'))
    for key in b.files:
        assert np.array_equal(a[key], b[key]), key


def test_a_breakdown_that_changes_after_the_first_period_is_refused(scene):
    session = LockstepSession(Session(scene), {'visual_lifting': ('visual_lifting',),
                                               'gait_manager': None})
    answer = controllers(scene, session)
    obs = session.session.observation()
    for controller, command in answer(obs).items():
        session.offer(controller, seconds_to_ns(obs.t), command)
    session.step()
    obs = session.session.observation()
    with pytest.raises(SimulationError, match="command of 'gait_manager' breaks down into "
                       r"sources \['posture'\]; scene 'tiny_stand' runs \['posture', "
                       r"'weight_transfer'\] on it"):
        session.offer('gait_manager', seconds_to_ns(obs.t),
                      values_of(ControllerCommand(JointCommand(np.zeros(18)),
                                                  {'posture': np.zeros(18)})))


def test_offer_refuses_unknown_senders_and_stale_or_future_stamps(scene):
    session = make_session(scene)
    assert session.controllers == ('visual_lifting', 'gait_manager')
    gm = zero(scene, 'gait_manager')
    with pytest.raises(SimulationError, match="unknown source 'posture'"):
        session.offer('posture', 0, gm)  # a source is not a sender: its controller is
    with pytest.raises(SimulationError, match='in the future'):
        session.offer('gait_manager', 1_000_000, gm)
    for controller in session.controllers:
        assert session.offer(controller, 0, zero(scene, controller))
    assert not session.offer('gait_manager', 0, zero(scene, 'gait_manager', 1.0))  # repeat
    session.step()
    assert session.missing() == list(session.controllers)
    assert not session.offer('gait_manager', 0, gm)  # a late repeat of t_0: ignored too
    with pytest.raises(SimulationError, match='without commands'):
        session.step()
    for controller in session.controllers:
        session.offer(controller, 1_000_000, zero(scene, controller))
    session.step()
    with pytest.raises(SimulationError, match="stale command of 'gait_manager' stamped 0.0 s"):
        session.offer('gait_manager', 0, gm)


def test_offer_checks_the_breakdown_against_the_scenes_sources(scene):
    session = make_session(scene)
    assert scene_sources(scene)['gait_manager'] == ('posture', 'weight_transfer')
    swapped = values_of(ControllerCommand(JointCommand(np.zeros(18)), {
        'weight_transfer': np.zeros(18), 'posture': np.zeros(18)}))
    with pytest.raises(SimulationError, match=r"breaks down into sources \['weight_transfer', "
                                              r"'posture'\]; .* runs \['posture', "
                                              r"'weight_transfer'\]"):
        session.offer('gait_manager', 0, swapped)
    with pytest.raises(SimulationError, match='breaks down into sources'):  # none given
        session.offer('gait_manager', 0,
                      values_of(ControllerCommand(JointCommand(np.zeros(18)), {})))
    # a single-source controller may leave it out: its effort at the state is recorded
    pd = JointCommand(np.ones(18), np.full(18, 10.0), np.full(18, 2.0), np.full(18, 0.1))
    assert session.offer('visual_lifting', 0, values_of(ControllerCommand(pd, {})))
    session.offer('gait_manager', 0, zero(scene, 'gait_manager'))
    state = session.sim.state
    session.step()
    session.session.flush()
    recorded = session.session.trajectory.arrays()['tau_visual_lifting'][0]
    np.testing.assert_array_equal(recorded, pd.torque(state.q, state.v))


def test_offer_refuses_a_force_beyond_the_urdf_effort_limit_at_the_state(scene):
    """The command's generalized force at the state it answers (effort and impedance) must
    stay within each coordinate's effort limit (the URDF's 500 N m); at the limit it is taken."""
    session = make_session(scene)
    limit = session.robot.effort_limit
    assert limit.shape == (18,) and np.all(limit == 500.0)
    sources = scene_sources(scene)['gait_manager']
    state = session.sim.state

    def command(effort, *impedance):
        return values_of(ControllerCommand(JointCommand(effort, *impedance),
                                           {s: np.zeros(18) for s in sources}))
    at_limit = np.zeros(18)
    at_limit[5] = -500.0
    over = at_limit.copy()
    over[5] = np.nextafter(-500.0, -np.inf)
    with pytest.raises(SimulationError, match=r"'gait_manager' asks -500 N m of q5 at "
                                              r"t=0.000000 s, beyond its effort limit 500"):
        session.offer('gait_manager', 0, command(over))
    reference = state.q.copy()
    reference[9] += 1.0  # 1 rad from the state: 501 N m of stiffness there
    with pytest.raises(SimulationError, match='asks 501 N m of q9'):
        session.offer('gait_manager', 0, command(np.zeros(18), np.full(18, 501.0),
                                                 np.zeros(18), reference))
    with pytest.raises(SimulationError, match='N of y0'):
        session.offer('gait_manager', 0, command(np.full(18, 1e300)))
    assert session.offer('gait_manager', 0, command(at_limit))


def test_reset_is_refused_while_recording_and_restarts_otherwise(scene, tmp_path):
    recording = make_session(scene, bag=tmp_path / 'bag')
    with pytest.raises(SimulationError, match='refused while'):
        recording.reset()
    recording.session.finish()
    session = make_session(scene)
    for controller in session.controllers:
        session.offer(controller, 0, zero(scene, controller))
    session.step()
    session.reset()
    assert session.t_ns == 0 and session.session.periods == 0
    assert len(session.session.trajectory) == 0


def test_free_running_holds_the_latest_command(scene):
    session = make_session(scene, lockstep=False)
    assert session.missing() == list(session.controllers)
    session.step()  # no command yet: nothing applied
    session.offer('gait_manager', 0, zero(scene, 'gait_manager'))  # late but not older: taken
    session.step()
    with pytest.raises(SimulationError, match='stale'):  # older than the controller's last
        session.offer('gait_manager', -1, zero(scene, 'gait_manager'))
    assert session.session.periods == 2


def test_rejected_commands_are_summarised_per_reason(capsys):
    """The run's rejected commands: counted per reason (numbers left out), the first kept whole;
    run_scene --ros prints them at the end."""
    from iceskate_bringup.graph import _report_rejected
    from iceskate_sim.ros.lockstep import FIRST_REJECTED, LoopMonitor
    monitor = LoopMonitor(('gait_manager',), 5.0, 0.001)
    reasons = [f"stale command of 'gait_manager' stamped 0.00{k} s (simulation at 0.009 s)"
               for k in range(7)] + ["command from unknown source 'posture'"]
    for reason in reasons:
        monitor.reject(reason)
    summary = monitor.rejected_summary()
    assert summary['count'] == 8 and summary['first'] == reasons[:FIRST_REJECTED]
    assert summary['by_reason'] == {
        "stale command of 'gait_manager' stamped # s (simulation at # s)": 7,
        "command from unknown source 'posture'": 1}
    _report_rejected({'rejected_commands': summary}, {'ROS_LOG_DIR': '/logs'})
    err = capsys.readouterr().err
    assert err.startswith('graph: 8 command(s) rejected (each is in /logs/simulator.log):\n')
    assert "  7 x stale command of 'gait_manager' stamped # s" in err
    assert err.count('  first: ') == FIRST_REJECTED
    _report_rejected({'rejected_commands': LoopMonitor((), 5.0, 0.001).rejected_summary()}, {})
    assert capsys.readouterr().err == ''


def test_commands_of_another_run_are_refused_said_once_and_counted(scene):
    """A simulator given a run token takes only commands that carry it: another run's (or a
    hand-started node's, without one) are refused, said once per controller name, each counted;
    the graph's clashes are said once each."""
    from iceskate_sim.ros.effort_cdr import CommandEncoder, ForeignCommand
    from iceskate_sim.ros.lockstep import LockstepLoop
    session = make_session(scene)
    loop = LockstepLoop(session, lambda topic, data: None, lambda text, failed: None,
                        run_token='ours')
    loop.phase = 'running'
    gm = zero(scene, 'gait_manager', 1.0)
    said = [loop.take(CommandEncoder('gait_manager', token).encode(gm, 0))
            for token in ('', 'theirs', '')]
    assert said[0].startswith("rejected command: a command naming 'gait_manager' is not of "
                              'this run (its run token differs)') and said[1:] == [None, None]
    assert session.missing() == list(session.controllers)  # none was taken
    assert loop.monitor.rejected == 3
    assert loop.monitor.rejected_summary()['by_reason'] == {ForeignCommand.REASON: 3}
    assert loop.take(CommandEncoder('gait_manager', 'ours').encode(gm, 0)) is None
    assert session.missing() == ['visual_lifting']
    first = loop.clashes(2, ['gait_manager', 'gait_manager', 'visual_lifting', 'spy'])
    assert len(first) == 3 and first[0].startswith('2 nodes publish gait_state')
    assert "1 node(s) named 'gait_manager' publish effort_commands on this ROS domain besides " \
        "the run's own; commands without this run's token are refused" in first
    assert "1 node(s) named 'spy' publish effort_commands on this ROS domain; commands " \
        "without this run's token are refused" in first
    assert loop.clashes(2, ['gait_manager', 'gait_manager', 'spy']) == []  # said once each
    assert loop.clashes(1, ['gait_manager', 'visual_lifting']) == []


def test_the_runs_own_command_beyond_the_effort_limit_ends_the_run(scene):
    """Refused and counted, and the run ends at once as its controller's failure (it would
    only send the same command again)."""
    from iceskate_sim.ros.effort_cdr import CommandEncoder
    from iceskate_sim.ros.lockstep import LockstepLoop
    reports = []
    loop = LockstepLoop(make_session(scene), lambda topic, data: None,
                        lambda text, failed: reports.append((text, failed)), run_token='ours')
    loop.phase = 'running'
    said = loop.take(CommandEncoder('gait_manager', 'ours').encode(
        zero(scene, 'gait_manager', 600.0), 0))
    assert said.startswith("rejected command: command of 'gait_manager' asks 600 N of y0 at "
                           't=0.000000 s')
    assert said.endswith('; the run ends')
    assert loop.phase == 'finished' and loop.exit_code == 1 and loop.monitor.rejected == 1
    metrics = loop.session.session.metrics
    assert metrics['end'] == 'controller_failed' and 'beyond its effort limit 500' in \
        metrics['failure'] and reports[-1][1]


def test_a_scene_without_controllers_runs_in_lockstep(tmp_path):
    """Nothing to wait for: the loop steps on its timer (it used to wait forever)."""
    from iceskate_sim.ros.lockstep import LockstepLoop
    scene = replace(load_scene(TINY), inputs={}, duration=0.12)
    loop = LockstepLoop(LockstepSession(Session(scene), {}), lambda *a: None,
                        lambda *a: None)
    assert loop.try_begin(set(), 0, 1.0)
    for _ in range(10):
        loop.tick()
    assert loop.phase == 'finished' and loop.session.session.metrics['failure'] is None
    assert loop.session.session.periods == 120


def test_a_lockstep_run_keeps_its_pace():
    """With a pace the loop steps only the periods due (0.05 s of simulated time a second:
    about 15 periods of 1 ms in 0.3 s), however often its timer ticks."""
    from iceskate_sim.ros.lockstep import LockstepLoop
    scene = replace(load_scene(TINY), inputs={}, duration=1.0)
    loop = LockstepLoop(LockstepSession(Session(scene), {}), lambda *a: None,
                        lambda *a: None, pace=0.05)
    assert loop.try_begin(set(), 0, 1.0)
    end = time.monotonic() + 0.3
    while time.monotonic() < end:
        loop.tick()
        time.sleep(0.002)
    assert 10 <= loop.session.session.periods <= 17
    loop.pace = 0.0  # none: the timer's batches, as fast as it goes
    loop.tick()
    assert loop.session.session.periods >= 10 + UNCONTROLLED_BATCH
    loop.stop()
