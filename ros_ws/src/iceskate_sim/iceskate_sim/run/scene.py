"""Scenes: one YAML file per experiment, validated once before the run (the simulator's part;
the controllers' blocks by ``parse_scene``'s ``validate_inputs``), a bad key refused with an
``InputRefused`` naming it (e.g. ``integrator.step``). A scene is named by its path or, for
those a package ships (``share/<package>/scenes/<name>.yaml``, the package registered under the
ament index's ``iceskate_scenes``), by its name. See docs/usage.md, 'Run a scene'.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
import copy
from dataclasses import MISSING, dataclass, field, make_dataclass
import math
import pathlib
import re
from typing import Any, NamedTuple

import numpy as np

from iceskate_native.parameters import block, checked, keyed_from_mapping, setting
from iceskate_sim.errors import InputRefused, SimulationError
from iceskate_sim.installed import shipped_or_path
from iceskate_sim.model.dynamics import DynamicsParameters
from iceskate_sim.model.robot import COORDINATE_NAMES, LINK_NAMES, N_COORDINATES, SIDES
from iceskate_sim.physics.hybrid import FrictionModel, HybridState
from iceskate_sim.physics.integrators import IntegratorConfig
from iceskate_sim.physics.simulation import SimulatorConfig, initial_state
from iceskate_sim.yaml_io import read_yaml  # scenes are read by it (and it is found here too)

POSTURES = ('bent_knees', 'staggered', 'upright')
#: The longest run [s] a scene (or ``run_scene --duration``) may ask for.
MAX_DURATION = 3600.0
#: The ament index resource of the packages that ship scenes.
SCENE_RESOURCE = 'iceskate_scenes'


@dataclass(frozen=True)
class Push:
    """A constant external force on a link frame over a time window.

    :param start: start time [s]. :param duration: length [s].
    :param frame: anatomical link frame (e.g. 'chest'). :param force: world force [N] (3,).
    """

    start: float
    duration: float
    frame: str
    force: tuple[float, float, float]

    def active(self, t: float) -> bool:
        """Whether the push acts at time t (start <= t < start + duration)."""
        return self.start <= t < self.start + self.duration


@dataclass(frozen=True)
class Scene:
    """A validated scene."""

    name: str
    description: str
    duration: float  # s
    simulator: SimulatorConfig
    initial: HybridState
    #: parameter block of each controller node the scene runs, by node name, in file order
    inputs: dict[str, dict[str, Any]]
    pushes: tuple[Push, ...] = ()
    record_bag: bool = True
    #: control periods per recorded sample (trajectory and bag; ``record.rate`` in the file)
    record_every: int = 1
    #: recorded samples per sample of the bag (``record.bag_rate`` in the file)
    bag_every: int = 1
    #: samples of the bag per /tf message (``record.tf_rate`` in the file)
    tf_every: int = 1
    raw: dict[str, Any] = field(default_factory=dict, repr=False)


# ------------------------------------------------------------------- the scene's schema
# Every key of a scene's simulator part is a ``setting`` of these classes or of the run's own
# configurations (``FrictionModel``, ``IntegratorConfig``, ``DynamicsParameters``; the parameter
# schema of the project, ``iceskate_native.parameters``): its default, description, unit and rules.
_checked = checked(InputRefused)


#: ``initial.q`` and ``initial.v``: a value per coordinate name (m, rad; m/s, rad/s), each
#: optional (unset: the posture's).
CoordinateSettings = make_dataclass(
    'CoordinateSettings',
    [(name, float | None, setting(None, f'{name} of the initial state')) for name in
     COORDINATE_NAMES], frozen=True, namespace={'__post_init__': _checked})


@dataclass(frozen=True)
class InitialSettings:
    """``initial``: the initial mode, support, posture and coordinates."""

    mode: int = setting(17, 'Table 2 mode', low=1, high=20)
    support: str = setting('right', 'support foot', choices=SIDES)
    posture: str = setting('bent_knees', 'standing posture the coordinates start from',
                           choices=POSTURES)
    knee_bend: float = setting(0.05, "knee bend of 'bent_knees'", unit='rad', low=0.0, high=0.6)
    stagger: float = setting(0.25, "distance of the feet of 'staggered'", unit='m', low=0.0,
                             high=0.8)
    q: CoordinateSettings = block(CoordinateSettings, 'coordinates set by name')
    v: CoordinateSettings = block(CoordinateSettings, 'velocities set by name')
    __post_init__ = _checked


@dataclass(frozen=True, kw_only=True)
class PushSettings:
    """An entry of ``disturbances``: a constant force on a link over a time window."""

    start: float = setting(MISSING, 'start time', unit='s', low=0.0)
    duration: float = setting(MISSING, 'length', unit='s', low=0.0, open_low=True)
    frame: str = setting(MISSING, 'anatomical link frame', choices=LINK_NAMES)
    force: tuple[float, float, float] = setting(MISSING, 'world force', unit='N')
    __post_init__ = _checked


#: The bag's default sample rate [1/s]: a quarter of a 1 kHz run's samples, every one exact, so
#: a 15 s run writes under 20 MB; the analyses' per-interval averages span 4 ms (docs/usage.md,
#: "Run a scene").
BAG_RATE = 250.0
#: The bag's default /tf rate [1/s]: smooth in Foxglove and RViz (they draw at 60 Hz); /tf at
#: every sample would be 40 % of the bag (docs/usage.md, "Run a scene").
TF_RATE = 100.0


@dataclass(frozen=True)
class RecordSettings:
    """``record``: the bag, the record rate, the bag's rate and its /tf rate."""

    bag: bool = setting(True, 'record an MCAP bag')
    rate: float | None = setting(None, 'samples recorded per second, a divisor of the control '
                                 'rate (unset: every period)', unit='1/s', low=0.0,
                                 open_low=True)
    bag_rate: float | None = setting(BAG_RATE, "the bag's samples per second, at least: every "
                                     'n-th recorded sample, the largest n that gives this rate '
                                     '(null: every recorded sample)', unit='1/s', low=0.0,
                                     open_low=True)
    tf_rate: float | None = setting(TF_RATE, "the bag's /tf messages per second, at least: "
                                    'every n-th sample of the bag, the largest n that gives this '
                                    'rate (null: every one)', unit='1/s', low=0.0,
                                    open_low=True)
    __post_init__ = _checked


