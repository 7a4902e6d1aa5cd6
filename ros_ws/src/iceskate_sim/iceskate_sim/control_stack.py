"""The controllers a scene asks for, as one callable: Observation -> command of each node.

The headless runner calls this at every control instant; the ROS nodes call the very same
law functions (``visual_lifting.law.visual_lifting``, ``gait_manager.law.gait_manager_torques``)
on the observation they rebuild from messages, so both paths give the same torques. Sources a
scene does not enable are never computed.

(The control-law packages depend on iceskate_sim's core; this module imports them at run time
only, so the package manifests stay acyclic.)
"""

from __future__ import annotations

import numpy as np

from iceskate_sim.command import ControllerCommand, JointCommand
from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.observation import Observation
from iceskate_sim.robot import Robot
from iceskate_sim.scene import Scene


class ControlStack:
    """Visual lifting and the gait-manager sources of a scene, with their own model data."""

    def __init__(self, scene: Scene, robot: Robot, initial: Observation) -> None:
        from gait_manager.law import GaitManagerParameters
        from visual_lifting.law import VisualLiftingParameters
        # controllers use their own model data (as separate nodes would), with default physics
        self.dynamics = GaitDynamics(robot)
        self.visual_lifting = (VisualLiftingParameters.from_dict(scene.visual_lifting or {})
                               if scene.visual_lifting is not None else None)
        self.gait_manager = (GaitManagerParameters.from_dict(scene.gait_manager or {})
                             if scene.gait_manager is not None else None)
        self.psi_initial = self.dynamics.head_pose(initial.contact(), initial.q)[0]
        self.last_psi_d = self.psi_initial.copy()

    def commands(self, obs: Observation) -> dict[str, ControllerCommand]:
        """What each controller node sends at ``obs`` (the sum of its enabled sources, with
        their breakdown), keyed by node name, in the order visual_lifting, gait_manager."""
        from gait_manager.law import gait_manager_commands, head_offset
        from visual_lifting.law import visual_lifting
        commands: dict[str, ControllerCommand] = {}
        if self.visual_lifting is not None:
            offset = (head_offset(obs, self.dynamics, self.gait_manager)
                      if self.gait_manager is not None else np.zeros(2))
            task = visual_lifting(obs, self.dynamics, self.visual_lifting, self.psi_initial,
                                  offset)
            commands['visual_lifting'] = ControllerCommand.of(
                {'visual_lifting': JointCommand(task.tau)}, obs.q, obs.v)
            self.last_psi_d = task.psi_d
        if self.gait_manager is not None and self.gait_manager.enabled:
            commands['gait_manager'] = ControllerCommand.of(
                gait_manager_commands(obs, self.dynamics, self.gait_manager), obs.q, obs.v)
        return commands
