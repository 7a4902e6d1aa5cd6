"""SPEC files of parameter studies: a base scene, overrides and axes over dotted scene keys, and
the runs they generate, every scene validated before any run starts (the format: docs/usage.md,
"Parameter studies"). A bad SPEC is a one-line ``StudyRefused`` naming its key. The runs are made
on demand (``Points``), never a million of them at once, and every loop over the values or points
of a SPEC ends at a signal of its ``StopRequest`` (``RunInterrupted``).
"""

from __future__ import annotations

from collections.abc import Container, Iterable, Iterator, Sequence
import copy
from dataclasses import MISSING, asdict, dataclass, replace
import hashlib
import json
import math
import numbers
import pathlib
import re
from typing import Any, TypeVar, overload

import numpy as np

from iceskate_bringup.scene import parse_scene
from iceskate_native.parameters import check_fields, keyed_from_mapping, setting
from iceskate_sim.errors import SimulationError
from iceskate_sim.installed import shipped_or_path
from iceskate_sim.run.metrics import METRIC_NAMES, METRICS
from iceskate_sim.run.scene import key_tokens, scene_path, scene_raw
from iceskate_sim.run.scene import set_key as set_scene_key
from iceskate_sim.shutdown import StopRequest, raise_if_stopped
from iceskate_sim.yaml_io import read_yaml
from iceskate_study.errors import StudyError, StudyRefused

SAMPLINGS = ('grid', 'random', 'latin_hypercube')
#: What the table keeps of each run's metrics when the SPEC does not say.
DEFAULT_METRICS = ('steps', 'fell', 'forward_distance_m', 'sim_time_s', 'wall_time_s',
                   'real_time_factor', 'transitions', 'head_error_rms', 'arm_swing',
                   'arm_swing_steady')
#: The heat maps drawn when a SPEC's ``maps`` gives no metrics (and its ratios).
DEFAULT_MAP_METRICS = ('steps', 'fell', 'forward_distance_m', 'arm_swing_steady.corr_q11_q14')
#: Columns of every row besides the axes and the metrics.
RUN_COLUMNS = ('key', 'point', 'repeat', 'status', 'failure', 'run_dir', 'worker_time_s')
#: The most runs a SPEC may generate.
MAX_RUNS = 1_000_000

_METRIC = re.compile(r'[A-Za-z0-9_]+(?:\.[A-Za-z0-9_]+)*')
T = TypeVar('T')


def _study_rules(obj: Any) -> None:
    check_fields(obj, StudyRefused)


@dataclass(frozen=True, kw_only=True)
class StudySettings:
    """A SPEC file's keys, each a ``setting`` with its rules (the blocks of axes, bags, ratios
    and maps are read by ``parse_spec``)."""

    study: str = setting(MISSING, 'name of the study (letters, digits, _ . -)')
    description: str = setting('', 'what the study asks')
    scene: str = setting(MISSING, 'base scene: a shipped name or a path (relative to the SPEC)')
    overrides: Any = setting(None, 'dotted scene key -> value, for every run')
    axes: Any = setting(MISSING, 'dotted scene key -> its values or range')
    sampling: str = setting('grid', 'every combination of the axes, or points drawn from their '
                            'ranges', choices=SAMPLINGS)
    samples: int | None = setting(None, "points to draw (sampling 'random' or "
                                  "'latin_hypercube')", low=1)
    seed: int | None = setting(None, 'seed of the draw', low=0)
    repeats: int = setting(1, 'runs of each point', low=1)
    metrics: tuple[str, ...] | None = setting(None, 'the entries of metrics.json the table '
                                              'keeps (dotted; None: DEFAULT_METRICS)')
    bags: Any = setting(None, "'all' or the axis values of the points recorded with a bag")
    ratios: Any = setting(None, 'derived metrics: a metric over its value at a baseline '
                          '(metric_ratio)')
    maps: Any = setting(None, 'the heat maps drawn at the end')
    __post_init__ = _study_rules


