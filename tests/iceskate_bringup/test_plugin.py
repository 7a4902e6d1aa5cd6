"""Controllers written in Python inside the native loop (iceskate_bringup.plugin, the nanobind
trampoline of iceskate_native.Controller): eq. (9) in numpy gives the C++ law's runs, bad
answers and exceptions end a run cleanly with one sentence, bad plug-ins are refused before it."""

from dataclasses import fields
import json
import math
from pathlib import Path

import numpy as np
import pytest

from iceskate_bringup.runner import main, simulate
from iceskate_bringup.scene import node_parameters, parse_scene, scene_sources
import iceskate_native
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.robot import load_robot
from iceskate_sim.physics.native_control import native_kinematics
from iceskate_sim.run.scene import scene_raw

EXAMPLE = 'iceskate_bringup.examples.visual_lifting_numpy:VisualLifting'
HERE = Path(__file__).resolve().parent


@pytest.fixture(autouse=True)
def _test_plugins(monkeypatch):
    """The test controllers import as ``plugin_controllers``."""
    monkeypatch.syspath_prepend(str(HERE))


def _raw(name: str, duration: float, bag: bool = False) -> dict:
    raw = scene_raw(name)
    raw['duration'] = duration
    raw['record'] = {'bag': bag}
    return raw


def _with_plugin(name: str, duration: float) -> dict:
    """Scene ``name`` with its visual lifting replaced by the numpy example, given the composed
    parameters of the C++ law (the moving stance of the gait manager included), listed first."""
    raw = _raw(name, duration)
    vl = node_parameters(parse_scene(raw))['visual_lifting']
    parameters = {f.name: getattr(vl, f.name) for f in fields(vl)}
    parameters = {k: list(v) if isinstance(v, tuple) else v for k, v in parameters.items()}
    inputs = {'lifting': {'plugin': EXAMPLE, 'parameters': parameters}}
    raw['inputs'] = inputs | {k: v for k, v in raw['inputs'].items() if k != 'visual_lifting'}
    return raw


def _run(raw: dict, out: Path) -> tuple[dict, SimulationError | None]:
    outcome = simulate(parse_scene(raw), out, progress=False, picture=False)
    return outcome.metrics, outcome.error


def _compare(a: Path, b: Path, tol: float) -> None:
    ta, tb = np.load(a / 'trajectory.npz'), np.load(b / 'trajectory.npz')
    assert len(ta['t']) == len(tb['t'])
    for key in ('t', 'q', 'v', 'qdd', 'applied', 'psi', 'head_target', 'multipliers', 'mode'):
        assert np.max(np.abs(ta[key] - tb[key]), initial=0.0) <= tol, key
    assert np.max(np.abs(ta['tau_visual_lifting'] - tb['tau_lifting'])) <= tol


def test_the_numpy_law_gives_the_cpp_laws_stand(tmp_path):
    """2 s of `stand`, its visual lifting replaced by the plug-in (the shipped `stand_python`
    scene): the same trajectory to 1e-9 (in fact bit for bit)."""
    metrics_a, error_a = _run(_raw('stand', 2.0), tmp_path / 'cpp')
    metrics_b, error_b = _run(_raw('stand_python', 2.0), tmp_path / 'python')
    assert error_a is None and error_b is None
    _compare(tmp_path / 'cpp', tmp_path / 'python', 1e-9)
    assert metrics_a['head_error_rms'] == pytest.approx(metrics_b['head_error_rms'], abs=1e-9)


def test_the_numpy_law_with_the_gait_manager_gives_the_cpp_laws_skate(tmp_path):
    """2 s of `skate`, visual lifting replaced by the plug-in, the gait manager kept: the same
    event sequence (and the same trajectory to 1e-9)."""
    _run(_raw('skate', 2.0), tmp_path / 'cpp')
    _run(_with_plugin('skate', 2.0), tmp_path / 'python')
    ea = json.loads((tmp_path / 'cpp' / 'events.json').read_text())
    eb = json.loads((tmp_path / 'python' / 'events.json').read_text())
    assert len(ea) > 5
    assert [(e['from_mode'], e['to_mode'], e['event']) for e in ea] == \
        [(e['from_mode'], e['to_mode'], e['event']) for e in eb]
    assert max(abs(x['t'] - y['t']) for x, y in zip(ea, eb, strict=True)) <= 1e-9
    _compare(tmp_path / 'cpp', tmp_path / 'python', 1e-9)


def _failing(how: str, t_fail: float, bag: bool = False) -> dict:
    raw = _raw('stand', 0.5, bag)
    raw['inputs'] = {'visual_lifting': raw['inputs']['visual_lifting'],
                     'bad': {'plugin': 'plugin_controllers:FailsAt',
                             'parameters': {'how': how, 't_fail': t_fail}}}
    return raw


