"""``ros2 run gait_manager gait_manager``: the gait-manager sources as one ROS node.

Subscribes ``gait_state`` (the hybrid state), publishes per instant one ``EffortCommand``
(source 'gait_manager') on ``effort_commands``, stamped with the state's time: the sum of its
enabled sources ('posture', 'feedforward', 'weight_transfer', 'heel', 'arm_assist', 'yaw'; the
posture command carries the joint impedance) and each source's share (``source_names``).
Its parameters are the fields of ``GaitManagerParameters`` as typed ROS parameters, one per
field of each block (``posture.stiffness``, ``yaw.amplitude``, ..., ``enabled``); a scene's
``inputs.gait_manager`` block becomes a parameter file at launch. The sources run natively
(``gait_manager.native``).
"""

from __future__ import annotations

from gait_manager.errors import GaitManagerError
from gait_manager.native import GaitManagerController
from gait_manager.parameters import GaitManagerParameters
import iceskate_native
from iceskate_sim.model.command import CommandValues
from iceskate_sim.physics.native_control import native_values
from iceskate_sim.ros.controller_node import ControllerNode
from iceskate_sim.ros.node_support import run_node


class GaitManagerNode(ControllerNode[GaitManagerParameters]):
    """The enabled gait-manager sources as a node (the native sources)."""

    parameter_class = GaitManagerParameters
    parameter_error = GaitManagerError
    law_errors = (GaitManagerError,)

    def __init__(self, **kwargs) -> None:
        super().__init__('gait_manager', **kwargs)
        self.controller = GaitManagerController(self.params)
        if not self.params.enabled:
            self.get_logger().warning('no source enabled: the node stays idle')

    def _on_parameters(self, params: GaitManagerParameters) -> None:
        """New parameters from the next state on."""
        super()._on_parameters(params)
        self.controller.set_parameters(params)

    @property
    def active(self) -> bool:
        """Idle while no source is enabled."""
        return bool(self.params.enabled)

    def compute(self, obs: iceskate_native.Observation) -> CommandValues:
        """The sum of the enabled sources at ``obs``, with each source's share."""
        if self.controller.head_start_y is None and obs.t != 0.0:
            self.get_logger().warning(f'first state seen at t={obs.t} s, not 0: its head y is '
                                      "taken as the start of the stabiliser's pace point")
        return native_values(self.controller, obs, self.kinematics)


def main(args: list[str] | None = None) -> int:
    """Console entry point."""
    return run_node(GaitManagerNode, 'gait_manager', args, __doc__, GaitManagerParameters)


if __name__ == '__main__':
    raise SystemExit(main())
