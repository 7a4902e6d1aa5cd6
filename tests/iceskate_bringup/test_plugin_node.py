"""A controller written in Python as a ROS node (``plugin_controller``,
iceskate_bringup.plugin_node): ``run_scene --ros`` starts one per plug-in of the scene, and the
graph gives the headless run."""

import json
import os
from pathlib import Path
import re
import shlex
import signal
import subprocess
import time

import numpy as np
import pytest

from iceskate_bringup.examples.visual_lifting_numpy import VisualLifting
from iceskate_bringup.plugin_node import (
    PluginNodeParameters,
    keyword_defaults,
    node_name,
    ros_value,
)
from iceskate_sim.errors import SimulationError

EXAMPLE = 'iceskate_bringup.examples.visual_lifting_numpy:VisualLifting'
USAGE = Path(__file__).resolve().parents[2] / 'docs' / 'usage.md'


def documented_plugin_node(tmp_path: Path) -> tuple[list[str], Path]:
    """The by-hand command of docs/usage.md, 'Your own controller', and a folder holding its
    ``my_package.my_module`` (the section's first Python block)."""
    text = USAGE.read_text().split('## Your own controller', 1)[1]
    code = re.search(r'```python\n(.*?)```', text, re.S).group(1)
    command = re.search(r'^ *(plugin_controller --ros-args .*)$', text, re.M).group(1)
    package = tmp_path / 'my_package'
    package.mkdir()
    (package / '__init__.py').write_text('')
    (package / 'my_module.py').write_text(code)
    return shlex.split(command), tmp_path


def test_the_node_takes_its_name_from_the_remapping_and_its_parameters_as_json():
    assert node_name(['--ros-args', '-r', '__node:=lifting']) == 'lifting'
    assert node_name([]) == 'plugin_controller'
    block = PluginNodeParameters(EXAMPLE, '{"desired_y": "fixed", "z_d": null}').block()
    assert block.plugin == EXAMPLE and block.parameters == {'desired_y': 'fixed', 'z_d': None}
    with pytest.raises(SimulationError, match='parameters must be a JSON mapping, got list'):
        PluginNodeParameters(EXAMPLE, '[1]').block()
    with pytest.raises(SimulationError, match='parameters is no JSON mapping'):
        PluginNodeParameters(EXAMPLE, '{desired_y: fixed}').block()


def test_the_keyword_arguments_of_a_plugin_class_become_typed_parameter_values():
    defaults = keyword_defaults(VisualLifting)
    assert defaults['kp'] == (20.0, 290.0, 1100.0) and defaults['z_d'] is None
    assert ros_value(defaults['kp']) == [20.0, 290.0, 1100.0]
    assert ros_value((1, 2.5)) == [1.0, 2.5] and ros_value(True) is True
    assert ros_value(None) is None and ros_value(()) is None and ros_value({'a': 1}) is None


@pytest.mark.parametrize('executable, package', [
    ('simulator', 'iceskate_sim'), ('visual_lifting', 'visual_lifting'),
    ('gait_manager', 'gait_manager'), ('plugin_controller', 'iceskate_bringup')])
