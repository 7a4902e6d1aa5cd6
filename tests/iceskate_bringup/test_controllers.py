"""The registry of controller kinds: every shipped entry's and the plug-in kind's parameters,
law, sources and node are what the scene, the in-process stack and the node graph get."""

from __future__ import annotations

from dataclasses import replace
import importlib

import numpy as np
import pytest
import yaml

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.controllers import PLUGIN, SHIPPED, kind_of
from iceskate_bringup.graph import graph_nodes
from iceskate_bringup.scene import load_scene, parse_scene, scene_sources
import iceskate_native
from iceskate_native.parameters import flatten
from iceskate_sim.errors import InputRefused
from iceskate_sim.installed import share_path
from iceskate_sim.run.session import Session


@pytest.mark.parametrize('name', sorted(SHIPPED))
def test_an_entry_builds_its_law_and_names_its_installed_node(name: str) -> None:
    kind = SHIPPED[name]
    params = kind.parameters(name, {})
    assert isinstance(kind.law(name, params), iceskate_native.Controller)
    assert kind.ros_parameters(params) == flatten(params)  # typed ROS parameters of the node
    assert (kind.node.package, kind.node.executable, kind.node.renamed) == (name, name, False)
    _assert_installed(kind)


def _assert_installed(kind) -> None:
    node = kind.node
    module = importlib.import_module(node.module)
    assert isinstance(getattr(module, node.node_class), type)
    executable = share_path(node.package).parents[1] / 'lib' / node.package / node.executable
    assert executable.is_file(), executable


def test_a_plugin_is_a_kind_registered_as_the_shipped_ones_are(tmp_path) -> None:
    block = {'plugin': 'iceskate_bringup.examples.visual_lifting_numpy:VisualLifting',
             'parameters': {}}
    kind = kind_of('lifting', block)
    assert kind is PLUGIN and kind.in_python and kind.node.renamed
    params = kind.parameters('lifting', block)
    assert isinstance(kind.law('lifting', params), iceskate_native.Controller)
    assert kind.sources('lifting', params) == ('lifting',)
    _assert_installed(kind)
    scene = {**load_scene('stand').raw, 'inputs': {'lifting': block}}
    (tmp_path / 'scene.yaml').write_text(yaml.safe_dump(scene))
    specs = graph_nodes(str(tmp_path / 'scene.yaml'), tmp_path / 'out')
    (spec,) = [s for s in specs if s.node == 'lifting']
    assert (spec.package, spec.executable, spec.module, spec.node_class) == (
        'iceskate_bringup', 'plugin_controller', 'iceskate_bringup.plugin_node',
        'PluginControllerNode')


def test_scenes_stack_and_sources_follow_the_registry() -> None:
    scene = replace(load_scene('skate'), duration=0.01)
    sources = scene_sources(scene)
    assert list(sources) == [node for node in scene.inputs if node in sources]
    assert set(sources) == set(SHIPPED)  # the shipped gait runs both
    for node, names in sources.items():
        kind = SHIPPED[node]
        assert names == kind.sources(node, kind.parameters(node, scene.inputs[node]))
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    assert list(stack.controllers) == list(sources)
    obs = session.sim.kernel.observation()
    for node, law in stack.controllers.items():
        values, _, _, answered = law.command(obs, stack.kinematics)
        assert tuple(answered) == sources[node] and np.all(np.isfinite(values))


def test_a_controller_the_registry_does_not_hold_is_refused_by_name() -> None:
    raw = {**load_scene('stand').raw, 'inputs': {'knee_brace': {'gain': 1.0}}}
    with pytest.raises(InputRefused, match=r"'inputs.knee_brace': unknown controller; one of "
                                           r"\['visual_lifting', 'gait_manager'\]"):
        parse_scene(raw)


def test_a_bad_value_of_a_registered_controller_is_refused_with_its_key() -> None:
    raw = {**load_scene('stand').raw, 'inputs': {'visual_lifting': {'kp': [1.0, 2.0]}}}
    with pytest.raises(InputRefused, match=r"scene key 'inputs.visual_lifting': "):
        parse_scene(raw)
