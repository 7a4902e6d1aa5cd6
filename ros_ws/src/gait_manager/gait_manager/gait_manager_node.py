"""``ros2 run gait_manager gait_manager``: the gait-manager sources as one ROS node.

Subscribes ``gait_state`` (the hybrid state), publishes per instant one ``EffortCommand``
(source 'gait_manager') on ``effort_commands``, stamped with the state's time: the sum of its
enabled sources ('posture', 'feedforward', 'weight_transfer', 'heel', 'arm_assist', 'yaw'; the
posture command carries the joint impedance) and each source's share (``source_names``).
Its parameters are the fields of ``GaitManagerParameters`` as typed ROS parameters, one per
field of each block (``posture.stiffness``, ``yaw.amplitude``, ..., ``enabled``); a scene's
``inputs.gait_manager`` block becomes a parameter file at launch.
"""

from __future__ import annotations

from gait_manager.errors import GaitManagerError
from gait_manager.law import GaitManagerParameters, gait_manager_commands
from iceskate_sim.command import ControllerCommand
from iceskate_sim.controller_node import ControllerNode
from iceskate_sim.node_support import run_node
from iceskate_sim.observation import Observation


class GaitManagerNode(ControllerNode[GaitManagerParameters]):
    """The enabled gait-manager sources as a node."""

    parameter_class = GaitManagerParameters
    parameter_error = GaitManagerError
    law_errors = (GaitManagerError,)

    def __init__(self, **kwargs) -> None:
        super().__init__('gait_manager', **kwargs)
        if not self.params.enabled:
            self.get_logger().warning('no source enabled: the node stays idle')

    @property
    def active(self) -> bool:
        """Idle while no source is enabled."""
        return bool(self.params.enabled)

    def compute(self, obs: Observation) -> ControllerCommand:
        """The sum of the enabled sources at ``obs``, with each source's share."""
        return ControllerCommand.of(gait_manager_commands(obs, self.dynamics, self.params),
                                    obs.q, obs.v)


def main(args: list[str] | None = None) -> int:
    """Console entry point."""
    return run_node(GaitManagerNode, 'gait_manager', args)


if __name__ == '__main__':
    raise SystemExit(main())
