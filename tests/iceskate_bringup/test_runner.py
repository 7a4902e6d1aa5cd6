"""The headless runner: outputs, a short skate run, determinism and same-code-as-nodes."""

from dataclasses import replace
import json

import numpy as np
import pytest
import yaml

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.runner import main, run
from iceskate_bringup.scene import load_scene, scene_sources
from iceskate_sim.model.dynamics import ContactState
from iceskate_sim.model.modes import get_mode
from iceskate_sim.model.robot import SIDES, load_robot
from iceskate_sim.physics.simulation import Simulator
from oracle.commands import stack_commands
from oracle.dynamics import GaitDynamics

SHORT_SKATE = 5.0  # s: the first steps of the skate scene (past the arm assist's release)


@pytest.fixture(scope='module')
def skate_run(tmp_path_factory):
    out = tmp_path_factory.mktemp('skate')
    scene = replace(load_scene('skate'), duration=SHORT_SKATE)
    metrics = run(scene, out, progress=False)
    return out, metrics


def test_short_skate_run_does_not_fall_and_writes_everything(skate_run):
    out, metrics = skate_run
    assert metrics['end'] == 'completed' and not metrics['fell'], metrics['failure']
    assert metrics['sim_time_s'] == pytest.approx(SHORT_SKATE, abs=1e-9)
    for name in ('metrics.json', 'events.json', 'trajectory.npz', 'bag/metadata.yaml'):
        assert (out / name).is_file(), name
    assert json.loads((out / 'metrics.json').read_text()) == json.loads(json.dumps(metrics))
    for key in ('scene', 'wall_time_s', 'real_time_factor', 'steps', 'failure',
                'forward_distance_m', 'head_error_rms', 'mode_time_fraction', 'transitions',
                'zmp_outside_support_fraction', 'max_constraint_residual', 'arm_swing'):
        assert key in metrics, key
    assert sum(metrics['mode_time_fraction'].values()) == pytest.approx(1.0)
    whole, steady = metrics['arm_swing'], metrics['arm_swing_steady']
    assert abs(2 * steady['samples'] - whole['samples']) <= 2  # the second half in time
    assert steady['q11_peak_to_peak'] <= whole['q11_peak_to_peak']


@pytest.mark.slow
def test_a_whole_skate_run_writes_at_most_20_mb_by_default(tmp_path):
    """The shipped 15 s ``skate`` run, default outputs: every period in trajectory.npz, every
    4th in the bag, all of it under 20 MB."""
    assert main(['skate', '--out', str(tmp_path), '--quiet']) == 0
    written = sum(f.stat().st_size for f in tmp_path.rglob('*') if f.is_file())
    assert written <= 20e6, f'{written / 1e6:.1f} MB'
    info = yaml.safe_load((tmp_path / 'bag' / 'metadata.yaml').read_text())
    counts = {item['topic_metadata']['name']: item['message_count']
              for item in info['rosbag2_bagfile_information']['topics_with_message_count']}
    assert len(np.load(tmp_path / 'trajectory.npz')['t']) == 15000
    assert counts['/joint_dynamics'] == 3750 and counts['/tf'] == 1875


def test_short_skate_run_visits_the_expected_modes(skate_run):
    """The scene's single-support start (mode 1; the first sample may already be on the toe,
    2, after the transitions due at t = 0), then the ice cycle of docs/model.md §6.6: support
    gliding (F-G: 3), front heel landing and gliding (Hs: 7 or 8; the gait passes these within a
    control period, so only the events show them), support exchanges (E6/E7)."""
    out, _metrics = skate_run
    events = json.loads((out / 'events.json').read_text())
    modes = set(np.load(out / 'trajectory.npz')['mode'].tolist())
    assert events[0]['from_mode'] == 1
    assert int(np.load(out / 'trajectory.npz')['mode'][0]) in (1, 2, 3, 4)  # swing foot up
    assert 3 in modes  # a sampled glide
    assert {e['to_mode'] for e in events} & {7, 8}  # passed through (maybe within a period)
    exchanges = [e['t'] for e in events if e['event'] == 'E6']
    assert len(exchanges) >= 3, exchanges


