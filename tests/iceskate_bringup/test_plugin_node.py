"""A controller written in Python as a ROS node (``plugin_controller``,
iceskate_bringup.plugin_node): ``run_scene --ros`` starts one per plug-in of the scene, and the
graph gives the headless run."""

import json

import numpy as np
import pytest

from iceskate_bringup.plugin_node import PluginNodeParameters, node_name
from iceskate_sim.errors import SimulationError

EXAMPLE = 'iceskate_bringup.examples.visual_lifting_numpy:VisualLifting'


def test_the_node_takes_its_name_from_the_remapping_and_its_parameters_as_json():
    assert node_name(['--ros-args', '-r', '__node:=lifting']) == 'lifting'
    assert node_name([]) == 'plugin_controller'
    block = PluginNodeParameters(EXAMPLE, '{"desired_y": "fixed", "z_d": null}').block()
    assert block.plugin == EXAMPLE and block.parameters == {'desired_y': 'fixed', 'z_d': None}
    with pytest.raises(SimulationError, match='parameters must be a JSON mapping, got list'):
        PluginNodeParameters(EXAMPLE, '[1]').block()
    with pytest.raises(SimulationError, match='parameters is no JSON mapping'):
        PluginNodeParameters(EXAMPLE, '{desired_y: fixed}').block()


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
    for key in ('q', 'v', 'psi_d', 'tau_lifting', 'tau_posture'):
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
