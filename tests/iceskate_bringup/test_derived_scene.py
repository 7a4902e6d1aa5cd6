"""A scene with a ``base`` replaces an inherited controller by a plug-in (the block that names
``plugin`` replaces the base's whole) or removes it (a null block): the composed controllers,
what a headless run and the ROS graph run, run_scene's start line, and the one-sentence errors."""

import json
from pathlib import Path
import re

import pytest
import yaml

from iceskate_bringup import api
from iceskate_bringup.graph import graph_nodes
from iceskate_bringup.runner import main
from iceskate_bringup.scene import load_scene, scene_sources
from iceskate_sim.errors import SimulationError
from iceskate_sim.run.scene import load_scene as simulator_scene

HERE = Path(__file__).resolve().parent
SKATE_SOURCES = ('posture', 'weight_transfer', 'heel', 'arm_assist', 'yaw')
REPLACED = """base: skate
scene: replaced
duration: 0.05
record: {bag: false}
inputs:
  visual_lifting:
    plugin: plugin_controllers:PlainLaw
    parameters: {gain: 0.5}
"""
REMOVED = """base: skate
scene: removed
duration: 0.05
record: {bag: false}
inputs:
  visual_lifting: null
  knees:
    plugin: plugin_controllers:NamedSources
    parameters: {names: [knee_damper]}
"""


@pytest.fixture(autouse=True)
def _test_plugins(monkeypatch):
    """The test controllers import as ``plugin_controllers``."""
    monkeypatch.syspath_prepend(str(HERE))


def _scene_file(folder: Path, text: str, name: str = 'derived.yaml') -> Path:
    path = folder / name
    path.write_text(text)
    return path


def test_a_plugin_block_replaces_the_inherited_block_whole(tmp_path):
    scene = load_scene(_scene_file(tmp_path, REPLACED))
    assert scene.inputs['visual_lifting'] == {'plugin': 'plugin_controllers:PlainLaw',
                                              'parameters': {'gain': 0.5}}  # no desired_y, v_d
    assert list(scene.inputs) == ['visual_lifting', 'gait_manager']  # the base's order
    assert scene.inputs['gait_manager'] == load_scene('skate').inputs['gait_manager']
    assert scene_sources(scene) == {'visual_lifting': ('visual_lifting',),
                                    'gait_manager': SKATE_SOURCES}


def test_a_null_block_removes_the_inherited_controller(tmp_path):
    scene = load_scene(_scene_file(tmp_path, REMOVED))
    assert list(scene.inputs) == ['gait_manager', 'knees']
    assert scene_sources(scene) == {'gait_manager': SKATE_SOURCES, 'knees': ('knee_damper',)}


@pytest.mark.parametrize('text, sources', [
    (REPLACED, ['visual_lifting', *SKATE_SOURCES]),
    (REMOVED, [*SKATE_SOURCES, 'knee_damper']),
])
def test_a_headless_run_runs_only_the_composed_controllers(tmp_path, text, sources):
    run = api.run(_scene_file(tmp_path, text), out=tmp_path / 'out')
    assert run.error is None and run.metrics['end'] == 'completed'
    assert json.loads((tmp_path / 'out' / 'metrics.json').read_text())['sources'] == sources
    assert sorted(k for k in run.columns if k.startswith('tau_')) == sorted(
        f'tau_{source}' for source in sources)


def test_a_removed_controller_gets_no_node_in_the_ros_graph(tmp_path):
    specs = graph_nodes(str(_scene_file(tmp_path, REMOVED)), tmp_path / 'out')
    assert sorted(spec.name or spec.executable for spec in specs) == [
        'gait_manager', 'knees', 'simulator']
    params = tmp_path / 'out' / 'params'
    simulator = yaml.safe_load((params / 'simulator.yaml').read_text())
    assert simulator['simulator']['ros__parameters']['controllers'] == ['gait_manager', 'knees']
    assert yaml.safe_load((params / 'scene.yaml').read_text())['inputs']['visual_lifting'] is None
    assert list(simulator_scene(params / 'scene.yaml').inputs) == ['gait_manager', 'knees']
    assert not (params / 'visual_lifting.yaml').exists()


@pytest.mark.parametrize('text, extra, line', [
    (REPLACED, [], 'run_scene: controllers: visual_lifting (plugin plugin_controllers:PlainLaw, '
                   'this scene), gait_manager (skate)'),
    (REMOVED, [], 'run_scene: controllers: gait_manager (skate), knees (plugin '
                  'plugin_controllers:NamedSources, this scene); visual_lifting removed by this '
                  'scene'),
    (REPLACED, ['--set', 'inputs.gait_manager.enabled=[posture]', '--set',
                'inputs.visual_lifting=null'],
     'run_scene: controllers: gait_manager (skate, changed by --set); visual_lifting removed by '
     '--set'),
])
def test_run_scene_says_at_its_start_which_controllers_run(tmp_path, capsys, text, extra, line):
    path = _scene_file(tmp_path, text)
    assert main([str(path), '--out', str(tmp_path / 'out'), '--quiet', *extra]) == 0
    err = capsys.readouterr().err
    assert err.splitlines()[0] == line, err


def test_a_chain_names_the_scene_that_gave_and_changed_each_controller(tmp_path, capsys):
    _scene_file(tmp_path, REMOVED, 'middle.yaml')
    path = _scene_file(tmp_path, 'base: middle.yaml\nscene: top\ninputs:\n'
                                 '  gait_manager: {enabled: [posture]}\n')
    assert main([str(path), '--out', str(tmp_path / 'out'), '--quiet']) == 0
    assert capsys.readouterr().err.splitlines()[0] == (
        'run_scene: controllers: gait_manager (skate, changed by this scene), knees (plugin '
        'plugin_controllers:NamedSources, middle.yaml); visual_lifting removed by middle.yaml')


@pytest.mark.parametrize('text, message', [
    (REPLACED.replace('parameters: {gain: 0.5}', 'desired_y: moving'),
     "scene key 'inputs.visual_lifting.desired_y': unknown key; allowed: ['plugin', "
     "'parameters']"),
    (REMOVED.replace('visual_lifting: null', 'visual_liftin: null'),
     "scene key 'inputs.visual_liftin': null removes a controller of the base scene, and "
     "'skate' runs none of that name"),
    (REPLACED.replace('plugin: plugin_controllers:PlainLaw\n', ''),  # merged: no plugin
     "scene key 'inputs.visual_lifting': unknown key parameters; expected one of"),
])
def test_what_stays_wrong_is_refused_in_one_sentence(tmp_path, capsys, text, message):
    path = _scene_file(tmp_path, text)
    with pytest.raises(SimulationError, match='^' + re.escape(message)):
        load_scene(path)
    assert main([str(path), '--out', str(tmp_path / 'out'), '--quiet']) == 2
    err = capsys.readouterr().err
    assert err.startswith(f'run_scene: error: {message}') and err.count('\n') == 1, err
    assert not (tmp_path / 'out').exists()
