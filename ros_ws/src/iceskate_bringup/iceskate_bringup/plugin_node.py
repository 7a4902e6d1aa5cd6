"""``plugin_controller``: a controller written in Python (``iceskate_bringup.plugin``) as a ROS
node, named with ``-r __node:=NAME``; its parameters ``plugin`` ('package.module:Class'),
``parameters`` (the class's keyword arguments, a JSON mapping) and one parameter per keyword
argument of the class (``-p gain:=2.0``; typed as its default, and winning over ``parameters``).
See docs/usage.md, 'Your own controller'.
"""

from __future__ import annotations

import array
from dataclasses import dataclass
import inspect
import json
import sys
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, ParameterException
from rclpy.parameter import Parameter

from iceskate_bringup.plugin import PluginBlock, make_controller, plugin_class
import iceskate_native
from iceskate_native.parameters import check_fields, setting
from iceskate_sim.errors import InputRefused, SimulationError
from iceskate_sim.model.command import CommandValues
from iceskate_sim.physics.native_control import native_values
from iceskate_sim.ros.controller_node import ControllerNode
from iceskate_sim.ros.node_support import ConfigError, run_node

#: The node's name unless remapped (``-r __node:=NAME``).
DEFAULT_NAME = 'plugin_controller'
#: The node's own parameters: a keyword argument of that name is given through ``parameters``.
OWN_PARAMETERS = ('plugin', 'parameters', 'run_token', 'use_sim_time')


@dataclass(frozen=True)
class PluginNodeParameters:
    """The parameters of a plug-in controller node."""

    plugin: str = setting('', "the controller class, 'package.module:Class'")
    parameters: str = setting('{}', "the class's keyword arguments, a JSON mapping (a keyword's "
                              'own parameter wins)')

    def __post_init__(self) -> None:
        """Check the types (InputRefused naming the field)."""
        check_fields(self, InputRefused)

    def block(self) -> PluginBlock:
        """The plug-in these parameters name (InputRefused if ``parameters`` is no JSON
        mapping)."""
        try:
            parameters = json.loads(self.parameters)
        except ValueError as exc:
            raise InputRefused(f'parameters is no JSON mapping: {exc}') from None
        if not isinstance(parameters, dict):
            raise InputRefused(f'parameters must be a JSON mapping, got '
                               f'{type(parameters).__name__}')
        return PluginBlock(self.plugin, parameters)


def keyword_defaults(cls: type) -> dict[str, Any]:
    """The keyword arguments of ``cls``'s constructor with their defaults
    (``inspect.Parameter.empty``: none), but for the node's own parameter names."""
    try:
        signature = inspect.signature(cls)
    except (TypeError, ValueError):  # no Python constructor (e.g. Controller's own)
        return {}
    return {p.name: p.default for p in signature.parameters.values()
            if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
            and p.name not in OWN_PARAMETERS}


def ros_value(value: Any) -> Any:
    """``value`` as a typed ROS parameter value (a sequence as a list, ints among floats as
    floats), or None if ROS has no type for it."""
    if type(value) in (bool, int, float, str):
        return value
    if isinstance(value, (tuple, list)) and value:
        kinds = {type(v) for v in value}
        if len(kinds) == 1 and kinds <= {bool, int, float, str}:
            return list(value)
        if kinds == {int, float}:
            return [float(v) for v in value]
    return None


def _python(value: Any) -> Any:
    """A parameter value as the plug-in takes it (an array as a list)."""
    return list(value) if isinstance(value, array.array) else value


def node_name(args: list[str] | None) -> str:
    """The node's name from a ``__node:=NAME`` remapping in ``args`` (else DEFAULT_NAME)."""
    for arg in args or ():
        if arg.startswith('__node:='):
            return arg.removeprefix('__node:=')
    return DEFAULT_NAME


class PluginControllerNode(ControllerNode[PluginNodeParameters]):
    """A plug-in controller as a node."""

    parameter_class = PluginNodeParameters
    parameter_error = InputRefused
    law_errors = (iceskate_native.ControllerError,)

    def __init__(self, name: str | None = None, **kwargs: Any) -> None:
        self._keywords: set[str] = set()  # the class's keyword arguments, as parameters
        self._given: set[str] = set()  # those given (-p, a params file, a set): they win
        super().__init__(name or node_name(kwargs.get('cli_args')), **kwargs)
        block = self._block(self.params)
        self.controller = make_controller(self.get_name(), block)
        self.get_logger().info(f'controller {block.plugin} with {block.parameters}')

    def declare_more_parameters(self) -> None:
        """One ROS parameter per keyword argument of the plug-in class: typed as its default,
        or of any type and unset if it has none ROS can hold."""
        cls = plugin_class(self.params.plugin, f'inputs.{self.get_name()}.plugin')
        for keyword, default in keyword_defaults(cls).items():
            value = None if default is inspect.Parameter.empty else ros_value(default)
            text = f'keyword argument {keyword!r} of {cls.__name__}' + (
                '' if default is inspect.Parameter.empty else f' (default {default!r})')
            try:
                self.declare_parameter(keyword, value, ParameterDescriptor(
                    description=text, dynamic_typing=value is None))
            except InvalidParameterTypeException:  # e.g. an integer where a float is due
                kind = Parameter.Type.from_parameter_value(value).name
                hint = '; write 2.0, not 2' if kind.startswith('DOUBLE') else ''
                raise ConfigError(f'parameter {keyword!r} must be of type {kind}, as its default '
                                  f'{default!r} is{hint}') from None
            except ParameterException as exc:
                raise ConfigError(f'parameter {keyword!r}: {exc}') from None
            self._keywords.add(keyword)
        self._given = self._keywords & set(getattr(self, '_parameter_overrides', {}))
        self.add_on_set_parameters_callback(self._on_keywords)

    def _block(self, params: PluginNodeParameters, changes: dict[str, Any] | None = None
               ) -> PluginBlock:
        """The plug-in of ``params``: the keyword arguments of its ``parameters`` and, over
        them, the keyword parameters given (and ``changes``)."""
        block = params.block()
        given = {k: _python(self.get_parameter(k).value) for k in sorted(self._given)}
        return PluginBlock(block.plugin, block.parameters | given | (changes or {}))

    def _on_keywords(self, changes: list[Parameter]) -> SetParametersResult:
        """A new instance for new keyword parameters (``ros2 param set``), from the next state
        on; refused with the class's reason if it cannot be built."""
        ours = {p.name: _python(p.value) for p in changes if p.name in self._keywords}
        if not ours:
            return SetParametersResult(successful=True)
        try:
            controller = make_controller(self.get_name(), self._block(self.params, ours))
        except SimulationError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self._given |= set(ours)
        self.controller = controller
        self.get_logger().info('parameters changed')
        return SetParametersResult(successful=True)

    def _on_parameters(self, params: PluginNodeParameters) -> None:
        """A new instance of the controller the parameters name, from the next state on."""
        try:
            controller = make_controller(self.get_name(), self._block(params))
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
    return run_node(lambda: PluginControllerNode(name), 'iceskate_bringup', name, args, __doc__,
                    PluginNodeParameters)


if __name__ == '__main__':
    raise SystemExit(main())
