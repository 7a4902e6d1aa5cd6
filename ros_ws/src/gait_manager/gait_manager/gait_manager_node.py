"""``ros2 run gait_manager gait_manager``: the gait-manager sources as one ROS node.

Subscribes ``gait_state`` (the hybrid state), publishes per instant one ``EffortCommand``
(source 'gait_manager') on ``effort_commands``, stamped with the state's time: the sum of its
enabled sources ('posture', 'feedforward', 'weight_transfer', 'heel', 'arm_assist', 'yaw'; the
posture command carries the joint impedance) and each source's share (``source_names``).
Its parameters are the scene's ``inputs.gait_manager`` block (parameter ``scene``).
"""

from __future__ import annotations

from gait_manager.errors import GaitManagerError
from gait_manager.law import GaitManagerParameters, gait_manager_commands
from iceskate_sim.command import JointCommand
from iceskate_sim.controller_node import ControllerNode
from iceskate_sim.node_support import run_node
from iceskate_sim.observation import Observation
from iceskate_sim.scene import Scene


class GaitManagerNode(ControllerNode):
    """The gait-manager sources a scene enables."""

    law_errors = (GaitManagerError,)

    def __init__(self, **kwargs) -> None:
        self.params: GaitManagerParameters | None = None
        super().__init__('gait_manager', **kwargs)

    def configure(self, scene: Scene) -> bool:
        """Law parameters from the scene (validated when the scene was loaded)."""
        if scene.gait_manager is None:
            return False
        self.params = GaitManagerParameters.from_dict(scene.gait_manager or {})
        return bool(self.params.enabled)

    def compute(self, obs: Observation) -> dict[str, JointCommand]:
        """One command per enabled source at ``obs``."""
        return gait_manager_commands(obs, self.dynamics, self.params)


def main(args: list[str] | None = None) -> int:
    """Console entry point."""
    return run_node(GaitManagerNode, 'gait_manager', args)


if __name__ == '__main__':
    raise SystemExit(main())
