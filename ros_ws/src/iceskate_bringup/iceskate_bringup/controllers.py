"""The shipped controllers, registered once: ``SHIPPED`` maps the name a scene gives a controller
(its ``inputs`` key, its node's name) to its ``ShippedController``: parameter class, native law,
command sources and ROS node. Scenes (validation, sources, key rules), the in-process stack
(``composition``) and the node graph (``graph``) read it; a new C++ controller is its package
and one entry here. See docs/architecture.md, 'The control laws in C++'.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from gait_manager.errors import GaitManagerError
from gait_manager.native import GaitManagerController
from gait_manager.parameters import SOURCES, GaitManagerParameters
import iceskate_native
from visual_lifting.errors import VisualLiftingError
from visual_lifting.native import VisualLiftingController
from visual_lifting.parameters import VisualLiftingParameters


@dataclass(frozen=True)
class ShippedController:
    """A controller package's law as scenes, the stack and the graph use it.

    :param parameters: its parameter class (``iceskate_native.parameters`` schema:
        ``from_dict``, typed ROS parameters).
    :param errors: what that class raises for a bad value.
    :param law: its native law from its parameters.
    :param sources: its command sources from its parameters, in summing order (none: the
        controller does not run).
    :param node_class: its ROS node's class, in ``<name>.<name>_node`` of package ``<name>``
        (executable ``<name>``).
    :param start: what the law needs at the run's first observation (None: nothing), called
        with the law, that observation (native) and the laws' kinematics.
    """

    parameters: type
    errors: tuple[type[Exception], ...]
    law: Callable[[Any], iceskate_native.Controller]
    sources: Callable[[Any], tuple[str, ...]]
    node_class: str
    start: Callable[[Any, iceskate_native.Observation, iceskate_native.Kinematics],
                    None] | None = None


def _latch_head_origin(law: VisualLiftingController, initial: iceskate_native.Observation,
                       kinematics: iceskate_native.Kinematics) -> None:
    law.latch_origin(initial, kinematics)  # psi(0), the origin of its head target


#: The shipped controllers by name; a scene's controllers are summed in the order it lists them.
SHIPPED = {
    'visual_lifting': ShippedController(
        VisualLiftingParameters, (VisualLiftingError,), VisualLiftingController,
        lambda params: ('visual_lifting',), 'VisualLiftingNode', _latch_head_origin),
    'gait_manager': ShippedController(
        GaitManagerParameters, (GaitManagerError,), GaitManagerController,
        lambda params: tuple(s for s in SOURCES if s in params.enabled), 'GaitManagerNode'),
}
