"""Controllers written in Python that a scene names (``inputs.<name>: {plugin: 'pkg.mod:Class',
parameters: {...}}``): ``PluginBlock``, ``make_controller``, ``PluginAdapter``.
See docs/usage.md, 'Your own controller'.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import importlib
import re
from typing import Any

import iceskate_native
from iceskate_sim.errors import InputRefused

#: The keys of a plug-in's scene block.
PLUGIN_KEYS = ('plugin', 'parameters')
_PATH = re.compile(r'^[A-Za-z_]\w*(\.[A-Za-z_]\w*)*:[A-Za-z_]\w*(\.[A-Za-z_]\w*)*$')
_NODE_NAME = re.compile(r'^[A-Za-z_]\w*$')


@dataclass(frozen=True)
class PluginBlock:
    """A plug-in controller of a scene: ``plugin`` 'package.module:Class' and the keyword
    arguments of its constructor (``parameters``, as the scene gives them)."""

    plugin: str
    parameters: dict[str, Any] = field(default_factory=dict)


def is_plugin(block: Any) -> bool:
    """Whether a scene's ``inputs`` block names a plug-in (it has the key ``plugin``)."""
    return isinstance(block, dict) and 'plugin' in block


def checked_block(node: str, block: dict[str, Any]) -> PluginBlock:
    """The checked ``PluginBlock`` of scene block ``inputs.<node>`` (its class is importable and
    takes the parameters)."""
    key = f'inputs.{node}'
    if not _NODE_NAME.match(node):
        raise InputRefused(f'scene key {key!r}: a controller name must be a ROS node name '
                           '(letters, digits and _, not starting with a digit)')
    unknown = sorted(set(block) - set(PLUGIN_KEYS))
    if unknown:
        raise InputRefused(f'scene key {f"{key}.{unknown[0]}"!r}: unknown key; allowed: '
                           f'{list(PLUGIN_KEYS)}')
    parameters = block.get('parameters') or {}
    if not isinstance(parameters, dict):
        raise InputRefused(f'scene key {f"{key}.parameters"!r}: must be a mapping, got '
                           f'{type(parameters).__name__}')
    plugin = PluginBlock(block['plugin'], dict(parameters))
    make_controller(node, plugin)  # the class exists and takes the parameters
    return plugin


def plugin_class(path: Any, key: str = 'plugin') -> type:
    """The class 'package.module:Class' names (an InputRefused naming ``key`` otherwise)."""
    where = f'scene key {key!r}'
    if not isinstance(path, str) or not _PATH.match(path):
        raise InputRefused(f"{where}: must be 'package.module:Class', got {path!r}")
    module_name, _, qualname = path.partition(':')
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        raise InputRefused(f'{where}: no module {exc.name!r} to import {module_name!r} '
                           '(is its package on PYTHONPATH?)') from None
    except Exception as exc:  # noqa: BLE001 - the module's own error, in one sentence
        raise InputRefused(f'{where}: importing {module_name!r} failed: '
                           f'{type(exc).__name__}: {exc}') from None
    target: Any = module
    for part in qualname.split('.'):
        target = getattr(target, part, None)
        if target is None:
            raise InputRefused(f'{where}: module {module_name!r} has no {qualname!r}')
    if not isinstance(target, type) or not callable(getattr(target, 'compute', None)):
        raise InputRefused(f'{where}: {path!r} is not a controller class (a subclass of '
                           'iceskate_native.Controller, or a class with compute(obs, '
                           'kinematics))')
    return target


class PluginAdapter(iceskate_native.Controller):
    """A plain Python object with ``compute(obs, kinematics)`` (and maybe ``sources``) as an
    ``iceskate_native.Controller``."""

    def __init__(self, law: Any) -> None:
        super().__init__()
        self.law = law
        self.sources = getattr(law, 'sources', None)

    def compute(self, obs: iceskate_native.Observation,
                kinematics: iceskate_native.Kinematics) -> Any:
        """The wrapped object's answer."""
        return self.law.compute(obs, kinematics)


def make_controller(node: str, plugin: PluginBlock) -> iceskate_native.Controller:
    """A new instance of the plug-in of scene block ``inputs.<node>``, named ``node``."""
    key = f'inputs.{node}'
    cls = plugin_class(plugin.plugin, f'{key}.plugin')
    try:
        law = cls(**plugin.parameters)
    except (TypeError, ValueError) as exc:  # an unknown keyword, a value the class refuses
        raise InputRefused(f'scene key {f"{key}.parameters"!r}: {exc}') from None
    except Exception as exc:  # noqa: BLE001 - the class's own error, in one sentence
        raise InputRefused(f'scene key {f"{key}.parameters"!r}: {plugin.plugin} failed: '
                           f'{type(exc).__name__}: {exc}') from None
    controller = law if isinstance(law, iceskate_native.Controller) else PluginAdapter(law)
    try:
        controller.name = node
    except AttributeError:
        raise InputRefused(f'scene key {key!r}: {plugin.plugin} does not take the attribute '
                           "'name' (the controller's name)") from None
    plugin_sources(node, controller)
    return controller


def plugin_sources(node: str, controller: Any) -> tuple[str, ...]:
    """The source names of a plug-in controller: its ``sources``, else its name."""
    sources = getattr(controller, 'sources', None)
    if sources is None:
        return (node,)
    if (isinstance(sources, str) or not isinstance(sources, (tuple, list)) or not sources
            or not all(isinstance(s, str) and s for s in sources)
            or len(set(sources)) != len(sources)):
        raise InputRefused(f'scene key {f"inputs.{node}"!r}: the controller\'s sources '
                           f'must be distinct non-empty names, got {sources!r}')
    return tuple(sources)