@dataclass(frozen=True, kw_only=True)
class SceneSettings:
    """A scene file's top level: the simulator's keys and blocks, the controllers' blocks
    (``inputs``, validated by the layer that composes the controllers) and the pushes."""

    scene: str = setting(MISSING, 'name of the scene')
    description: str = setting('', 'what the scene is for')
    duration: float = setting(MISSING, 'run length', unit='s', low=0.0, open_low=True,
                              high=MAX_DURATION)
    control_period: float = setting(MISSING, 'period of the controllers (zero-order hold)',
                                    unit='s', low=0.0, open_low=True, high=0.1)
    fall_height: float = setting(1.2, 'head-top height below which the robot has fallen',
                                 unit='m', low=0.0, high=1.7)
    floor: FrictionModel = block(FrictionModel, 'floor friction')
    initial: InitialSettings = block(InitialSettings, 'initial state')
    integrator: IntegratorConfig = block(IntegratorConfig, 'integrator')
    dynamics: DynamicsParameters = block(DynamicsParameters, 'contact and joint model')
    record: RecordSettings = block(RecordSettings, 'what is recorded')
    inputs: Any = setting(MISSING, 'parameter block of each controller node, by node name')
    disturbances: Any = setting(None, 'pushes: a list of PushSettings mappings')
    __post_init__ = _checked


def _fail(key: str, message: str) -> InputRefused:
    return InputRefused(f'scene key {key!r}: {message}')


# ----------------------------------------------------------------------- postures
def standing_posture(kind: str, knee_bend: float, stagger: float) -> tuple[np.ndarray, str]:
    """Initial coordinates of a double-support posture and the pivot to use.

    * 'bent_knees' (default, docs/model.md §12): feet side by side, q2..q7 = (-a, 2a, -a, a,
      -2a, a): both soles flat, the pelvis level, not singular.
    * 'staggered' (docs/model.md §12): support (front) foot ``stagger`` m ahead of the swing foot,
      straight legs.
    * 'upright': all zero (singular in double support, docs/model.md §4.5; single support only).
    """
    q = np.zeros(N_COORDINATES)
    if kind == 'bent_knees':
        a = knee_bend
        q[2:8] = [-a, 2 * a, -a, a, -2 * a, a]
    elif kind == 'staggered':
        alpha = math.asin((stagger / 2.0) / 0.78)
        q[2:8] = [alpha, 0.0, -alpha, -alpha, 0.0, alpha]
    return q, 'toe'