@dataclass(frozen=True)
class Axis:
    """One axis: grid ``values``, or a range [``low``, ``high``] to sample (``log`` scale)."""

    key: str
    values: tuple[Any, ...] | None = None
    low: float | None = None
    high: float | None = None
    log: bool = False


@dataclass(frozen=True)
class Ratio:
    """A derived metric: the mean of ``metrics`` over its value at the run whose axis
    ``baseline_key`` is ``baseline_value`` (the other axes and the repeat equal), by
    ``iceskate_sim.run.metrics.metric_ratio``; a ratio named as one of its ``METRICS`` is
    that one."""

    name: str
    metrics: tuple[str, ...]
    baseline_key: str
    baseline_value: Any


@dataclass(frozen=True, kw_only=True)
class MapSpec:
    """``maps``: the heat maps drawn at the end of a sweep, ``metrics`` over axes ``x`` and
    ``y``."""

    x: str = setting(MISSING, 'axis along x')
    y: str = setting(MISSING, 'axis along y, another than x')
    metrics: tuple[str, ...] | None = setting(None, 'the columns drawn (None: '
                                              'DEFAULT_MAP_METRICS and the ratios)')
    __post_init__ = _study_rules


@dataclass(frozen=True)
class Point:
    """One run of a sweep.

    :param index: the parameter point (0-based, in the SPEC's order; repeats share it).
    :param repeat: the repeat index (0-based).
    :param values: the axes' values, by key.
    :param raw: the whole scene mapping of the run (validated).
    :param key: hash of ``raw`` and ``repeat``: the run's row key.
    :param bag: the run is recorded with a bag (into the sweep's ``runs/<key>/``).
    """

    index: int
    repeat: int
    values: dict[str, Any]
    raw: dict[str, Any]
    key: str
    bag: bool


@dataclass(frozen=True)
class Spec:
    """A validated SPEC."""

    study: str
    description: str
    path: pathlib.Path
    scene: pathlib.Path
    base: dict[str, Any]  # the base scene mapping with the overrides applied
    axes: tuple[Axis, ...]
    sampling: str
    samples: int
    seed: int
    repeats: int
    metrics: tuple[str, ...]
    bags: tuple[dict[str, Any], ...] | None  # None: every point
    ratios: tuple[Ratio, ...]
    maps: MapSpec | None

    @property
    def axis_keys(self) -> tuple[str, ...]:
        """The axes' keys, in the SPEC's order."""
        return tuple(axis.key for axis in self.axes)

    def description_for_table(self) -> dict[str, Any]:
        """What the results table records of the SPEC (plain JSON types)."""
        return {'study': self.study, 'description': self.description,
                'scene': str(self.scene), 'sampling': self.sampling,
                'axes': {a.key: {'log': a.log, 'values': list(a.values)} if a.values is not None
                         else {'log': a.log, 'range': [a.low, a.high]} for a in self.axes},
                'repeats': self.repeats, 'metrics': list(self.metrics),
                'ratios': {r.name: {'metrics': list(r.metrics),
                                    'baseline': {r.baseline_key: r.baseline_value}}
                           for r in self.ratios},
                'maps': asdict(self.maps) if self.maps is not None else None}


def _fail(key: str, message: str) -> StudyRefused:
    return StudyRefused(f'SPEC key {key!r}: {message}')


def _is_number(value: Any) -> bool:
    return (isinstance(value, numbers.Real) and not isinstance(value, bool)
            and math.isfinite(float(value)))


def polled(items: Iterable[T], stop: StopRequest | None) -> Iterator[T]:
    """``items``, ending with ``RunInterrupted`` before the next one once ``stop`` has a
    signal (None: never)."""
    for item in items:
        raise_if_stopped(stop)
        yield item


# ------------------------------------------------------------------ dotted scene keys
def set_key(raw: dict[str, Any], key: str, value: Any, where: str) -> None:
    """``iceskate_sim.run.scene.set_key``, its refusal named as SPEC key ``where``."""
    try:
        set_scene_key(raw, key, value)
    except SimulationError as exc:
        raise _fail(where, str(exc)) from None


