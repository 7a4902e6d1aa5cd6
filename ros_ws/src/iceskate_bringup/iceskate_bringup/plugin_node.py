"""``plugin_controller``: a controller written in Python (``iceskate_bringup.plugin``) as a ROS
node, named with ``-r __node:=NAME``; its parameters ``plugin`` ('package.module:Class') and
``parameters`` (the class's keyword arguments, a JSON mapping). See docs/usage.md, 'Your own
controller'.
"""

from __future__ import annotations

from dataclasses import dataclass
import json
import sys
from typing import Any

from iceskate_bringup.plugin import PluginBlock, make_controller
import iceskate_native
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import CommandValues
from iceskate_sim.parameters import check_fields, setting
from iceskate_sim.physics.native_control import native_values
from iceskate_sim.ros.controller_node import ControllerNode
from iceskate_sim.ros.node_support import run_node

#: The node's name unless remapped (``-r __node:=NAME``).
DEFAULT_NAME = 'plugin_controller'


@dataclass(frozen=True)
class PluginNodeParameters:
    """The parameters of a plug-in controller node."""

    plugin: str = setting('', "the controller class, 'package.module:Class'")
    parameters: str = setting('{}', "the class's keyword arguments, a JSON mapping")

    def __post_init__(self) -> None:
        """Check the types (SimulationError naming the field)."""
        check_fields(self, SimulationError)

    def block(self) -> PluginBlock:
        """The plug-in these parameters name (SimulationError if ``parameters`` is no JSON
        mapping)."""
        try:
            parameters = json.loads(self.parameters)
        except ValueError as exc:
            raise SimulationError(f'parameters is no JSON mapping: {exc}') from None
        if not isinstance(parameters, dict):
            raise SimulationError(f'parameters must be a JSON mapping, got '
                                  f'{type(parameters).__name__}')
        return PluginBlock(self.plugin, parameters)


def node_name(args: list[str] | None) -> str:
    """The node's name from a ``__node:=NAME`` remapping in ``args`` (else DEFAULT_NAME)."""
    for arg in args or ():
        if arg.startswith('__node:='):
            return arg.removeprefix('__node:=')
    return DEFAULT_NAME


class PluginControllerNode(ControllerNode[PluginNodeParameters]):
    """A plug-in controller as a node."""

    parameter_class = PluginNodeParameters
    parameter_error = SimulationError
    law_errors = (iceskate_native.ControllerError,)

    def __init__(self, name: str | None = None, **kwargs: Any) -> None:
        super().__init__(name or node_name(kwargs.get('cli_args')), **kwargs)
        self.controller = make_controller(self.get_name(), self.params.block())

    def _on_parameters(self, params: PluginNodeParameters) -> None:
        """A new instance of the controller the parameters name, from the next state on."""
        try:
            controller = make_controller(self.get_name(), params.block())
        except SimulationError as exc:
            self.get_logger().error(f'parameters not applied: {exc}')
            return
        super()._on_parameters(params)
        self.controller = controller

    def compute(self, obs: iceskate_native.Observation) -> CommandValues:
        """The controller's checked answer at ``obs``."""
        return native_values(self.controller, obs, self.kinematics)


def main(args: list[str] | None = None) -> int:
    """Console entry point."""
    name = node_name(sys.argv if args is None else args)
    return run_node(lambda: PluginControllerNode(name), name, args, __doc__,
                    PluginNodeParameters)


if __name__ == '__main__':
    raise SystemExit(main())
