"""``ros2 run visual_lifting visual_lifting``: the eq. (9) head-pose controller as a ROS node.

Subscribes ``gait_state`` (the hybrid state), publishes one ``EffortCommand`` (source
'visual_lifting') per instant on ``effort_commands``, stamped with the state's time. Its
parameters are the scene's ``inputs.visual_lifting`` block (parameter ``scene``). The target's
origin psi(0) is the head pose of the state at t = 0 (latched again after a reset); the moving
stance shift comes from ``gait_manager.law.head_offset`` with the same scene's parameters, as in
the headless control stack.
"""

from __future__ import annotations

import numpy as np

from gait_manager.errors import GaitManagerError
from gait_manager.law import GaitManagerParameters, head_offset
from iceskate_sim.command import JointCommand
from iceskate_sim.controller_node import ControllerNode
from iceskate_sim.node_support import run_node
from iceskate_sim.observation import Observation
from iceskate_sim.scene import Scene
from visual_lifting.errors import VisualLiftingError
from visual_lifting.law import VisualLiftingParameters, visual_lifting

SOURCE = 'visual_lifting'


class VisualLiftingNode(ControllerNode):
    """Visual lifting of one scene."""

    law_errors = (VisualLiftingError, GaitManagerError)

    def __init__(self, **kwargs) -> None:
        self.params: VisualLiftingParameters | None = None
        self.gait_manager: GaitManagerParameters | None = None
        self.psi_initial: np.ndarray | None = None
        super().__init__('visual_lifting', **kwargs)

    def configure(self, scene: Scene) -> bool:
        """Law parameters from the scene (validated when the scene was loaded)."""
        if scene.visual_lifting is None:
            return False
        self.params = VisualLiftingParameters.from_dict(scene.visual_lifting or {})
        if scene.gait_manager is not None:
            self.gait_manager = GaitManagerParameters.from_dict(scene.gait_manager or {})
        return True

    def compute(self, obs: Observation) -> dict[str, JointCommand]:
        """tau_h = J_H^T K_p (psi_d - psi) at ``obs``."""
        if obs.t == 0.0 or self.psi_initial is None:
            if obs.t != 0.0:
                self.get_logger().warning(f'first state seen at t={obs.t} s, not 0: its head '
                                          'pose is taken as psi(0)')
            self.psi_initial = self.dynamics.head_pose(obs.contact(), obs.q)[0]
        offset = (head_offset(obs, self.dynamics, self.gait_manager)
                  if self.gait_manager is not None else np.zeros(2))
        task = visual_lifting(obs, self.dynamics, self.params, self.psi_initial, offset)
        return {SOURCE: JointCommand(task.tau)}


def main(args: list[str] | None = None) -> int:
    """Console entry point."""
    return run_node(VisualLiftingNode, 'visual_lifting', args)


if __name__ == '__main__':
    raise SystemExit(main())