def run_key(raw: dict[str, Any], repeat: int) -> str:
    """The key of a run: a hash of its whole scene mapping and its repeat index."""
    text = json.dumps({'scene': raw, 'repeat': repeat}, sort_keys=True, default=str,
                      separators=(',', ':'))
    return hashlib.sha256(text.encode('utf-8')).hexdigest()[:16]


# ------------------------------------------------------------------------- axes
def _axis(key: str, raw: Any, sampling: str) -> Axis:
    where = f'axes.{key}'
    try:
        key_tokens(key)
    except SimulationError as exc:
        raise _fail(where, str(exc)) from None
    kinds = list(raw.keys() & {'linspace', 'logspace', 'range'}) if isinstance(raw, dict) else []
    if not isinstance(raw, list) and len(kinds) != 1:
        raise _fail(where, 'an axis is a list of values, {linspace: [start, stop, count]}, '
                           f'{{logspace: [start, stop, count]}} or {{range: [low, high]}}, got '
                           f'{raw!r}')
    kind = kinds[0] if kinds else 'values'
    if kind == 'range' and sampling == 'grid':
        raise _fail(where, "a range is sampled: set sampling to 'random' or "
                           "'latin_hypercube', or give the values (a list, linspace, logspace)")
    if kind != 'range' and sampling != 'grid':
        raise _fail(where, f'sampling {sampling!r} draws from a range: give {{range: [low, '
                           'high]}')
    if isinstance(raw, list):
        if not raw:
            raise _fail(where, 'an axis needs at least one value, got []')
        texts = [json.dumps(v, sort_keys=True, default=str) for v in raw]
        if len(set(texts)) != len(texts):
            raise _fail(where, f'an axis must not repeat a value, got {raw}')
        return Axis(key, tuple(raw))
    allowed = [kind, 'scale'] if kind == 'range' else [kind]
    unknown = sorted(set(raw) - set(allowed))
    if unknown:
        raise _fail(f'{where}.{unknown[0]}', f'unknown key; allowed with {kind}: {allowed}')
    args = raw[kind]
    if not isinstance(args, list) or len(args) != (2 if kind == 'range' else 3) or not all(
            _is_number(a) for a in args[:2]):
        form = '[low, high]' if kind == 'range' else '[start, stop, count]'
        raise _fail(f'{where}.{kind}', f'must be {form} (finite numbers), got {args!r}')
    low, high = float(args[0]), float(args[1])
    if kind == 'range':
        scale = raw.get('scale', 'linear')
        if scale not in ('linear', 'log'):
            raise _fail(f'{where}.scale', f"must be 'linear' or 'log', got {scale!r}")
        if not low < high:
            raise _fail(f'{where}.range', f'low must be below high, got [{low:g}, {high:g}]')
        if scale == 'log' and low <= 0.0:
            raise _fail(f'{where}.range', f'a log scale needs low > 0, got {low:g}')
        return Axis(key, low=low, high=high, log=scale == 'log')
    count = args[2]
    if (isinstance(count, bool) or not isinstance(count, numbers.Integral) or count < 1
            or count > MAX_RUNS):
        raise _fail(f'{where}.{kind}', f'the count of values must be an integer in [1, '
                                       f'{MAX_RUNS}], got {count!r}')
    if count > 1 and low == high:
        raise _fail(f'{where}.{kind}', f'start and stop are equal ({low:g}): {count} equal values')
    if kind == 'logspace' and (low <= 0.0 or high <= 0.0):
        raise _fail(f'{where}.logspace', f'start and stop must be > 0, got [{low:g}, {high:g}]')
    values = (np.geomspace if kind == 'logspace' else np.linspace)(low, high, int(count))
    return Axis(key, tuple(float(v) for v in values), log=kind == 'logspace')