def test_each_node_s_help_names_its_package(executable, package):
    done = subprocess.run([executable, '--help'], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith(f'usage: {executable} [-h] [--ros-args')
    assert lines[1].startswith(f'   or: ros2 run {package} {executable} [-h]')


@pytest.mark.ros
def test_the_documented_plugin_node_command_declares_the_keyword_parameters(tmp_path, ros_env,
                                                                            ros_context):
    """The docs' exact line starts the node; its keyword parameter is typed, set as given, and
    a value the class's default type refuses is one sentence."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    command, folder = documented_plugin_node(tmp_path)
    assert command[-2:] == ['-p', 'gain:=2.0']
    ros_env['PYTHONPATH'] = os.pathsep.join([str(folder), ros_env.get('PYTHONPATH', '')])
    bad = subprocess.run([*command[:-1], 'gain:=2'], env=ros_env, capture_output=True,
                         text=True, timeout=60)
    assert bad.returncode == 2  # refused input
    assert bad.stderr.strip().splitlines()[-1] == ("knees: error: parameter 'gain' must be of "
                                                   'type DOUBLE, as its default 5.0 is; write '
                                                   '2.0, not 2')
    node = subprocess.Popen(command, env=ros_env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    probe = Node('probe', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(probe)
    try:
        client = AsyncParameterClient(probe, 'knees')
        deadline = time.monotonic() + 60.0
        while not client.services_are_ready() and time.monotonic() < deadline:
            assert node.poll() is None, node.communicate()[0]
            executor.spin_once(timeout_sec=0.1)
        assert client.services_are_ready(), 'no parameter services of /knees within 60 s'

        def answer(future):
            executor.spin_until_future_complete(future, timeout_sec=30.0)
            assert future.done()
            return future.result()

        values = answer(client.get_parameters(['plugin', 'gain'])).values
        assert values[0].string_value == 'my_package.my_module:KneeDamper'
        assert (values[1].type, values[1].double_value) == (Parameter.Type.DOUBLE.value, 2.0)
        results = answer(client.set_parameters([Parameter('gain', value=3.0)])).results
        assert results[0].successful
    finally:
        executor.shutdown()
        probe.destroy_node()
        node.send_signal(signal.SIGINT)
        output = node.communicate(timeout=30)[0]
    assert node.returncode == 0, output
    assert "controller my_package.my_module:KneeDamper with {'gain': 2.0}" in output


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize('single_process', [False, True])
def test_the_graph_with_a_plugin_node_gives_the_headless_trajectory(tmp_path, ros_domain_id,
                                                                    single_process):
    pytest.importorskip('rclpy')
    from iceskate_bringup.graph import graph_nodes, run_graph
    from iceskate_bringup.runner import run
    from iceskate_bringup.scene import load_scene
    from iceskate_sim.run.scene import scene_raw

    raw = scene_raw('stand_python')
    raw['duration'] = 0.3
    raw['record'] = {'bag': False}
    path = tmp_path / 'scene.yaml'
    path.write_text(json.dumps(raw))  # JSON is YAML
    nodes = graph_nodes(str(path), tmp_path / 'nodes')
    lifting = next(n for n in nodes if n.node == 'lifting')
    assert lifting.executable == 'plugin_controller'
    assert lifting.ros_args()[1:3] == ['-r', '__node:=lifting']
    metrics = run_graph(str(path), tmp_path / 'ros', single_process=single_process,
                        domain_id=ros_domain_id, timeout=120.0)
    assert metrics['failure'] is None
    run(load_scene(path), tmp_path / 'headless', progress=False, picture=False)
    ros = np.load(tmp_path / 'ros' / 'trajectory.npz')
    headless = np.load(tmp_path / 'headless' / 'trajectory.npz')
    assert len(ros['t']) == len(headless['t']) == 300
    for key in ('q', 'v', 'head_target', 'tau_lifting', 'tau_posture'):
        assert np.max(np.abs(ros[key] - headless[key])) <= 1e-12, key


@pytest.mark.ros
@pytest.mark.slow
def test_a_failing_plugin_node_logs_its_error_and_the_simulator_names_it(tmp_path, ros_domain_id,
                                                                         monkeypatch, capsys):
    """The node logs the ControllerError and sends nothing at that instant; the simulator's
    control timeout then ends the run, cleanly, naming the node."""
    pytest.importorskip('rclpy')
    import os
    from pathlib import Path

    from iceskate_bringup.graph import run_graph
    from iceskate_sim.run.scene import scene_raw
    here = str(Path(__file__).resolve().parent)  # plugin_controllers, for the node's process
    monkeypatch.setenv('PYTHONPATH', os.pathsep.join([here, os.environ.get('PYTHONPATH', '')]))
    monkeypatch.syspath_prepend(here)
    raw = scene_raw('stand')
    raw['duration'] = 0.5
    raw['record'] = {'bag': True}
    raw['inputs'] = {'visual_lifting': raw['inputs']['visual_lifting'],
                     'bad': {'plugin': 'plugin_controllers:FailsAt',
                             'parameters': {'how': 'raise', 't_fail': 0.1}}}
    path = tmp_path / 'scene.yaml'
    path.write_text(json.dumps(raw))
    with pytest.raises(SimulationError, match=r"controller timeout at t=0\.100000 s: no command "
                       r"from node\(s\) 'bad'"):
        run_graph(str(path), tmp_path / 'ros', domain_id=ros_domain_id, timeout=120.0,
                  control_timeout=1.0)
    metrics = json.loads((tmp_path / 'ros' / 'metrics.json').read_text())
    assert metrics['sim_time_s'] == pytest.approx(0.1, abs=1e-9)
    assert (tmp_path / 'ros' / 'bag' / 'metadata.yaml').is_file()
    logs = Path(capsys.readouterr().err.split('logs in ')[1].split()[0])
    assert "controller 'bad' (plugin_controllers.FailsAt) at t=0.100000 s: ZeroDivisionError" \
        in (logs / 'bad.log').read_text()
