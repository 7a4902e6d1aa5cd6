"""Scenes: one YAML file per experiment, validated once before the run (the simulator's part).

A scene declares the floor, the initial posture and mode, which controllers run (``inputs``:
one parameter block per controller node), disturbances, duration, control period, integrator
and tolerance, and what is recorded. This module validates everything the simulator uses; the
controllers' blocks are kept as given and validated by the layer that composes the controllers
(``parse_scene``'s ``validate_inputs``; ``iceskate_bringup.scene`` does it for the shipped
controllers). An unknown key, a wrong type or an out-of-range value is refused with a
``SimulationError`` naming the key (e.g. ``integrator.step``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
import math
import pathlib
from typing import Any

import numpy as np

from iceskate_sim.dynamics import DynamicsParameters
from iceskate_sim.errors import SimulationError
from iceskate_sim.hybrid import FrictionModel, HybridState
from iceskate_sim.integrators import METHODS, IntegratorConfig
from iceskate_sim.parameters import Rules, check_value
from iceskate_sim.robot import COORDINATE_NAMES, LINK_NAMES, N_COORDINATES, SIDES
from iceskate_sim.simulation import ENGINES, SimulatorConfig, initial_state
from iceskate_sim.yaml_io import read_yaml  # scenes are read by it (and it is found here too)

POSTURES = ('bent_knees', 'staggered', 'upright')
#: The longest run [s] a scene (or ``run_scene --duration``) may ask for.
MAX_DURATION = 3600.0
_NUMBER = (int, float)


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
    raw: dict[str, Any] = field(default_factory=dict, repr=False)



# ---------------------------------------------------------------- validation helpers
def _fail(key: str, message: str) -> SimulationError:
    return SimulationError(f'scene key {key!r}: {message}')


def _check_keys(d: Any, key: str, allowed: set[str], required: set[str] = frozenset()
                ) -> dict[str, Any]:
    if not isinstance(d, dict):
        raise _fail(key, f'must be a mapping, got {type(d).__name__}')
    for k in d:
        if k not in allowed:
            raise _fail(f'{key}.{k}' if key else str(k),
                        f'unknown key; allowed: {sorted(allowed)}')
    for k in required:
        if k not in d:
            raise _fail(f'{key}.{k}' if key else k, 'missing')
    return d


def _setting(d: dict[str, Any], key: str, path: str, default: Any, kind: type,
             **rules: Any) -> Any:
    """``d[key]`` (or ``default``) checked by the parameter schema's rules
    (``iceskate_sim.parameters``, the rules of every parameter of the project), named ``path``."""
    try:
        return check_value(path, d.get(key, default), kind, Rules(path, **rules),
                           SimulationError)
    except SimulationError as exc:  # 'path must be ...' -> "scene key 'path': must be ..."
        raise _fail(path, str(exc).removeprefix(f'{path} ')) from None


def _number(d: dict[str, Any], key: str, path: str, default: float, low: float | None = None,
            high: float | None = None, positive: bool = False) -> float:
    if positive:
        return _setting(d, key, path, default, float, low=0.0, high=high, open_low=True)
    return _setting(d, key, path, default, float, low=low, high=high)


def _boolean(d: dict[str, Any], key: str, path: str, default: bool) -> bool:
    return _setting(d, key, path, default, bool)


def _choice(d: dict[str, Any], key: str, path: str, default: str, choices: tuple[str, ...]
            ) -> str:
    return _setting(d, key, path, default, str, choices=choices)


def _coordinates(d: Any, path: str) -> dict[int, float]:
    d = _check_keys(d or {}, path, set(COORDINATE_NAMES))
    return {COORDINATE_NAMES.index(k): _number(d, k, f'{path}.{k}', 0.0) for k in d}


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
_TOP = {'scene', 'description', 'duration', 'control_period', 'floor', 'initial', 'integrator',
        'dynamics', 'inputs', 'disturbances', 'record', 'fall_height', 'engine'}


def parse_scene(raw: Any, validate_inputs: Callable[[str, dict[str, Any]], None] | None = None
                ) -> Scene:
    """Validate a scene mapping and build a Scene; raise SimulationError naming the key.

    :param validate_inputs: ``validate_inputs(node, block)`` checks the parameter block of one
        controller node (raising SimulationError naming the key); None: blocks are taken as
        given (the simulator needs only their node names).
    """
    raw = _check_keys(raw, '', _TOP, {'scene', 'duration', 'control_period', 'inputs'})
    name = raw['scene']
    if not isinstance(name, str) or not name:
        raise _fail('scene', f'must be a non-empty name, got {name!r}')
    description = raw.get('description', '')
    if not isinstance(description, str):
        raise _fail('description', 'must be text')
    duration = _number(raw, 'duration', 'duration', 0.0, positive=True, high=MAX_DURATION)
    control_period = _number(raw, 'control_period', 'control_period', 0.0, positive=True,
                             high=0.1)

    floor = _check_keys(raw.get('floor', {}), 'floor', {'rule', 'mu'})
    friction = FrictionModel(mu=_number(floor, 'mu', 'floor.mu', 0.005, low=0.0, high=2.0),
                             rule=_choice(floor, 'rule', 'floor.rule', 'ice', ('ice', 'coulomb')))

    integ = _check_keys(raw.get('integrator', {}), 'integrator',
                        {'method', 'step', 'rtol', 'atol', 'event_tolerance', 'projection'})
    integrator = IntegratorConfig(
        method=_choice(integ, 'method', 'integrator.method', 'rk4', METHODS),
        step=_number(integ, 'step', 'integrator.step', 1e-4, positive=True, high=0.1),
        rtol=_number(integ, 'rtol', 'integrator.rtol', 1e-8, positive=True, high=1.0),
        atol=_number(integ, 'atol', 'integrator.atol', 1e-10, positive=True, high=1.0),
        event_tolerance=_number(integ, 'event_tolerance', 'integrator.event_tolerance', 1e-10,
                                positive=True, high=1e-3))
    projection = _boolean(integ, 'projection', 'integrator.projection', True)

    dyn = _check_keys(raw.get('dynamics', {}), 'dynamics',
                      {'joint_limits', 'damping', 'baumgarte', 'limit_stiffness',
                       'limit_damping'})
    dynamics = DynamicsParameters(
        joint_limits=_boolean(dyn, 'joint_limits', 'dynamics.joint_limits', True),
        damping=_boolean(dyn, 'damping', 'dynamics.damping', True),
        baumgarte=_number(dyn, 'baumgarte', 'dynamics.baumgarte', 0.0, low=0.0, high=1e4),
        limit_stiffness=_number(dyn, 'limit_stiffness', 'dynamics.limit_stiffness', 1e4,
                                low=0.0, high=1e7),
        limit_damping=_number(dyn, 'limit_damping', 'dynamics.limit_damping', 100.0, low=0.0,
                              high=1e5))
    fall_height = _number(raw, 'fall_height', 'fall_height', 1.2, low=0.0, high=1.7)
    engine = _choice(raw, 'engine', 'engine', 'native', ENGINES)
    try:
        simulator = SimulatorConfig(control_period=control_period, integrator=integrator,
                                    friction=friction, dynamics=dynamics, projection=projection,
                                    fall_height=fall_height, engine=engine)
    except SimulationError as exc:
        raise _fail('control_period', str(exc)) from None

    init = _check_keys(raw.get('initial', {}), 'initial',
                       {'mode', 'support', 'posture', 'knee_bend', 'stagger', 'q', 'v'})
    mode = init.get('mode', 17)
    if isinstance(mode, bool) or not isinstance(mode, int) or not 1 <= mode <= 20:
        raise _fail('initial.mode', f'must be a Table 2 mode 1-20, got {mode!r}')
    side = _choice(init, 'support', 'initial.support', 'right', SIDES)
    posture = _choice(init, 'posture', 'initial.posture', 'bent_knees', POSTURES)
    q, pivot = standing_posture(
        posture, _number(init, 'knee_bend', 'initial.knee_bend', 0.05, low=0.0, high=0.6),
        _number(init, 'stagger', 'initial.stagger', 0.25, low=0.0, high=0.8))
    for i, value in _coordinates(init.get('q'), 'initial.q').items():
        q[i] = value
    v = np.zeros(N_COORDINATES)
    for i, value in _coordinates(init.get('v'), 'initial.v').items():
        v[i] = value
    initial = initial_state(q, mode, side, pivot, v)
    if 1 not in initial.mode.active and q[1] != 0.0:  # the sole is flat: q1 is not free
        raise _fail('initial.q.q1', f'q1 (the support sole on its edge) is not a coordinate of '
                    f'mode {mode}, whose support sole is flat; leave it out or start in a mode '
                    'with the sole on its toe or heel')
    locked = [i for i in (0, 1) if i not in initial.mode.active and v[i] != 0.0]
    if locked:
        name = COORDINATE_NAMES[locked[0]]
        raise _fail(f'initial.v.{name}', f'{name} is not a coordinate of mode {mode}; its '
                    'velocity must be 0')

    if not isinstance(raw['inputs'], dict):
        raise _fail('inputs', f'must be a mapping, got {type(raw["inputs"]).__name__}')
    inputs: dict[str, dict[str, Any]] = {}
    for node, block in raw['inputs'].items():
        block = {} if block is None else block
        if not isinstance(block, dict):
            raise _fail(f'inputs.{node}', f'must be a mapping, got {type(block).__name__}')
        if validate_inputs is not None:
            validate_inputs(str(node), block)
        inputs[str(node)] = block

    pushes = []
    for k, item in enumerate(raw.get('disturbances', []) or []):
        path = f'disturbances[{k}]'
        item = _check_keys(item, path, {'start', 'duration', 'frame', 'force'},
                           {'start', 'duration', 'frame', 'force'})
        frame = item['frame']
        if frame not in LINK_NAMES:
            raise _fail(f'{path}.frame', f'unknown link {frame!r}; one of {list(LINK_NAMES)}')
        force = item['force']
        if (not isinstance(force, list) or len(force) != 3
                or not all(isinstance(f, _NUMBER) and not isinstance(f, bool) for f in force)):
            raise _fail(f'{path}.force', f'must be 3 numbers [N], got {force!r}')
        pushes.append(Push(_number(item, 'start', f'{path}.start', 0.0, low=0.0),
                           _number(item, 'duration', f'{path}.duration', 0.0, positive=True),
                           frame, tuple(float(f) for f in force)))
    record = _check_keys(raw.get('record', {}), 'record', {'bag', 'rate'})
    return Scene(name, description, duration, simulator, initial, inputs, tuple(pushes),
                 _boolean(record, 'bag', 'record.bag', True),
                 _record_every(record, simulator.control_period), raw)


def _record_every(record: dict[str, Any], control_period: float) -> int:
    """Control periods per recorded sample from ``record.rate`` [samples/s], which must divide
    the control rate (default: the control rate, every period)."""
    control_rate = 1.0 / control_period
    rate = _number(record, 'rate', 'record.rate', control_rate, positive=True)
    every = round(control_rate / rate)
    if every < 1 or abs(every * rate - control_rate) > 1e-9 * control_rate:
        raise _fail('record.rate', f'{rate:g} samples/s does not divide the control rate '
                    f'{control_rate:g} Hz (e.g. {control_rate:g}, {control_rate / 2:g}, '
                    f'{control_rate / 10:g})')
    return every

def load_scene(path: str | pathlib.Path,
               validate_inputs: Callable[[str, dict[str, Any]], None] | None = None) -> Scene:
    """Load and validate the scene YAML file at ``path`` (see ``parse_scene``)."""
    return parse_scene(read_yaml(path, 'scene'), validate_inputs)

