"""Scenes: one YAML file per experiment, validated once before the run.

A scene declares the floor, the initial posture and mode, which inputs run (visual lifting and
the gait-manager sources), disturbances, duration, control period, integrator and tolerance,
and what is recorded. An unknown key, a wrong type or an out-of-range value is refused with a
``SimulationError`` naming the key (e.g. ``integrator.step``). Shipped scenes live in
``share/iceskate_sim/scenes/<name>.yaml``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
import pathlib
from typing import Any

import numpy as np
import yaml

from iceskate_sim.dynamics import DynamicsParameters
from iceskate_sim.errors import SimulationError
from iceskate_sim.hybrid import FrictionModel, HybridState
from iceskate_sim.integrators import METHODS, IntegratorConfig
from iceskate_sim.robot import COORDINATE_NAMES, LINK_NAMES, N_COORDINATES, SIDES, _ament_prefixes
from iceskate_sim.simulation import SimulatorConfig, initial_state

POSTURES = ('bent_knees', 'staggered', 'upright')
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
    visual_lifting: dict[str, Any] | None  # parameters for VisualLiftingParameters, or off
    gait_manager: dict[str, Any] | None  # parameters for GaitManagerParameters, or off
    pushes: tuple[Push, ...] = ()
    record_bag: bool = True
    raw: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def sources(self) -> tuple[str, ...]:
        """Names of the input sources this scene runs (effort-command sources)."""
        names: list[str] = []
        if self.visual_lifting is not None:
            names.append('visual_lifting')
        if self.gait_manager is not None:
            from gait_manager.law import GaitManagerParameters
            names += sorted(GaitManagerParameters.from_dict(self.gait_manager).enabled)
        return tuple(names)


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


def _number(d: dict[str, Any], key: str, path: str, default: float, low: float | None = None,
            high: float | None = None, positive: bool = False) -> float:
    value = d.get(key, default)
    if isinstance(value, bool) or not isinstance(value, _NUMBER):
        raise _fail(path, f'must be a number, got {value!r}')
    value = float(value)
    if not math.isfinite(value):
        raise _fail(path, f'must be finite, got {value!r}')
    if positive and value <= 0.0:
        raise _fail(path, f'must be > 0, got {value}')
    if low is not None and value < low:
        raise _fail(path, f'must be >= {low}, got {value}')
    if high is not None and value > high:
        raise _fail(path, f'must be <= {high}, got {value}')
    return value


def _boolean(d: dict[str, Any], key: str, path: str, default: bool) -> bool:
    value = d.get(key, default)
    if not isinstance(value, bool):
        raise _fail(path, f'must be true or false, got {value!r}')
    return value


def _choice(d: dict[str, Any], key: str, path: str, default: str, choices: tuple[str, ...]
            ) -> str:
    value = d.get(key, default)
    if value not in choices:
        raise _fail(path, f'must be one of {list(choices)}, got {value!r}')
    return value


def _coordinates(d: Any, path: str) -> dict[int, float]:
    d = _check_keys(d or {}, path, set(COORDINATE_NAMES))
    return {COORDINATE_NAMES.index(k): _number(d, k, f'{path}.{k}', 0.0) for k in d}


# ----------------------------------------------------------------------- postures
def standing_posture(kind: str, knee_bend: float, stagger: float) -> tuple[np.ndarray, str]:
    """Initial coordinates of a double-support posture and the pivot to use.

    * 'bent_knees' (default, model-spec 13.1): feet side by side, q2..q7 = (-a, 2a, -a, a,
      -2a, a): both soles flat, the pelvis level, not singular.
    * 'staggered' (model-spec 2.6): support (front) foot ``stagger`` m ahead of the swing foot,
      straight legs.
    * 'upright': all zero (singular in double support, model-spec 13.1; single support only).
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
        'dynamics', 'inputs', 'disturbances', 'record', 'fall_height'}


def parse_scene(raw: Any, source: str = '<scene>') -> Scene:
    """Validate a scene mapping and build a Scene; raise SimulationError naming the key."""
    raw = _check_keys(raw, '', _TOP, {'scene', 'duration', 'control_period', 'inputs'})
    name = raw['scene']
    if not isinstance(name, str) or not name:
        raise _fail('scene', f'must be a non-empty name, got {name!r}')
    description = raw.get('description', '')
    if not isinstance(description, str):
        raise _fail('description', 'must be text')
    duration = _number(raw, 'duration', 'duration', 0.0, positive=True, high=3600.0)
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
    try:
        simulator = SimulatorConfig(control_period=control_period, integrator=integrator,
                                    friction=friction, dynamics=dynamics, projection=projection,
                                    fall_height=fall_height)
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
    locked = [i for i in (0, 1) if i not in initial.mode.active and v[i] != 0.0]
    if locked:
        raise _fail('initial.v', f'{COORDINATE_NAMES[locked[0]]} is not a coordinate of mode '
                    f'{mode}; its velocity must be 0')

    inputs = _check_keys(raw['inputs'], 'inputs', {'visual_lifting', 'gait_manager'})
    vl = inputs.get('visual_lifting')
    gm = inputs.get('gait_manager')
    _validate_controllers(vl, gm)

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
    record = _check_keys(raw.get('record', {}), 'record', {'bag'})
    return Scene(name, description, duration, simulator, initial, vl, gm, tuple(pushes),
                 _boolean(record, 'bag', 'record.bag', True), raw)


def _validate_controllers(vl: Any, gm: Any) -> None:
    from gait_manager.errors import GaitManagerError
    from gait_manager.law import GaitManagerParameters
    from visual_lifting.errors import VisualLiftingError
    from visual_lifting.law import VisualLiftingParameters
    if vl is not None:
        try:
            VisualLiftingParameters.from_dict(vl or {})
        except VisualLiftingError as exc:
            raise _fail('inputs.visual_lifting', str(exc)) from None
    if gm is not None:
        try:
            GaitManagerParameters.from_dict(gm or {})
        except GaitManagerError as exc:
            raise _fail('inputs.gait_manager', str(exc)) from None


def scene_dirs() -> list[pathlib.Path]:
    """Directories searched for shipped scenes (installed share dir, then the source tree)."""
    here = pathlib.Path(__file__).resolve().parent
    dirs = [p / 'share' / 'iceskate_sim' / 'scenes' for p in _ament_prefixes()]
    dirs.append(here.parent / 'scenes')
    return [d for d in dirs if d.is_dir()]


def shipped_scenes() -> list[str]:
    """Names of the scenes shipped with the package."""
    names = set()
    for d in scene_dirs():
        names.update(p.stem for p in d.glob('*.yaml'))
    return sorted(names)


def load_scene(name_or_path: str | pathlib.Path) -> Scene:
    """Load a shipped scene by name (e.g. 'skate') or a YAML file by path."""
    path = pathlib.Path(name_or_path)
    if not path.suffix:
        for d in scene_dirs():
            if (d / f'{path.name}.yaml').is_file():
                path = d / f'{path.name}.yaml'
                break
        else:
            raise SimulationError(f'unknown scene {str(name_or_path)!r}; shipped scenes: '
                                  f'{shipped_scenes()}')
    try:
        text = path.read_text(encoding='utf-8')
    except OSError as exc:
        raise SimulationError(f'cannot read scene {path}: {exc}') from exc
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise SimulationError(f'malformed YAML in scene {path}: {exc}') from exc
    return parse_scene(raw, str(path))
