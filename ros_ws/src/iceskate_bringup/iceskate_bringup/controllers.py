"""Every kind of controller a scene may run, registered the same way: ``SHIPPED`` maps the name a
scene gives a shipped controller (its ``inputs`` key, its node's name) to its ``ControllerKind``;
``PLUGIN`` is the kind of a controller written in Python (a block ``plugin: pkg.mod:Class``);
``kind_of`` gives the one a scene block names. Scenes (validation, sources, key rules), the
in-process stack (``composition``) and the node graph (``graph``) read only these; a new C++
controller is its package and one entry in ``SHIPPED``. See docs/architecture.md, 'The control
laws in C++'.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import json
from typing import Any

from gait_manager.errors import GaitManagerError
from gait_manager.native import GaitManagerController
from gait_manager.parameters import SOURCES, GaitManagerParameters
from iceskate_bringup.plugin import (
    PluginBlock,
    checked_block,
    is_plugin,
    make_controller,
    plugin_sources,
)
import iceskate_native
from iceskate_native.parameters import flatten
from iceskate_sim.errors import InputRefused
from visual_lifting.errors import VisualLiftingError
from visual_lifting.native import VisualLiftingController
from visual_lifting.parameters import VisualLiftingParameters


@dataclass(frozen=True)
class NodeKind:
    """The ROS node that runs a controller: its package, executable, module and class;
    ``renamed``: the node takes the controller's name (else the executable's, which is it)."""

    package: str
    executable: str
    module: str
    node_class: str
    renamed: bool = False


@dataclass(frozen=True)
class ControllerKind:
    """How scenes, the stack and the graph use one kind of controller; each callable takes the
    controller's name (its scene key) first.

    :param parameters: its parameters from its scene block, validated.
    :param check: refuses a bad scene block (InputRefused naming the key); what it checks
        beyond ``parameters`` (a plug-in's class is imported and built once).
    :param law: its law (an ``iceskate_native.Controller``) from its parameters.
    :param sources: its command sources from its parameters, in summing order (none: the
        controller does not run).
    :param node: its ROS node.
    :param ros_parameters: its node's parameters from its parameters.
    :param schema: its parameter class, whose rules describe its scene keys (None: none).
    :param in_python: its law runs Python (it takes the GIL once per period).
    :param start: what the law needs at the run's first observation (None: nothing), called
        with the law, that observation (native) and the laws' kinematics.
    """

    parameters: Callable[[str, dict[str, Any]], Any]
    check: Callable[[str, dict[str, Any]], Any]
    law: Callable[[str, Any], iceskate_native.Controller]
    sources: Callable[[str, Any], tuple[str, ...]]
    node: NodeKind
    ros_parameters: Callable[[Any], dict[str, Any]]
    schema: type | None = None
    in_python: bool = False
    start: Callable[[Any, iceskate_native.Observation, iceskate_native.Kinematics],
                    None] | None = None


def _shipped(name: str, schema: type, errors: tuple[type[Exception], ...],
             law: Callable[[Any], iceskate_native.Controller],
             sources: Callable[[Any], tuple[str, ...]], node_class: str,
             start: Callable[..., None] | None = None) -> ControllerKind:
    """The kind of a controller package ``name``: parameters of class ``schema`` (which raises
    ``errors`` for a bad value), its node ``<name>.<name>_node.<node_class>`` run as
    executable ``<name>`` of package ``<name>``."""

    def parameters(node: str, block: dict[str, Any]) -> Any:
        try:
            return schema.from_dict(block)
        except errors as exc:
            raise InputRefused(f'scene key {f"inputs.{node}"!r}: {exc}') from None

    return ControllerKind(parameters, parameters, lambda node, params: law(params),
                          lambda node, params: sources(params),
                          NodeKind(name, name, f'{name}.{name}_node', node_class), flatten,
                          schema, start=start)


def _latch_head_origin(law: VisualLiftingController, initial: iceskate_native.Observation,
                       kinematics: iceskate_native.Kinematics) -> None:
    law.latch_origin(initial, kinematics)  # psi(0), the origin of its head target


#: The shipped controllers by name; a scene's controllers are summed in the order it lists them.
SHIPPED = {
    'visual_lifting': _shipped(
        'visual_lifting', VisualLiftingParameters, (VisualLiftingError,),
        VisualLiftingController, lambda params: ('visual_lifting',), 'VisualLiftingNode',
        _latch_head_origin),
    'gait_manager': _shipped(
        'gait_manager', GaitManagerParameters, (GaitManagerError,), GaitManagerController,
        lambda params: tuple(s for s in SOURCES if s in params.enabled), 'GaitManagerNode'),
}

#: A controller written in Python: its class and the keyword arguments of its constructor as
#: the scene gives them (``PluginBlock``), run by ``iceskate_bringup.plugin_node`` under the
#: controller's name.
PLUGIN = ControllerKind(
    parameters=lambda node, block: PluginBlock(block['plugin'],
                                               dict(block.get('parameters') or {})),
    check=checked_block,
    law=make_controller,
    sources=lambda node, params: plugin_sources(node, make_controller(node, params)),
    node=NodeKind('iceskate_bringup', 'plugin_controller', 'iceskate_bringup.plugin_node',
                  'PluginControllerNode', renamed=True),
    ros_parameters=lambda params: {'plugin': params.plugin,
                                   'parameters': json.dumps(params.parameters)},
    in_python=True)


def kind_of(node: str, block: Any) -> ControllerKind:
    """The kind of controller scene block ``inputs.<node>`` names: a plug-in (a block with
    ``plugin``) or the shipped controller ``node``.

    :raises InputRefused: for a name no shipped controller has.
    """
    if is_plugin(block):
        return PLUGIN
    if node in SHIPPED:
        return SHIPPED[node]
    raise InputRefused(f'scene key {f"inputs.{node}"!r}: unknown controller; one of '
                       f"{list(SHIPPED)}, or a controller written in Python (a block "
                       "with 'plugin: package.module:Class')")