# ----------------------------------------------------------------------- loading
def parse_scene(raw: Any, validate_inputs: Callable[[str, dict[str, Any]], None] | None = None
                ) -> Scene:
    """Validate a scene mapping and build a Scene; raise InputRefused naming the key.

    :param validate_inputs: ``validate_inputs(node, block)`` checks the parameter block of one
        controller node (raising InputRefused naming the key); None: blocks are taken as
        given (the simulator needs only their node names).
    """
    if not isinstance(raw, dict):
        raise InputRefused(f'a scene must be a mapping of keys, got {type(raw).__name__}')
    if 'engine' in raw:  # a scene written for the Python engine, which is gone
        raise _fail('engine', 'the physics always runs on the native core now; remove the key')
    if isinstance(raw.get('dynamics'), dict) and 'mu' in raw['dynamics']:
        raise _fail('dynamics.mu', "the friction coefficient is the floor's: set floor.mu")
    top = keyed_from_mapping(SceneSettings, raw, SimulationError, _fail)
    if not top.scene:
        raise _fail('scene', f'must be a non-empty name, got {top.scene!r}')
    init = top.initial
    try:
        simulator = SimulatorConfig(control_period=top.control_period,
                                    integrator=top.integrator, friction=top.floor,
                                    dynamics=top.dynamics, fall_height=top.fall_height)
    except SimulationError as exc:
        raise _fail('control_period', str(exc)) from None

    q, pivot = standing_posture(init.posture, init.knee_bend, init.stagger)
    v = np.zeros(N_COORDINATES)
    for values, given in ((q, init.q), (v, init.v)):
        for i, name in enumerate(COORDINATE_NAMES):
            if getattr(given, name) is not None:
                values[i] = getattr(given, name)
    mode = init.mode
    initial = initial_state(q, mode, init.support, pivot, v)
    if 1 not in initial.mode.active and q[1] != 0.0:  # the sole is flat: q1 is not free
        raise _fail('initial.q.q1', f'q1 (the support sole on its edge) is not a coordinate of '
                    f'mode {mode}, whose support sole is flat; leave it out or start in a mode '
                    'with the sole on its toe or heel')
    locked = [i for i in (0, 1) if i not in initial.mode.active and v[i] != 0.0]
    if locked:
        name = COORDINATE_NAMES[locked[0]]
        raise _fail(f'initial.v.{name}', f'{name} is not a coordinate of mode {mode}; its '
                    'velocity must be 0')

    if not isinstance(top.inputs, dict):
        raise _fail('inputs', f'must be a mapping, got {type(top.inputs).__name__}')
    inputs: dict[str, dict[str, Any]] = {}
    for node, block_ in top.inputs.items():
        if block_ is None:  # not run (a base's controller removed)
            continue
        if not isinstance(block_, dict):
            raise _fail(f'inputs.{node}', f'must be a mapping, got {type(block_).__name__}')
        if validate_inputs is not None:
            validate_inputs(str(node), block_)
        inputs[str(node)] = block_

    items = top.disturbances or []
    if not isinstance(items, list):
        raise _fail('disturbances', f'must be a list, got {type(items).__name__}')
    pushes = tuple(Push(p.start, p.duration, p.frame, p.force) for p in (
        keyed_from_mapping(PushSettings, item, SimulationError, _fail, f'disturbances[{k}]')
        for k, item in enumerate(items)))
    record_every = _record_every(top.record.rate, simulator.control_period)
    record_rate = 1.0 / (simulator.control_period * record_every)
    bag_every = _thinned(record_rate, top.record.bag_rate)
    tf_every = _thinned(record_rate / bag_every, top.record.tf_rate)
    return Scene(top.scene, top.description, top.duration, simulator, initial, inputs, pushes,
                 top.record.bag, record_every, bag_every, tf_every, raw)