def point_count(spec: Spec) -> int:
    """The parameter points of ``spec`` (each run ``repeats`` times)."""
    return (spec.samples if spec.sampling != 'grid'
            else math.prod(len(axis.values or ()) for axis in spec.axes))


def drawn_values(spec: Spec) -> np.ndarray:
    """The axes' values of the ``samples`` random or Latin-hypercube points (``seed``) of a
    sampled ``spec``, mapped onto the ranges: one row per point."""
    axes, samples = spec.axes, spec.samples
    rng = np.random.default_rng(spec.seed)
    if spec.sampling == 'random':
        unit = rng.random((samples, len(axes)))
    else:
        from scipy.stats import qmc
        unit = qmc.LatinHypercube(d=len(axes), rng=rng).random(samples)
    log = np.array([axis.log for axis in axes])
    bounds = np.array([(axis.low, axis.high) for axis in axes], dtype=float)
    bounds[log] = np.log(bounds[log])
    values = bounds[:, 0] + unit * (bounds[:, 1] - bounds[:, 0])
    values[:, log] = np.exp(values[:, log])
    return values


def _match(value: Any, wanted: Any) -> bool:
    if _is_number(value) and _is_number(wanted):
        return bool(np.isclose(float(value), float(wanted), rtol=1e-9, atol=0.0))
    return bool(value == wanted)


# ------------------------------------------------------------------------ metrics
def _metric_name(name: Any, where: str) -> str:
    if not isinstance(name, str) or not _METRIC.fullmatch(name):
        raise _fail(where, f'{name!r} is not a metric name (dotted, e.g. '
                           'arm_swing_steady.corr_q11_q14)')
    if name.split('.')[0] not in METRIC_NAMES:
        raise _fail(where, f'{name!r} is not in metrics.json; its entries: '
                           f'{list(METRIC_NAMES)}')
    return name


def kept(name: str, metrics: tuple[str, ...]) -> bool:
    """Whether column ``name`` is among the kept ``metrics`` (itself, or inside a kept block)."""
    return any(name == m or name.startswith(f'{m}.') for m in metrics)


# ------------------------------------------------------------------------ the SPEC
#: The ament index resource of the packages that ship studies.
STUDY_RESOURCE = 'iceskate_studies'


def load_spec(name_or_path: str | pathlib.Path, stop: StopRequest | None = None) -> Spec:
    """Read and validate a SPEC file (a path, or a shipped study's name); ``stop``: as
    ``parse_spec``'s."""
    try:
        path = shipped_or_path(name_or_path, STUDY_RESOURCE, 'studies', 'study')
        raw = read_yaml(path, 'SPEC')
    except SimulationError as exc:
        raise StudyRefused(str(exc)) from None
    return parse_spec(raw, path, stop)


def _base_scene(raw: str, path: pathlib.Path) -> tuple[pathlib.Path, dict[str, Any]]:
    if not raw:  # text, by StudySettings
        raise _fail('scene', "must be a shipped scene name or the path of a scene file, got ''")
    relative = path.parent / raw  # a path is relative to the SPEC's folder, as a scene's base
    try:
        scene_file = scene_path(relative if pathlib.Path(raw).suffix and relative.is_file()
                                else raw)
        return scene_file.resolve(), scene_raw(scene_file)
    except SimulationError as exc:
        raise _fail('scene', str(exc)) from None


def _check_scene(raw: dict[str, Any], where: str, what: str) -> None:
    try:
        parse_scene(raw)
    except SimulationError as exc:
        raise _fail(where, f'{what} gives a bad scene: {exc}') from None


