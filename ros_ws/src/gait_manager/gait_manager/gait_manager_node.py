"""``ros2 run gait_manager gait_manager``: the gait-manager sources (``gait_manager.native``) as
one ROS node: ``gait_state`` in, one ``EffortCommand`` (source 'gait_manager') per instant out;
its parameters are ``GaitManagerParameters``' fields (``posture.stiffness``, ..., ``enabled``).
See docs/usage.md, 'Through ROS 2: the node graph, bags, replay, analysis'.
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
    return run_node(GaitManagerNode, 'gait_manager', 'gait_manager', args, __doc__,
                    GaitManagerParameters)


if __name__ == '__main__':
    raise SystemExit(main())
