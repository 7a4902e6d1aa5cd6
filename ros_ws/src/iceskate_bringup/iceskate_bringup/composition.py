"""The controllers of a scene in one process, for the headless runner: ``ControlStack`` (the
native laws and the plug-ins, in the scene's order). See docs/architecture.md, 'The control
laws in C++'.
"""

from __future__ import annotations

from gait_manager.native import GaitManagerController
from gait_manager.parameters import GaitManagerParameters
from iceskate_bringup.plugin import PluginBlock, make_controller
from iceskate_bringup.scene import node_parameters
from iceskate_sim.model.observation import Observation
from iceskate_sim.model.robot import Robot
from iceskate_sim.physics.native_control import native_kinematics, native_observation
from iceskate_sim.run.scene import Scene
from visual_lifting.native import VisualLiftingController
from visual_lifting.parameters import VisualLiftingParameters


class ControlStack:
    """Visual lifting, the gait-manager sources and the plug-ins of a scene, with their own
    model data."""

    def __init__(self, scene: Scene, robot: Robot, initial: Observation) -> None:
        self.kinematics = native_kinematics(robot)  # the laws' own model data, as in the nodes
        #: the native law of each controller node, in summing order (the scene's)
        self.controllers: dict[str, object] = {}
        #: the controllers written in Python (they take the GIL once per period)
        self.plugins: tuple[str, ...] = ()
        for node, params in node_parameters(scene).items():
            if isinstance(params, VisualLiftingParameters):
                lifting = VisualLiftingController(params)
                lifting.latch_origin(native_observation(initial), self.kinematics)  # psi(0)
                self.controllers[node] = lifting
            elif isinstance(params, GaitManagerParameters) and params.enabled:
                self.controllers[node] = GaitManagerController(params)
            elif isinstance(params, PluginBlock):
                self.controllers[node] = make_controller(node, params)
                self.plugins += (node,)