def parse_spec(raw: Any, path: pathlib.Path, stop: StopRequest | None = None) -> Spec:
    """Validate a SPEC mapping read from ``path`` (StudyRefused naming the key).

    :param stop: its signal ends the checks of the axes' values (``RunInterrupted``).
    """
    if not isinstance(raw, dict):
        raise StudyRefused(f'SPEC {path} must be a mapping, got {type(raw).__name__}')
    top = keyed_from_mapping(StudySettings, raw, StudyError, _fail)
    if not re.fullmatch(r'[A-Za-z0-9_.-]+', top.study):
        raise _fail('study', f'must be a name (letters, digits, _ . -), got {top.study!r}')
    scene_file, base = _base_scene(top.scene, path)

    overrides = top.overrides or {}
    if not isinstance(overrides, dict):
        raise _fail('overrides', f'must be a mapping of scene keys, got {overrides!r}')
    for key, value in overrides.items():
        set_key(base, key, value, f'overrides.{key}')
    _check_scene(base, 'overrides', 'the base scene with the overrides')

    sampling = top.sampling
    if sampling == 'grid':
        for k in ('samples', 'seed'):
            if getattr(top, k) is not None:
                raise _fail(k, "is for sampling 'random' or 'latin_hypercube'")
    elif top.samples is None:
        raise _fail('samples', f'must be given for sampling {sampling!r} (the points to draw)')

    if not isinstance(top.axes, dict) or not top.axes:
        raise _fail('axes', f'must map at least one scene key to its values, got '
                            f'{top.axes!r}')
    axes = tuple(_axis(str(key), value, sampling) for key, value in top.axes.items())
    points = (top.samples if sampling != 'grid'
              else math.prod(len(axis.values or ()) for axis in axes))
    if points * top.repeats > MAX_RUNS:  # before any run's scene is made
        raise _fail('axes', f'the SPEC generates {points * top.repeats} runs, more than '
                            f'{MAX_RUNS}')
    keys = tuple(axis.key for axis in axes)
    bags = _bags(top.bags, keys)
    alone = one_scene_per_value(axes, sampling)
    for axis in axes:  # each axis alone, at each value (or both ends of its range)
        for value in polled(axis.values if axis.values is not None else (axis.low, axis.high),
                            stop):
            scene = copy.deepcopy(base)
            set_key(scene, axis.key, value, f'axes.{axis.key}')
            if alone:  # the very scene of the run: expand() need not check it again
                set_key(scene, 'record.bag', bagged({axis.key: value}, bags), 'bags')
            _check_scene(scene, f'axes.{axis.key}', f'the value {value!r}')

    metrics = DEFAULT_METRICS if top.metrics is None else top.metrics
    if not metrics:
        raise _fail('metrics', 'must name at least one metric, got []')
    metrics = tuple(dict.fromkeys(_metric_name(m, 'metrics') for m in metrics))
    ratios = _ratios(top.ratios, axes, metrics, sampling, stop)
    return Spec(top.study, top.description, path, scene_file, base, axes, sampling,
                top.samples or 0, top.seed or 0, top.repeats, metrics, bags,
                ratios, _maps(top.maps, keys, metrics, ratios))


def one_scene_per_value(axes: tuple[Axis, ...], sampling: str) -> bool:
    """Whether the runs' scenes are those of the values of one grid axis (``parse_spec``
    checks them as such, bag flag included)."""
    return sampling == 'grid' and len(axes) == 1


def bagged(values: dict[str, Any], bags: tuple[dict[str, Any], ...] | None) -> bool:
    """Whether the point of the axes' ``values`` is recorded with a bag (``Spec.bags``)."""
    return bags is None or any(all(_match(values[k], v) for k, v in selector.items())
                               for selector in bags)


def _bags(raw: Any, keys: tuple[str, ...]) -> tuple[dict[str, Any], ...] | None:
    if raw is None:
        return ()
    if raw == 'all':
        return None
    if not isinstance(raw, list):
        raise _fail('bags', f"must be 'all' or a list of axis values to match, got {raw!r}")
    for i, selector in enumerate(raw):
        if not isinstance(selector, dict) or not selector:
            raise _fail(f'bags[{i}]', f'must map axis keys to values, got {selector!r}')
        for key in selector:
            if key not in keys:
                raise _fail(f'bags[{i}].{key}', f'not an axis; the axes: {list(keys)}')
    return tuple(raw)