def _thinned(rate: float, at_least: float | None) -> int:
    """The largest n such that every n-th of samples at ``rate`` [1/s] comes at least
    ``at_least`` [1/s] times a second (None: 1, every sample)."""
    return 1 if at_least is None else max(1, int(rate / at_least * (1.0 + 1e-9)))


def _record_every(rate: float | None, control_period: float) -> int:
    """Control periods per recorded sample from ``record.rate`` [samples/s], which must divide
    the control rate (None: the control rate, every period)."""
    control_rate = 1.0 / control_period
    if rate is None:
        return 1
    every = round(control_rate / rate)
    if every < 1 or abs(every * rate - control_rate) > 1e-9 * control_rate:
        raise _fail('record.rate', f'{rate:g} samples/s does not divide the control rate '
                    f'{control_rate:g} Hz (e.g. {control_rate:g}, {control_rate / 2:g}, '
                    f'{control_rate / 10:g})')
    return every


def scene_path(name_or_path: str | pathlib.Path) -> pathlib.Path:
    """The YAML file of a shipped scene name (e.g. 'skate'), or the path itself.

    :raises InputRefused: for a name no package ships, listing those shipped.
    """
    return shipped_or_path(name_or_path, SCENE_RESOURCE, 'scenes', 'scene')


_NAME = r'[A-Za-z_][A-Za-z0-9_]*'
_KEY = re.compile(rf'{_NAME}(?:\[\d+\])*(?:\.{_NAME}(?:\[\d+\])*)*')
_TOKEN = re.compile(rf'({_NAME})|\[(\d+)\]')


def key_tokens(key: str) -> list[str | int]:
    """The names and list indices of a dotted scene key (``a.b[2].c`` -> a, b, 2, c).

    :raises InputRefused: for text that is no dotted key.
    """
    if not isinstance(key, str) or not _KEY.fullmatch(key):
        raise InputRefused(f'{key!r} is not a dotted scene key (e.g. floor.mu, '
                           'inputs.visual_lifting.kp[1], disturbances[0].force[1])')
    return [name if name else int(index) for name, index in _TOKEN.findall(key)]


def set_key(raw: dict[str, Any], key: str, value: Any) -> None:
    """Set scene key ``key`` of mapping ``raw`` to ``value``; a missing mapping on the way is
    made (the scene's validation judges the key), a list entry must exist.

    :raises InputRefused: for a bad key or a path the scene's shape does not have.
    """
    tokens = key_tokens(key)
    node: Any = raw
    for depth, token in enumerate(tokens):
        last = depth == len(tokens) - 1
        done = ''.join(f'[{t}]' if isinstance(t, int) else f'.{t}' for t in tokens[:depth])
        done = done.lstrip('.')
        if isinstance(token, int):
            if not isinstance(node, list):
                raise InputRefused(f'{done} is not a list in the scene; give it whole in '
                                   'overrides first')
            if token >= len(node):
                raise InputRefused(f'{done} has {len(node)} entries in the scene, no '
                                   f'[{token}]')
        elif not isinstance(node, dict):
            raise InputRefused(f'{done} is not a mapping in the scene')
        elif not last and node.get(token) is None:
            if isinstance(tokens[depth + 1], int):
                raise InputRefused(f'{done + "." if done else ""}{token} is not in the '
                                   'scene; give the whole list in overrides first')
            node[token] = {}
        if last:
            node[token] = value
        else:
            node = node[token]


def _merged(base: Any, child: Any, path: tuple[Any, ...] = ()) -> Any:
    """``child`` over ``base`` (at scene key ``path``): mappings key by key, anything else
    replaced whole, and so is a controller block that names its plug-in (``inputs.<name>`` with
    ``plugin``): nothing of the base's block of that name is kept. A null block stays null: the
    controller is removed (``parse_scene`` leaves it out)."""
    if (not (isinstance(base, dict) and isinstance(child, dict))
            or (len(path) == 2 and path[0] == 'inputs' and 'plugin' in child)):
        return copy.deepcopy(child)
    out = copy.deepcopy(base)
    for key, value in child.items():
        out[key] = _merged(base.get(key), value, (*path, key))
    return out