def test_y0_never_decreases_on_ice(skate_run):
    """The support foot never slides backward (toe pick); y0 restarts at each exchange."""
    out, _metrics = skate_run
    a = np.load(out / 'trajectory.npz')
    same_support = np.diff(a['step_index']) == 0
    assert same_support.sum() > 100
    assert np.all(np.diff(a['q'][:, 0])[same_support] >= -1e-9)  # 1 nm: event-time round-off


def test_recorded_accelerations_are_the_dynamics_at_the_sample(skate_run):
    """The npz holds qdd at t_k under the held command: row 11 (right shoulder, no constraint
    force reaches it) of M qdd + h + g equals the applied generalized force."""
    out, _metrics = skate_run
    a = np.load(out / 'trajectory.npz')
    dynamics = GaitDynamics(load_robot())
    for k in np.linspace(0, len(a['t']) - 1, 12).astype(int):
        contact = ContactState(get_mode(int(a['mode'][k])), SIDES[int(a['side'][k])],
                               {0: 'toe', 1: 'toe', 2: 'heel'}[int(a['pivot'][k])])
        q, v, qdd = a['q'][k], a['v'][k], a['qdd'][k]
        act = list(contact.mode.active)
        row = act.index(11)
        lhs = (dynamics.mass_matrix(contact, q)[row] @ qdd[act]
               + dynamics.bias_terms(contact, q, v)[row]
               + dynamics.gravity_terms(contact, q)[row])
        assert lhs == pytest.approx(a['applied'][k][11], abs=1e-9), k


def test_runner_is_deterministic(tmp_path):
    scene = replace(load_scene('stand'), duration=0.05)
    first = run(scene, tmp_path / 'a', progress=False)
    second = run(scene, tmp_path / 'b', progress=False)
    a, b = (np.load(tmp_path / d / 'trajectory.npz') for d in 'ab')
    assert np.array_equal(a['q'], b['q']) and np.array_equal(a['v'], b['v'])
    assert first['transitions'] == second['transitions']


def test_control_stack_computes_only_the_scene_sources():
    scene = load_scene('stand')
    robot = load_robot()
    sim = Simulator(robot, scene.simulator, scene.initial)
    commands = stack_commands(ControlStack(scene, robot, sim.observation()), sim.observation())
    assert list(commands) == ['visual_lifting', 'gait_manager']
    assert {node: tuple(c.source_efforts) for node, c in commands.items()} == scene_sources(scene)
    assert commands['gait_manager'].command.has_impedance  # the posture's


def test_main_refuses_a_bad_scene_with_exit_status_2(tmp_path, capsys):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('scene: bad\nduration: 1.0\ncontrol_period: 0.001\ninputs: {}\nfoo: 1\n')
    assert main([str(bad), '--out', str(tmp_path / 'out'), '--quiet']) == 2
    assert "scene key 'foo'" in capsys.readouterr().err


@pytest.mark.parametrize('option', [['--rt-priority', '10'], ['--single-process']])
def test_main_refuses_graph_options_without_ros(tmp_path, capsys, option):
    assert main(['stand', '--out', str(tmp_path / 'out'), '--quiet', *option]) == 2
    assert '--single-process and --rt-priority need --ros' in capsys.readouterr().err
    assert not (tmp_path / 'out').exists()


def test_set_changes_scene_keys_of_the_run(tmp_path, capsys):
    """``--set KEY=VALUE`` (VALUE in YAML) changes the scene the run uses; the ROS graph gets
    the same scene in ``params/scene.yaml``."""
    out = tmp_path / 'out'
    assert main(['stand', '--out', str(out), '--quiet', '--set', 'duration=0.02',
                 '--set', 'floor.mu=0.5', '--set', 'inputs.visual_lifting.kp=[30, 290, 1e3]',
                 '--set', 'record.bag=false']) == 0
    metrics = json.loads((out / 'metrics.json').read_text())
    assert metrics['sim_time_s'] == pytest.approx(0.02)
    assert not (out / 'bag').exists()
    from iceskate_bringup.graph import graph_nodes
    graph_nodes('stand', tmp_path / 'graph', overrides={'floor.mu': 0.5})
    written = yaml.safe_load((tmp_path / 'graph' / 'params' / 'scene.yaml').read_text())
    assert written['floor']['mu'] == 0.5 and written['scene'] == 'stand'
    simulator = yaml.safe_load((tmp_path / 'graph' / 'params' / 'simulator.yaml').read_text())
    assert simulator['simulator']['ros__parameters']['scene'] == str(
        (tmp_path / 'graph' / 'params' / 'scene.yaml').resolve())