def _ratios(raw: Any, axes: tuple[Axis, ...], metrics: tuple[str, ...], sampling: str,
            stop: StopRequest | None) -> tuple[Ratio, ...]:
    if raw is None:
        return ()
    if not isinstance(raw, dict):
        raise _fail('ratios', f'must map names to {{metric: ..., baseline: {{axis: value}}}}, '
                              f'got {raw!r}')
    if raw and sampling != 'grid':
        raise _fail('ratios', 'a ratio needs grid axes (a baseline value on one axis)')
    out = []
    for name, body in raw.items():
        where = f'ratios.{name}'
        if not isinstance(name, str) or not re.fullmatch(r'[A-Za-z0-9_]+', name):
            raise _fail(where, 'a ratio name is letters, digits and _')
        if kept(name, metrics) or name in RUN_COLUMNS:
            raise _fail(where, 'the name is already a column of the table')
        known = METRICS.get(name)  # a ratio of the registry: its metric, or none given
        if known is not None and not known.ratio_of:
            raise _fail(where, f'{name!r} is a metric of metrics.json: give the ratio another '
                               'name')
        if (not isinstance(body, dict) or 'baseline' not in body
                or not set(body) <= {'metric', 'baseline'}
                or ('metric' not in body and known is None)):
            raise _fail(where, f'must be {{metric: NAME or [NAMES], baseline: {{axis: value}}}}, '
                               f'got {body!r}')
        given = body.get('metric', list(known.ratio_of) if known is not None else [])
        names = given if isinstance(given, list) else [given]
        if not names:
            raise _fail(f'{where}.metric', 'names no metric')
        if known is not None and tuple(names) != known.ratio_of:
            raise _fail(f'{where}.metric', f'{name} is the ratio of '
                                           f'{", ".join(known.ratio_of)} (metrics.json\'s); give '
                                           'that metric, or name this ratio otherwise')
        for m in names:
            _metric_name(m, f'{where}.metric')
            if not kept(m, metrics):
                raise _fail(f'{where}.metric', f'{m!r} is not among the metrics kept (add it '
                                               'to metrics)')
        baseline = body['baseline']
        if not isinstance(baseline, dict) or len(baseline) != 1:
            raise _fail(f'{where}.baseline', f'must be {{axis key: value}}, got {baseline!r}')
        ((key, value),) = baseline.items()
        axis = next((a for a in axes if a.key == key), None)
        if axis is None or axis.values is None:
            raise _fail(f'{where}.baseline', f'{key!r} is not an axis')
        exact = next((v for v in polled(axis.values, stop) if _match(v, value)), None)
        if exact is None:
            raise _fail(f'{where}.baseline', f'{value!r} is not a value of axis {key!r}: '
                                             f'{list(axis.values)}')
        out.append(Ratio(name, tuple(names), key, exact))
    return tuple(out)


def _maps(raw: Any, keys: tuple[str, ...], metrics: tuple[str, ...],
          ratios: tuple[Ratio, ...]) -> MapSpec | None:
    if raw is None:
        return None
    maps = keyed_from_mapping(MapSpec, raw, StudyError, _fail, 'maps')
    for k, axis in (('x', maps.x), ('y', maps.y)):
        if axis not in keys:
            raise _fail(f'maps.{k}', f'{axis!r} is not an axis; the axes: {list(keys)}')
    if maps.x == maps.y:
        raise _fail('maps.y', 'must be another axis than x')
    names = (maps.metrics if maps.metrics is not None
             else (*DEFAULT_MAP_METRICS, *(r.name for r in ratios)))
    if not names:
        raise _fail('maps.metrics', 'must name at least one metric, got []')
    for name in names:
        if not (name in {r.name for r in ratios} or name == 'status' or kept(name, metrics)):
            raise _fail('maps.metrics', f'{name!r} is neither a metric kept nor a ratio')
    return replace(maps, metrics=names)


