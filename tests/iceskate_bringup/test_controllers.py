"""The registry of shipped controllers: every entry's parameter class, law, sources and node are
what the scene, the in-process stack and the node graph get from it."""

from __future__ import annotations

from dataclasses import replace
import importlib

import numpy as np
import pytest

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.controllers import SHIPPED
from iceskate_bringup.scene import load_scene, parse_scene, scene_sources
import iceskate_native
from iceskate_native.parameters import flatten
from iceskate_sim.errors import InputRefused
from iceskate_sim.installed import share_path
from iceskate_sim.run.session import Session


@pytest.mark.parametrize('name', sorted(SHIPPED))
def test_an_entry_builds_its_law_and_names_its_installed_node(name: str) -> None:
    entry = SHIPPED[name]
    params = entry.parameters.from_dict({})
    assert isinstance(entry.law(params), iceskate_native.Controller)
    assert flatten(params)  # typed ROS parameters of the node
    module = importlib.import_module(f'{name}.{name}_node')
    assert isinstance(getattr(module, entry.node_class), type)
    executable = share_path(name).parents[1] / 'lib' / name / name
    assert executable.is_file(), executable


def test_scenes_stack_and_sources_follow_the_registry() -> None:
    scene = replace(load_scene('skate'), duration=0.01)
    sources = scene_sources(scene)
    assert list(sources) == [node for node in scene.inputs if node in sources]
    assert set(sources) == set(SHIPPED)  # the shipped gait runs both
    for node, names in sources.items():
        assert names == SHIPPED[node].sources(SHIPPED[node].parameters.from_dict(
            scene.inputs[node]))
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
