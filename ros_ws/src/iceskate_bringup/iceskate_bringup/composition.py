"""The controllers of a scene in one process, for the headless runner: ``ControlStack`` (the
native laws and the plug-ins, in the scene's order). See docs/architecture.md, 'The control
laws in C++'.
"""

from __future__ import annotations

from iceskate_bringup.controllers import kind_of
from iceskate_bringup.scene import node_parameters, scene_sources
from iceskate_sim.model.observation import Observation
from iceskate_sim.model.robot import Robot
from iceskate_sim.physics.native_control import native_kinematics, native_observation
from iceskate_sim.run.scene import Scene


class ControlStack:
    """The controllers of a scene that run (``scene_sources``: those with a source), each built
    as its kind says (``kind_of``: shipped or a plug-in), with their own model data."""

    def __init__(self, scene: Scene, robot: Robot, initial: Observation) -> None:
        self.kinematics = native_kinematics(robot)  # the laws' own model data, as in the nodes
        #: the native law of each controller node, in summing order (the scene's)
        self.controllers: dict[str, object] = {}
        #: the controllers written in Python (they take the GIL once per period)
        self.plugins: tuple[str, ...] = ()
        running = scene_sources(scene)
        for node, params in node_parameters(scene).items():
            if node not in running:
                continue
            kind = kind_of(node, scene.inputs[node])
            law = self.controllers[node] = kind.law(node, params)
            if kind.in_python:
                self.plugins += (node,)
            if kind.start is not None:
                kind.start(law, native_observation(initial), self.kinematics)
