"""``ros2 run visual_lifting visual_lifting``: the eq. (9) head-pose controller as a ROS node.

Subscribes ``gait_state`` (the hybrid state), publishes one ``EffortCommand`` (source
'visual_lifting') per instant on ``effort_commands``, stamped with the state's time, with the
head target psi_d it steers to (``head_target``, recorded beside the head pose). Its parameters
are the fields of ``VisualLiftingParameters`` as typed ROS parameters (``ros2 param list
/visual_lifting``; a scene's ``inputs.visual_lifting`` block becomes a parameter file at launch).
The target's origin psi(0) is the head pose of the state at t = 0 (latched again after a reset).
"""

from __future__ import annotations

import numpy as np

from iceskate_sim.command import ControllerCommand, JointCommand
from iceskate_sim.controller_node import ControllerNode
from iceskate_sim.node_support import run_node
from iceskate_sim.observation import Observation
from visual_lifting.errors import VisualLiftingError
from visual_lifting.law import VisualLiftingParameters, head_origin, visual_lifting

SOURCE = 'visual_lifting'


class VisualLiftingNode(ControllerNode[VisualLiftingParameters]):
    """Visual lifting as a node."""

    parameter_class = VisualLiftingParameters
    parameter_error = VisualLiftingError
    law_errors = (VisualLiftingError,)

    def __init__(self, **kwargs) -> None:
        self.psi_initial: np.ndarray | None = None
        super().__init__('visual_lifting', **kwargs)

    def compute(self, obs: Observation) -> ControllerCommand:
        """tau_h = J_H^T K_p (psi_d - psi) at ``obs``, with its target psi_d."""
        if obs.t == 0.0 or self.psi_initial is None:
            if obs.t != 0.0:
                self.get_logger().warning(f'first state seen at t={obs.t} s, not 0: its head '
                                          'pose is taken as psi(0)')
            self.psi_initial = head_origin(obs, self.dynamics)
        task = visual_lifting(obs, self.dynamics, self.params, self.psi_initial)
        return ControllerCommand.of({SOURCE: JointCommand(task.tau)}, obs.q, obs.v, task.psi_d)


def main(args: list[str] | None = None) -> int:
    """Console entry point."""
    return run_node(VisualLiftingNode, 'visual_lifting', args)


if __name__ == '__main__':
    raise SystemExit(main())