class SceneStep(NamedTuple):
    """A step of a scene's composition (``scene_steps``)."""

    #: the file as named (the scene's name or path as given; a base as the file above names it);
    #: None for the overrides
    name: str | None
    #: what the step gives: the file's own keys (without ``base``), or the overrides
    keys: dict[str, Any]
    #: the scene's keys after the step
    raw: dict[str, Any]


def _scene_files(name_or_path: str | pathlib.Path, name: str,
                 seen: tuple[pathlib.Path, ...] = ()) -> list[tuple[str, dict[str, Any]]]:
    """The files a scene is made of, its deepest base first: how each is named, its own keys.

    :raises InputRefused: for an unreadable file, a file that is no mapping, a base that is
        no scene or names itself in a chain.
    """
    path = scene_path(name_or_path)
    raw = read_yaml(path, 'scene')
    if not isinstance(raw, dict):
        raise InputRefused(f'a scene must be a mapping of keys, got {type(raw).__name__} '
                           f'({path})')
    if 'base' not in raw:
        return [(name, raw)]
    base = raw.pop('base')
    if not isinstance(base, str) or not base:
        raise InputRefused(f'scene {path}: base must be a shipped scene name or the path of '
                           f'a scene file, got {base!r}')
    relative = path.parent / base
    base_file = scene_path(relative if pathlib.Path(base).suffix and relative.is_file() else base)
    if base_file.resolve() in (*seen, path.resolve()):
        raise InputRefused(f'scene {path}: its base {base!r} leads back to itself')
    return [*_scene_files(base_file, base, (*seen, path.resolve())), (name, raw)]


def scene_steps(name_or_path: str | pathlib.Path,
                overrides: Mapping[str, Any] | None = None) -> list[SceneStep]:
    """How the keys of a scene are composed: each file's over those of the scene its ``base``
    names (a shipped name, or a path relative to the file), deepest base first, mappings merged
    key by key and anything else replaced whole (``_merged``: a controller block that names its
    ``plugin`` replaces the base's whole, a null one removes it), then ``overrides`` (dotted
    key -> value, ``set_key``; a last step when given).

    :raises InputRefused: for an unreadable file, a base that is no scene or names itself in
        a chain, a null controller block in a file whose base runs no controller of that name,
        or a bad override.
    """
    steps: list[SceneStep] = []
    raw: dict[str, Any] = {}
    for name, keys in _scene_files(name_or_path, str(name_or_path)):
        inputs, had = keys.get('inputs'), raw.get('inputs')
        for node, block_ in (inputs.items() if isinstance(inputs, dict) and steps else ()):
            if block_ is None and (not isinstance(had, dict) or had.get(node) is None):
                raise _fail(f'inputs.{node}', f'null removes a controller of the base scene, and '
                            f'{steps[-1].name!r} runs none of that name')
        raw = _merged(raw, keys)
        steps.append(SceneStep(name, keys, raw))
    if overrides:
        raw = copy.deepcopy(raw)
        set_keys(raw, overrides)
        steps.append(SceneStep(None, dict(overrides), raw))
    return steps


def scene_raw(name_or_path: str | pathlib.Path,
              overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The keys of a scene, its bases and ``overrides`` composed (``scene_steps``).

    :raises InputRefused: as ``scene_steps``.
    """
    return scene_steps(name_or_path, overrides)[-1].raw


def set_keys(raw: dict[str, Any], overrides: Mapping[str, Any]) -> None:
    """Set the dotted keys of ``overrides`` in the scene mapping ``raw`` (``set_key``).

    :raises InputRefused: 'override KEY: ...' for a key that cannot be set.
    """
    for key, value in overrides.items():
        try:
            set_key(raw, key, value)
        except SimulationError as exc:
            raise InputRefused(f'override {key}: {exc}') from None


def load_scene(name_or_path: str | pathlib.Path,
               validate_inputs: Callable[[str, dict[str, Any]], None] | None = None,
               overrides: Mapping[str, Any] | None = None) -> Scene:
    """Load and validate a scene (``scene_raw``: by name or path, with its base and
    ``overrides``; see ``parse_scene``)."""
    return parse_scene(scene_raw(name_or_path, overrides), validate_inputs)
