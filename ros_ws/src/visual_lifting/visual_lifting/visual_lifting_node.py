"""``ros2 run visual_lifting visual_lifting``: the eq. (9) head-pose controller as a ROS node:
``gait_state`` in, one ``EffortCommand`` (source 'visual_lifting', with its head target) per
instant out; its parameters are ``VisualLiftingParameters``' fields. See docs/usage.md,
'Through ROS 2: the node graph, bags, replay, analysis'.
"""

from __future__ import annotations

import iceskate_native
from iceskate_sim.model.command import CommandValues
from iceskate_sim.physics.native_control import native_values
from iceskate_sim.ros.controller_node import ControllerNode
from iceskate_sim.ros.node_support import run_node
from visual_lifting.errors import VisualLiftingError
from visual_lifting.native import VisualLiftingController
from visual_lifting.parameters import VisualLiftingParameters


class VisualLiftingNode(ControllerNode[VisualLiftingParameters]):
    """Visual lifting as a node (the native law)."""

    parameter_class = VisualLiftingParameters
    parameter_error = VisualLiftingError
    law_errors = (VisualLiftingError,)

    def __init__(self, **kwargs) -> None:
        super().__init__('visual_lifting', **kwargs)
        self.controller = VisualLiftingController(self.params)

    def _on_parameters(self, params: VisualLiftingParameters) -> None:
        """New parameters from the next state on; psi(0) stays."""
        super()._on_parameters(params)
        self.controller.set_parameters(params)

    def compute(self, obs: iceskate_native.Observation) -> CommandValues:
        """tau_h = J_H^T K_p (psi_d - psi) at ``obs``, with its target psi_d."""
        if self.controller.origin is None and obs.t != 0.0:
            self.get_logger().warning(f'first state seen at t={obs.t} s, not 0: its head pose '
                                      'is taken as psi(0)')
        return native_values(self.controller, obs, self.kinematics)


def main(args: list[str] | None = None) -> int:
    """Console entry point."""
    return run_node(VisualLiftingNode, 'visual_lifting', 'visual_lifting', args, __doc__,
                    VisualLiftingParameters)


if __name__ == '__main__':
    raise SystemExit(main())
