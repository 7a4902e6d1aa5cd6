"""The controllers of a scene in one process: Observation -> the command of each node.

The headless runner calls this at every control instant; the ROS controller nodes call the very
same law functions (``visual_lifting.law.visual_lifting``,
``gait_manager.law.gait_manager_commands``) with the same parameters (``node_parameters``) on
the observation they rebuild from a GaitState message, so both paths give the same commands.
Sources a scene does not enable are never computed.
"""

from __future__ import annotations

from gait_manager.law import GaitManagerParameters, gait_manager_commands
from iceskate_bringup.scene import node_parameters
from iceskate_sim.command import ControllerCommand, JointCommand
from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.observation import Observation
from iceskate_sim.robot import Robot
from iceskate_sim.scene import Scene
from visual_lifting.law import VisualLiftingParameters, head_origin, visual_lifting


class ControlStack:
    """Visual lifting and the gait-manager sources of a scene, with their own model data."""

    def __init__(self, scene: Scene, robot: Robot, initial: Observation) -> None:
        # the controllers use their own model data (as separate nodes do), default physics
        self.dynamics = GaitDynamics(robot)
        params = node_parameters(scene)
        vl, gm = params.get('visual_lifting'), params.get('gait_manager')
        self.visual_lifting = vl if isinstance(vl, VisualLiftingParameters) else None
        self.gait_manager = (gm if isinstance(gm, GaitManagerParameters) and gm.enabled
                             else None)
        self.psi_initial = head_origin(initial, self.dynamics)

    def commands(self, obs: Observation) -> dict[str, ControllerCommand]:
        """What each controller node sends at ``obs`` (the sum of its enabled sources, with
        their breakdown), keyed by node name, in the order visual_lifting, gait_manager."""
        commands: dict[str, ControllerCommand] = {}
        if self.visual_lifting is not None:
            task = visual_lifting(obs, self.dynamics, self.visual_lifting, self.psi_initial)
            commands['visual_lifting'] = ControllerCommand.of(
                {'visual_lifting': JointCommand(task.tau)}, obs.q, obs.v, task.psi_d)
        if self.gait_manager is not None:
            commands['gait_manager'] = ControllerCommand.of(
                gait_manager_commands(obs, self.dynamics, self.gait_manager), obs.q, obs.v)
        return commands
