"""Scenes with their controllers: shipped names, the whole validation (the ``inputs`` blocks and
plug-ins too), each node's parameters (``node_parameters``) and sources (``scene_sources``).
See docs/architecture.md, 'Packages, bottom up'.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import is_dataclass, replace
import pathlib
from typing import Any

from gait_manager.parameters import GaitManagerParameters, head_stance
from iceskate_bringup.controllers import SHIPPED, kind_of
from iceskate_bringup.plugin import is_plugin
from iceskate_native.parameters import Rules, field_types, rules_of
from iceskate_sim.errors import InputRefused
from iceskate_sim.run.scene import Scene, SceneSettings, scene_steps
from iceskate_sim.run.scene import load_scene as load_scene_file
from iceskate_sim.run.scene import parse_scene as parse_simulator_scene
from visual_lifting.parameters import VisualLiftingParameters

#: A controller's parameters: a shipped one's parameter object or a plug-in's block
#: (``ControllerKind.parameters``).
ControllerParameters = Any


def validate_inputs(node: str, block: dict[str, Any]) -> None:
    """Check the parameter block of controller ``node`` (InputRefused naming the key)."""
    kind_of(node, block).check(node, block)


def controller_parameters(node: str, block: dict[str, Any]) -> ControllerParameters:
    """The validated parameters of controller ``node`` from its scene block (a plug-in's as
    given: its class is checked by ``validate_inputs`` and when it is built)."""
    return kind_of(node, block).parameters(node, block)


def node_parameters(scene: Scene) -> dict[str, ControllerParameters]:
    """The parameters of each controller node the scene runs, in the scene's order, composed:
    visual lifting's head target follows the gait manager's moving stance when both run
    (``head_stance``)."""
    params = {node: controller_parameters(node, block) for node, block in scene.inputs.items()}
    vl, gm = params.get('visual_lifting'), params.get('gait_manager')
    if isinstance(vl, VisualLiftingParameters) and isinstance(gm, GaitManagerParameters):
        stance = head_stance(gm)
        if stance is not None:
            params['visual_lifting'] = replace(vl, shift_y1=stance.dy1, shift_z1=stance.dz1,
                                               shift_time1=stance.t1, shift_y2=stance.dy2,
                                               shift_time2=stance.t2)
    return params


#: Names a controller node may not take: the simulator node's.
RESERVED_NODES = ('simulator',)
#: Source names the record keeps for itself: the scene's push.
RESERVED_SOURCES = ('push',)


def parse_scene(raw: Any) -> Scene:
    """Validate a whole scene mapping (simulator part, controller blocks, and that no two
    controllers' sources share a name: each is its own column of the record)."""
    scene = parse_simulator_scene(raw, validate_inputs)
    owner: dict[str, str] = {}
    for node, sources in scene_sources(scene).items():
        if node in RESERVED_NODES:
            raise InputRefused(f'scene key {f"inputs.{node}"!r}: {node!r} is the simulator '
                               "node's name; name the controller otherwise")
        for source in sources:
            if source in RESERVED_SOURCES or source in owner:
                other = ("the scene's push" if source in RESERVED_SOURCES
                         else f'inputs.{owner[source]}')
                raise InputRefused(f'scene key {f"inputs.{node}"!r}: its source {source!r} '
                                   f'is also a source of {other}; every source needs its '
                                   'own name')
            owner[source] = node
    return scene


def scene_sources(scene: Scene) -> dict[str, tuple[str, ...]]:
    """The scene's controller nodes, in summing order (the scene's), each with its command
    sources in order (an idle gait manager, with no source enabled, is left out)."""
    out: dict[str, tuple[str, ...]] = {}
    for node, block in scene.inputs.items():
        sources = kind_of(node, block).sources(node, controller_parameters(node, block))
        if sources:
            out[node] = sources
    return out


def key_rules(key: str) -> Rules | None:
    """The rules (description, unit, range) of scene key ``key`` (dotted, e.g. 'floor.mu' or
    'inputs.gait_manager.yaw.amplitude'), from the schema that declares it; None for a key no
    schema declares (a list entry, a plug-in's parameter)."""
    head, _, rest = key.partition('.')
    node, _, field = rest.partition('.')
    cls, names = ((SHIPPED[node].schema, field) if head == 'inputs' and node in SHIPPED
                  else (SceneSettings, key))
    *blocks, last = names.split('.')
    for name in blocks:
        cls = field_types(cls).get(name)
        if not is_dataclass(cls):
            return None
    return rules_of(cls).get(last)


def load_scene(name_or_path: str | pathlib.Path,
               overrides: Mapping[str, Any] | None = None) -> Scene:
    """Load a shipped scene by name or a scene YAML by path (with its base and ``overrides``,
    dotted key -> value: ``iceskate_sim.run.scene.scene_raw``), validated whole."""
    return load_scene_file(name_or_path, validate_inputs, overrides)


def controllers_line(scene: Scene, name_or_path: str | pathlib.Path,
                     overrides: Mapping[str, Any] | None = None) -> str:
    """What run_scene says at its start: the controllers ``scene`` (loaded from
    ``name_or_path`` with ``overrides``) runs, in summing order, each with where its block comes
    from (the scene that gave it, then those that changed it; 'this scene', a base as named,
    '--set'), and the controllers a scene removed, e.g. ``controllers: gait_manager (skate),
    knees (plugin my_pkg.knees:Knees, this scene); visual_lifting removed by this scene``."""
    steps = scene_steps(name_or_path, overrides)
    top = max(i for i, step in enumerate(steps) if step.name is not None)
    history: dict[str, list[str]] = {}  # node -> where its block comes from
    removed: dict[str, str] = {}  # node -> who removed it
    before: dict[str, Any] = {}
    for i, step in enumerate(steps):
        label = '--set' if step.name is None else 'this scene' if i == top else step.name
        own, after = (_inputs_of(keys) for keys in (step.keys, step.raw))
        for node, block in after.items():
            old = before.get(node)
            if block is None:
                if old is not None or node not in before:
                    removed[node] = f'removed by {label}'
            elif not isinstance(old, dict) or own.get(node) == block:
                history[node] = [label]
                removed.pop(node, None)
            elif block != old:
                history[node].append(f'changed by {label}')
        before = after
    running = scene_sources(scene)
    runs = []
    for node, block in scene.inputs.items():
        if node in running:
            where = [f'plugin {block["plugin"]}'] if is_plugin(block) else []
            runs.append(f'{node} ({", ".join(where + history[node])})')
    gone = [f'{node} {removed[node]}' for node, block in before.items()
            if block is None and node in removed]
    return f'controllers: {", ".join(runs) or "none"}' + (f'; {", ".join(gone)}' if gone else '')


def _inputs_of(raw: Mapping[str, Any]) -> dict[str, Any]:
    """The controller blocks of scene keys ``raw`` (none where ``inputs`` is no mapping)."""
    inputs = raw.get('inputs')
    return inputs if isinstance(inputs, dict) else {}
