"""The controllers of a scene in one process: Observation -> the command of each node.

The headless runner calls this at every control instant; the ROS controller nodes run the very
same native laws (``visual_lifting.native.VisualLiftingController``,
``gait_manager.native.GaitManagerController``) with the same parameters (``node_parameters``) on
the observation they rebuild from a GaitState message, through the same conversion
(``iceskate_sim.native_control.native_command``), so both paths give the same commands. Sources
a scene does not enable are never computed.
"""

from __future__ import annotations

from gait_manager.law import GaitManagerParameters
from gait_manager.native import GaitManagerController
from iceskate_bringup.scene import node_parameters
from iceskate_sim.command import ControllerCommand
from iceskate_sim.native_control import native_command, native_kinematics, native_observation
from iceskate_sim.observation import Observation
from iceskate_sim.robot import Robot
from iceskate_sim.scene import Scene
from visual_lifting.law import VisualLiftingParameters
from visual_lifting.native import VisualLiftingController


class ControlStack:
    """Visual lifting and the gait-manager sources of a scene, with their own model data."""

    def __init__(self, scene: Scene, robot: Robot, initial: Observation) -> None:
        self.kinematics = native_kinematics(robot)  # the laws' own model data, as in the nodes
        params = node_parameters(scene)
        vl, gm = params.get('visual_lifting'), params.get('gait_manager')
        #: the native law of each controller node, in summing order
        self.controllers: dict[str, object] = {}
        if isinstance(vl, VisualLiftingParameters):
            lifting = VisualLiftingController(vl)
            lifting.latch_origin(native_observation(initial), self.kinematics)  # psi(0)
            self.controllers['visual_lifting'] = lifting
        if isinstance(gm, GaitManagerParameters) and gm.enabled:
            self.controllers['gait_manager'] = GaitManagerController(gm)

    def commands(self, obs: Observation) -> dict[str, ControllerCommand]:
        """What each controller node sends at ``obs`` (the sum of its enabled sources, with
        their breakdown), keyed by node name, in the order visual_lifting, gait_manager."""
        return {node: native_command(controller, obs, self.kinematics)
                for node, controller in self.controllers.items()}