@pytest.mark.parametrize(('how', 'message'), [
    ('nan', r"source 'bad' torque\[3\] is nan: every entry must be finite"),
    ('short', r"source 'bad' torque has 17 entries, expected 18"),
    ('source', r"its answer has no command of source 'bad'"),
    ('raise', r'ZeroDivisionError: float division by zero \(plugin_controllers\.py:\d+\)'),
])
def test_a_bad_answer_or_an_exception_ends_the_run_cleanly_in_one_sentence(tmp_path, how,
                                                                         message):
    """The samples before the failing instant are recorded, the outputs written (the bag
    closed), and the error is one sentence naming the controller, its class and the time."""
    metrics, error = _run(_failing(how, 0.2, bag=True), tmp_path)
    assert isinstance(error, SimulationError)
    text = str(error)
    assert '\n' not in text
    assert text.startswith("controller 'bad' (plugin_controllers.FailsAt) at t=0.200000 s: ")
    assert __import__('re').search(message, text), text
    assert metrics['failure'] == text
    assert metrics['end'] == 'controller_failed' and not metrics['fell']  # no fall
    assert metrics['sim_time_s'] == pytest.approx(0.2, abs=1e-9)
    assert len(np.load(tmp_path / 'trajectory.npz')['t']) == 200
    assert (tmp_path / 'bag' / 'metadata.yaml').is_file()


def test_run_scene_says_so_and_exits_1(tmp_path, capsys):
    path = tmp_path / 'bad.yaml'
    path.write_text(json.dumps(_failing('raise', 0.0)))  # JSON is YAML
    assert main([str(path), '--out', str(tmp_path / 'out'), '--quiet']) == 1
    err = capsys.readouterr().err
    assert "run_scene: error: controller 'bad' (plugin_controllers.FailsAt) at t=0.000000 s: " \
           'ZeroDivisionError' in err
    assert (tmp_path / 'out' / 'metrics.json').is_file()


def test_a_class_without_compute_is_a_controller_error():
    kinematics = native_kinematics(load_robot())
    obs = iceskate_native.Observation(0.0, np.zeros(18), np.zeros(18), 1, 0, 0, 0, 0.0, 0.0,
                                      math.nan)
    with pytest.raises(iceskate_native.ControllerError,
                       match=r'Controller at t=0\.000000 s: its class defines no compute'):
        iceskate_native.Controller().command(obs, kinematics)


def test_the_exception_is_the_cause_of_the_controller_error():
    """Called directly, a failing compute raises iceskate_native.ControllerError with the
    controller's own exception (and its traceback) as its cause."""
    from plugin_controllers import FailsAt
    kinematics = native_kinematics(load_robot())
    obs = iceskate_native.Observation(0.0, np.zeros(18), np.zeros(18), 1, 0, 0, 0, 0.0, 0.0,
                                      math.nan)
    with pytest.raises(iceskate_native.ControllerError, match='ZeroDivisionError') as info:
        FailsAt('raise').command(obs, kinematics)
    assert isinstance(info.value.__cause__, ZeroDivisionError)
    assert info.value.__cause__.__traceback__ is not None


def test_sources_impedance_and_head_target_cross_as_a_command_carries_them():
    from plugin_controllers import TwoSources
    kinematics = native_kinematics(load_robot())
    q, v = np.zeros(18), np.zeros(18)
    q[3], v[3] = 0.05, 0.2
    obs = iceskate_native.Observation(0.1, q, v, 1, 0, 0, 0, 0.0, 0.0, math.nan)
    values, impedance, steers, names = TwoSources().command(obs, kinematics)
    assert impedance and steers and names == ['push_knee', 'hold_ankle']
    n = 18
    assert values[4] == 2.0 and values[n + 3] == 10.0 and values[2 * n + 3] == 1.0
    assert values[3 * n + 3] == pytest.approx(0.1)
    assert values[4 * n + 4] == 2.0  # push_knee's torque
    assert values[5 * n + 3] == pytest.approx(10.0 * (0.1 - 0.05) - 1.0 * 0.2)  # hold_ankle's
    assert list(values[6 * n:]) == [0.0, 1.5, 0.0]


def test_a_plain_object_runs_through_the_adapter_and_joins_in_the_scenes_order(tmp_path):
    raw = _raw('stand', 0.05)
    raw['inputs'] = {'damper': {'plugin': 'plugin_controllers:PlainLaw',
                                'parameters': {'gain': 2.0}}} | raw['inputs']
    scene = parse_scene(raw)
    assert list(scene_sources(scene)) == ['damper', 'visual_lifting', 'gait_manager']
    metrics, error = _run(raw, tmp_path)
    assert error is None and not metrics['fell']
    tau = np.load(tmp_path / 'trajectory.npz')['tau_damper']
    assert np.array_equal(tau, -2.0 * np.load(tmp_path / 'trajectory.npz')['v'])