@pytest.mark.parametrize(('setting', 'expected'), [
    ('floor.mu', "--set 'floor.mu': give KEY=VALUE (e.g. floor.mu=0.01)"),
    ('floor.mu=[0.1,', "--set floor.mu: '[0.1,' is no YAML value"),
    ('floor.nu=0.1', "scene key 'floor.nu'"),
    ('floor.mu=-1', "scene key 'floor.mu'"),
    ('initial.q[0]=1', 'override initial.q[0]: initial.q is not in the scene; give the whole'),
    ('a..b=1', "override a..b: 'a..b' is not a dotted scene key"),
])
def test_a_bad_set_is_refused_in_one_sentence(tmp_path, capsys, setting, expected):
    assert main(['stand', '--out', str(tmp_path / 'out'), '--quiet', '--set', setting]) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count('\n') == 1, err
    assert not (tmp_path / 'out').exists()


@pytest.mark.parametrize('options, expected', [
    (['--pace', '2'], '--pace needs --view'),
    (['--view-port', '9000'], '--view-port needs --view'),
    (['--view', '--pace', '-1'], '--pace must be >= 0 (0: as fast as it runs) and <= 1000'),
    (['--view', '--pace', 'nan'], '--pace must be >= 0'),
    (['--view', '--view-port', '70000'], '--view-port must be 0..65535'),
    (['--view', '--ros', '--pace', '2000'], '--pace must be >= 0 (0: as fast as it runs) and '
                                            '<= 1000'),
    (['--view', '--view-host', '192.0.2.1'], 'cannot serve the view on 192.0.2.1'),
])
def test_bad_view_options_are_refused_in_one_sentence(tmp_path, capsys, options, expected):
    assert main(['stand', '--out', str(tmp_path / 'out'), '--quiet', '--duration', '0.01',
                 *options]) == 2
    err = capsys.readouterr().err
    assert expected in err and 'Traceback' not in err


def test_the_arm_swing_ratio_is_the_mean_swing_over_the_same_scene_without_yaw(tmp_path, capsys):
    """``--arm-swing-ratio`` runs the scene again with ``yaw`` left out of the gait manager's
    sources; its ratio equals the one of the shipped ``skate_no_yaw`` scene (the same change,
    written as a scene file) and is written into metrics.json."""
    from iceskate_sim.run.metrics import arm_swing_ratio
    assert main(['skate', '--out', str(tmp_path / 'yaw'), '--quiet', '--duration', '6',
                 '--arm-swing-ratio']) == 0
    printed = json.loads(capsys.readouterr().out.split('\noutputs in')[0])
    metrics = json.loads((tmp_path / 'yaw' / 'metrics.json').read_text())
    without = run(replace(load_scene('skate_no_yaw'), duration=6.0), None, progress=False)
    expected = arm_swing_ratio(metrics, without)
    assert expected > 2.0  # the shoulders swing with tau8 from the 4th step
    assert metrics['arm_swing_ratio'] == pytest.approx(expected, rel=1e-12)
    assert printed['arm_swing_ratio'] == metrics['arm_swing_ratio']
    for figure in ('arm_swing', 'arm_swing_steady'):  # both arm-swing figures are printed
        assert printed[figure] == metrics[figure]
    swing = metrics['arm_swing']
    assert swing['mean_peak_to_peak'] == pytest.approx(
        (swing['q11_peak_to_peak'] + swing['q14_peak_to_peak']) / 2, rel=1e-15)


def test_a_scene_without_the_yaw_input_has_no_arm_swing_ratio(tmp_path, capsys):
    assert main(['stand', '--out', str(tmp_path / 'out'), '--quiet', '--duration', '0.05',
                 '--arm-swing-ratio']) == 0
    err = capsys.readouterr().err
    assert 'stand has no torso-yaw input' in err and 'Traceback' not in err
    assert 'arm_swing_ratio' not in json.loads((tmp_path / 'out' / 'metrics.json').read_text())