# ---------------------------------------------------------------------- the runs
class Points(Sequence[Point]):
    """The runs of a spec (parameter points in order, each ``repeats`` times), each made when
    asked for (its scene copied from the base, its key hashed): what a sweep holds of a
    million runs is their count."""

    def __init__(self, spec: Spec) -> None:
        self.spec = spec
        self.count = point_count(spec)  # parameter points
        self._drawn = drawn_values(spec) if spec.sampling != 'grid' else None

    def __len__(self) -> int:
        """Runs."""
        return self.count * self.spec.repeats

    @overload
    def __getitem__(self, item: int) -> Point: ...

    @overload
    def __getitem__(self, item: slice) -> list[Point]: ...

    def __getitem__(self, item: int | slice) -> Point | list[Point]:
        """The run at ``item`` (a slice: those runs)."""
        at = range(len(self))[item]
        if isinstance(at, range):
            return [self[i] for i in at]
        index, repeat = divmod(at, self.spec.repeats)
        values, raw, bag = self.scene(index)
        return Point(index, repeat, values, raw, run_key(raw, repeat), bag)

    def __iter__(self) -> Iterator[Point]:
        """Every run, in order."""
        return self.remaining(())

    def remaining(self, done: Container[tuple[int, int]]) -> Iterator[Point]:
        """The runs whose (point, repeat) is not in ``done``, in order (a scene made once for
        a point's repeats)."""
        repeats = range(self.spec.repeats)
        for index in range(self.count):
            left = [r for r in repeats if (index, r) not in done]
            if left:
                values, raw, bag = self.scene(index)
                yield from (Point(index, r, values, raw, run_key(raw, r), bag) for r in left)

    def values(self, index: int) -> dict[str, Any]:
        """The axes' values of parameter point ``index``, by key: the grid's combination
        (first axis slowest) or the drawn point."""
        axes = self.spec.axes
        if self._drawn is not None:
            return {axis.key: float(v) for axis, v in zip(axes, self._drawn[index], strict=True)}
        combo: list[tuple[str, Any]] = []
        for axis in reversed(axes):
            index, i = divmod(index, len(axis.values or ()))
            combo.append((axis.key, (axis.values or ())[i]))
        return dict(reversed(combo))

    def scene(self, index: int) -> tuple[dict[str, Any], dict[str, Any], bool]:
        """The axes' values, the whole scene mapping and the bag flag of point ``index``."""
        values, raw = self.values(index), copy.deepcopy(self.spec.base)
        for key, value in values.items():
            set_key(raw, key, value, f'axes.{key}')
        bag = bagged(values, self.spec.bags)
        set_key(raw, 'record.bag', bag, 'bags')
        return values, raw, bag

    def check(self, stop: StopRequest | None = None) -> None:
        """Check every selector of bags selects a point and every point's scene (those
        ``parse_spec`` checked as values of an axis are not checked again); StudyRefused
        naming the selector or the point, ``RunInterrupted`` at a signal of ``stop``."""
        spec = self.spec
        for i, selector in enumerate(spec.bags or ()):
            if self._drawn is None:  # a grid: each selected axis has a value selected
                hit = all(any(_match(v, selector[axis.key])
                              for v in polled(axis.values or (), stop))
                          for axis in spec.axes if axis.key in selector)
            else:
                hit = any(bagged(self.values(j), (selector,))
                          for j in polled(range(self.count), stop))
            if not hit:
                raise _fail(f'bags[{i}]', f'selects no point of the sweep: {selector}')
        if one_scene_per_value(spec.axes, spec.sampling):
            return
        for index in polled(range(self.count), stop):
            values, raw, _bag = self.scene(index)
            where = ', '.join(f'{k}={v!r}' for k, v in values.items())
            _check_scene(raw, 'axes', f'the point {where}')


def expand(spec: Spec, stop: StopRequest | None = None) -> Points:
    """Every run of ``spec``, each scene validated (``Points.check``)."""
    points = Points(spec)
    points.check(stop)
    return points