@pytest.mark.parametrize(('block', 'message'), [
    ({'plugin': 'not a path'}, "scene key 'inputs.mine.plugin': must be 'package.module:Class', "
                               "got 'not a path'"),
    ({'plugin': 'no_such_package.module:Class'},
     "scene key 'inputs.mine.plugin': no module 'no_such_package' to import "
     "'no_such_package.module'"),
    ({'plugin': 'iceskate_bringup.examples.visual_lifting_numpy:Nope'},
     "scene key 'inputs.mine.plugin': module 'iceskate_bringup.examples.visual_lifting_numpy' "
     "has no 'Nope'"),
    ({'plugin': 'iceskate_bringup.examples.visual_lifting_numpy:ramp'},
     'is not a controller class'),
    ({'plugin': EXAMPLE, 'parameters': {'kq': 1.0}},
     "scene key 'inputs.mine.parameters': .*unexpected keyword argument 'kq'"),
    ({'plugin': EXAMPLE, 'parameters': {'desired_y': 'up'}},
     "scene key 'inputs.mine.parameters': desired_y must be"),
    ({'plugin': EXAMPLE, 'parameters': [1]},
     "scene key 'inputs.mine.parameters': must be a mapping, got list"),
    ({'plugin': EXAMPLE, 'gains': 1}, "scene key 'inputs.mine.gains': unknown key"),
])
def test_a_bad_plugin_is_refused_in_one_sentence(block, message):
    raw = _raw('stand', 0.1)
    raw['inputs'] = {'mine': block}
    with pytest.raises(SimulationError, match=message) as info:
        parse_scene(raw)
    assert '\n' not in str(info.value)


@pytest.mark.parametrize(('node', 'names', 'message'), [
    ('simulator', ['mine'], "scene key 'inputs.simulator': 'simulator' is the simulator node's "
                            'name'),
    ('mine', ['posture'], "scene key 'inputs.mine': its source 'posture' is also a source of "
                          'inputs.gait_manager'),
    ('mine', ['push'], "scene key 'inputs.mine': its source 'push' is also a source of the "
                       "scene's push"),
])
def test_a_plugin_that_would_share_a_name_is_refused(node, names, message):
    """Each source is its own column of the record, and the simulator node's name is its own:
    a plug-in may take neither."""
    raw = _raw('stand', 0.1)
    raw['inputs'][node] = {'plugin': 'plugin_controllers:NamedSources',
                           'parameters': {'names': names}}
    with pytest.raises(SimulationError, match=message):
        parse_scene(raw)


def test_run_scene_refuses_a_bad_plugin_before_the_run(tmp_path, capsys):
    raw = _raw('stand', 0.1)
    raw['inputs'] = {'mine': {'plugin': 'no_such_package.module:Class'}}
    path = tmp_path / 'bad.yaml'
    path.write_text(json.dumps(raw))
    assert main([str(path), '--out', str(tmp_path / 'out'), '--quiet']) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("run_scene: error: scene key 'inputs.mine.plugin': no module")
    assert '\n' not in err
    assert not (tmp_path / 'out').exists()


def test_the_kinematics_answers_an_observation_as_its_state():
    """The queries a Python controller makes with ``obs`` equal those with (mode, side, pivot,
    q[, v]); ``active`` lists the mode's coordinates."""
    kinematics = native_kinematics(load_robot())
    rng = np.random.default_rng(3)
    q, v = 0.1 * rng.standard_normal(18), rng.standard_normal(18)
    q[0] = v[0] = 0.0  # mode 2: the support foot does not glide
    obs = iceskate_native.Observation(0.5, q, v, 2, 1, 1, 3, 0.1, 0.0, math.nan)
    state = (2, 1, 1, q)
    for a, b in zip(kinematics.head_pose(obs), kinematics.head_pose(*state), strict=True):
        assert np.array_equal(a, b)
    assert np.array_equal(kinematics.gravity(obs), kinematics.gravity(*state))
    assert np.array_equal(kinematics.swing_heel_z_row(obs), kinematics.swing_heel_z_row(*state))
    for a, b in zip(kinematics.centre_of_mass(obs), kinematics.centre_of_mass(*state, v),
                    strict=True):
        assert np.array_equal(a, b)
    assert np.array_equal(kinematics.frame_position(obs, 'pelvis_centre'),
                          kinematics.frame_position(*state, 'pelvis_centre'))
    assert np.array_equal(kinematics.joint_position(obs, 9), kinematics.joint_position(*state, 9))
    assert np.array_equal(kinematics.joint_velocity(obs, 9),
                          kinematics.joint_velocity(*state, v, 9))
    assert 1 in kinematics.active(2) and 0 not in kinematics.active(2)
    with pytest.raises(ValueError):
        kinematics.active(21)


@pytest.mark.parametrize('names', [('',), ('', 'a'), ('a', 'a')])
def test_the_loop_refuses_sources_that_are_empty_or_repeated(names):
    """A Python controller handed to the native loop directly (no scene in between) still
    gets its source names checked, the first one included."""
    from plugin_controllers import NamedSources

    from iceskate_sim.run.scene import load_scene
    from iceskate_sim.run.session import Session
    scene = load_scene('stand')
    session = Session(scene)
    loop = session.sim.control_loop(native_kinematics(session.robot), [NamedSources(names)], (),
                                    session.psi_initial)
    _, error = session.sim.run_loop(loop, 1)
    assert isinstance(error, iceskate_native.ControllerError)
    assert "its 'sources' must be distinct non-empty names" in str(error)
