"""Every gait-manager parameter class on the one schema: settings, ranges, types, flat form; every
field reaches the C++ sources by its name, and their binding refuses what C++ cannot take."""

from collections.abc import Iterator
from dataclasses import asdict, fields
import math
from types import SimpleNamespace
import typing
from typing import Any

import pytest

from gait_manager.errors import GaitManagerError
from gait_manager.native import GaitManagerController
from gait_manager.parameters import (
    SOURCES,
    ArmAssistParameters,
    BalanceParameters,
    FeedforwardParameters,
    GaitManagerParameters,
    HeelParameters,
    PostureParameters,
    WeightTransferParameters,
    YawParameters,
    head_stance,
)
from iceskate_native.parameters import Rules, field_types, flatten, leaf_fields, unflatten

CLASSES = (PostureParameters, BalanceParameters, FeedforwardParameters,
           WeightTransferParameters, HeelParameters, ArmAssistParameters, YawParameters,
           GaitManagerParameters)
LEAVES = leaf_fields(GaitManagerParameters)
UNITS = {'', 'm', 's', 'rad', 'm/s', 'N', 'N m', 'N m/rad', 'N m s/rad', 'N s/m', 'N m/m',
         'N m s/m', 'N/m'}


def _entry_type(tp: Any) -> Any:
    return typing.get_args(tp)[0]


def _out_of_range(tp: Any, r: Rules, default: Any) -> Iterator[Any]:
    """Values of type ``tp`` that break the range, choices or distinctness of ``r``."""
    origin = typing.get_origin(tp)
    if tp in (int, float):
        if r.low is not None:
            yield r.low - 1
            if r.open_low:
                yield r.low
        if r.high is not None:
            yield r.high + 1
    elif tp is str:
        yield 'no such choice'
    elif origin is tuple:
        for bad in _out_of_range(_entry_type(tp), r, None):
            yield [bad]
        if r.distinct:
            yield [default[0], default[0]]
    elif origin is frozenset:
        yield ['no such choice']


def _in_range(tp: Any, r: Rules) -> Iterator[Any]:
    """The bounds of ``r`` that are allowed values."""
    if tp in (int, float):
        if r.low is not None and not r.open_low:
            yield r.low
        if r.high is not None:
            yield r.high


def _wrong_type(tp: Any) -> list[Any]:
    if tp is bool:
        return ['yes', 1, None]
    if tp is int:
        return [1.5, True, '3', None]
    if tp is float:
        return ['x', True, None, math.nan, math.inf]
    if tp is str:
        return [3, None]
    if typing.get_origin(tp) is tuple:
        return ['2, 3', 2, None, [2.5]]
    return ['posture', 3, None]  # frozenset of names


def _cases(values: Any) -> list[tuple[str, Any]]:
    return [(name, value) for name, (tp, r, default) in LEAVES.items()
            for value in values(tp, r, default)]


def _nested(name: str, value: Any) -> dict[str, Any]:
    head, _, leaf = name.partition('.')
    return {head: {leaf: value}} if leaf else {head: value}


def _block_of(name: str) -> tuple[type, str]:
    """The class that owns dotted field ``name`` and the field's name in it."""
    head, _, leaf = name.partition('.')
    return (field_types(GaitManagerParameters)[head], leaf) if leaf else (
        GaitManagerParameters, head)


def _refused(name: str, value: Any) -> None:
    """``value`` for field ``name`` is refused by from_dict and by the owning class's
    constructor and from_dict, each with a message that starts with the key."""
    with pytest.raises(GaitManagerError) as exc:
        GaitManagerParameters.from_dict(_nested(name, value))
    assert str(exc.value).startswith(f'{name} '), str(exc.value)
    cls, leaf = _block_of(name)
    with pytest.raises(GaitManagerError) as exc:
        cls.from_dict({leaf: value})
    assert str(exc.value).startswith(f'{name} '), str(exc.value)
    with pytest.raises(GaitManagerError) as exc:
        cls(**{leaf: value})
    assert str(exc.value).startswith(f'{leaf} '), str(exc.value)


@pytest.mark.parametrize('cls', CLASSES)
def test_defaults_build_and_every_field_has_a_described_setting(cls):
    assert cls() == cls.from_dict({})
    for f in fields(cls):
        rules = f.metadata.get('rules')
        assert isinstance(rules, Rules), f'{cls.__name__}.{f.name} has no setting'
        assert rules.description.strip(), f'{cls.__name__}.{f.name} has no description'
        assert rules.unit in UNITS, f'{cls.__name__}.{f.name}: unit {rules.unit!r}'


def test_every_number_has_a_range_and_every_name_its_choices():
    assert len(LEAVES) > 70
    for name, (tp, r, _default) in LEAVES.items():
        entry = _entry_type(tp) if typing.get_origin(tp) in (tuple, frozenset) else tp
        if entry in (int, float):
            assert r.low is not None or r.high is not None, name
        if entry is str:
            assert r.choices, name
    assert LEAVES['enabled'][1].choices == SOURCES


@pytest.mark.parametrize(('name', 'value'), _cases(_out_of_range))
def test_out_of_range_values_are_refused_naming_the_key(name, value):
    _refused(name, value)


@pytest.mark.parametrize(('name', 'value'),
                         _cases(lambda tp, r, default: _wrong_type(tp)))
def test_wrong_types_are_refused_naming_the_key(name, value):
    _refused(name, value)


@pytest.mark.parametrize(('name', 'value'),
                         _cases(lambda tp, r, default: _in_range(tp, r)))
def test_closed_bounds_are_allowed(name, value):
    params = GaitManagerParameters.from_dict(_nested(name, value))
    assert flatten(params)[name] == value


def test_unknown_keys_are_named_with_their_path():
    with pytest.raises(GaitManagerError, match=r'^unknown key posture\.kq;'):
        GaitManagerParameters.from_dict({'posture': {'kq': 1.0}})
    with pytest.raises(GaitManagerError, match=r'^unknown key yaw\.gain;'):
        YawParameters.from_dict({'gain': 1.0})
    with pytest.raises(GaitManagerError, match='^unknown key postures;'):
        GaitManagerParameters.from_dict({'postures': {}})


def _round_trip(params: GaitManagerParameters) -> GaitManagerParameters:
    flat = flatten(params)
    assert set(flat) == set(LEAVES)
    return GaitManagerParameters.from_dict(unflatten(GaitManagerParameters, flat))


def test_flatten_unflatten_round_trip():
    default = GaitManagerParameters()
    assert _round_trip(default) == default
    changed = GaitManagerParameters.from_dict({
        'enabled': ['yaw', 'posture'],
        'posture': {'reference': 'balance', 'joints': [10, 2, 17], 'gravity_joints': [],
                    'stiffness': 123.456, 'null_space': True, 'shift_z1': -0.1},
        'balance': {'speed': 0.1 + 0.2, 'descent_start': 0.99},
        'weight_transfer': {'rule': 'com', 'joint1_torque': False},
        'arm_assist': {'off_from_step_index': 7, 'phase': 'B_clipped'},
        'yaw': {'amplitude': 1e-9},
    })
    assert changed != default
    back = _round_trip(changed)
    assert back == changed and flatten(back) == flatten(changed)
    assert back.posture.joints == (10, 2, 17) and back.posture.gravity_joints == ()
    assert back.enabled == frozenset({'posture', 'yaw'})
    assert isinstance(back.arm_assist.off_from_step_index, int)
    assert back.balance.speed == 0.1 + 0.2


def _distinct_values() -> GaitManagerParameters:
    """Every leaf field set to a value other than its default, the numbers all different from
    each other: a field read into the wrong C++ member cannot go unnoticed."""
    changed: dict[str, Any] = {}
    for k, (name, (tp, r, default)) in enumerate(sorted(LEAVES.items())):
        if tp is float:
            low = r.low if r.low is not None else -1.0
            high = r.high if r.high is not None else low + 100.0
            value = low + (high - low) * (0.05 + 0.9 * ((0.618034 * (k + 1)) % 1.0))
            changed[name] = value if value != default else (value + low) / 2.0
        elif tp is bool:
            changed[name] = not default
        elif tp is int:
            changed[name] = default + 4
        elif tp is str:
            changed[name] = next(c for c in r.choices if c != default)
    changed |= {'posture.joints': (10, 2, 17), 'posture.gravity_joints': (5, 9),
                'enabled': frozenset({'yaw', 'heel'})}
    return GaitManagerParameters.from_dict(unflatten(GaitManagerParameters, changed))


def _as_python(value: Any) -> Any:
    """A dataclass's values as the binding gives them back: lists, sources in their order."""
    if isinstance(value, dict):
        return {k: _as_python(v) for k, v in value.items()}
    if isinstance(value, frozenset):
        return [s for s in SOURCES if s in value]
    if isinstance(value, tuple):
        return list(value)
    return value


def test_every_field_reaches_the_cpp_sources_by_its_name():
    """Each field, set to its own value, comes back from the C++ struct the sources read
    (``GaitManagerController.parameters``, the generated reader and writer), under its own
    name; the struct has no field the dataclass lacks, nor the other way round."""
    params = _distinct_values()
    numbers = [v for name, v in flatten(params).items() if isinstance(v, float)]
    assert len(set(numbers)) == len(numbers) > 60
    for name, value in flatten(params).items():
        assert value != flatten(GaitManagerParameters())[name], name
    held = GaitManagerController(params).parameters
    assert held == _as_python(asdict(params))
    assert set(flatten(params)) == set(LEAVES)
    controller = GaitManagerController(GaitManagerParameters())
    controller.set_parameters(params)
    assert controller.parameters == held


def test_the_defaults_are_the_cpp_defaults():
    """The default parameters arrive unchanged (the generated struct defaults are the
    dataclass's too, so a C++ caller without Python gets the same sources)."""
    held = GaitManagerController(GaitManagerParameters()).parameters
    assert held == _as_python(asdict(GaitManagerParameters()))
    assert held['enabled'] == list(SOURCES)


def _fields(**blocks) -> SimpleNamespace:
    """The default parameters with some fields of some blocks changed, unchecked."""
    params = GaitManagerParameters()
    out = {name: SimpleNamespace(**asdict(getattr(params, name)))
           for name in ('posture', 'balance', 'feedforward', 'weight_transfer', 'heel',
                        'arm_assist', 'yaw')}
    for block, changes in blocks.items():
        for field, value in changes.items():
            setattr(out[block], field, value)
    return SimpleNamespace(**out, enabled=params.enabled)


@pytest.mark.parametrize(('blocks', 'message'), [
    ({'balance': {'speed': float('nan')}}, 'balance.speed is nan: every parameter must be finite'),
    ({'posture': {'joints': (2, 18)}}, 'posture.joints holds joint 18, expected joints 2-17'),
    ({'posture': {'gravity_joints': (1,)}}, 'posture.gravity_joints holds joint 1'),
    ({'posture': {'reference': 'sitting'}},
     "posture.reference 'sitting' is not one of moving, standing, balance"),
    ({'yaw': {'phase': 'C'}}, "yaw.phase 'C' is not one of A, B, B_clipped"),
    ({'weight_transfer': {'share': float('inf')}}, 'weight_transfer.share is inf'),
    ({'arm_assist': {'off_from_step_index': -1}},
     'arm_assist.off_from_step_index is -1, expected >= 0'),
    ({'heel': {'stiffness': None}}, 'heel.stiffness must be a number'),
    ({'feedforward': {'joint1_torque': 1}}, 'feedforward.joint1_torque must be true or false'),
])
def test_the_binding_refuses_bad_parameters_in_one_sentence(blocks, message):
    with pytest.raises(ValueError, match=message):
        GaitManagerController(_fields(**blocks))


def test_the_binding_refuses_an_unknown_source_and_a_missing_field():
    fields_ = _fields()
    fields_.enabled = frozenset({'posture', 'dance'})
    with pytest.raises(ValueError, match="^enabled 'dance' is not one of posture, "
                                         'feedforward, weight_transfer, heel, arm_assist, yaw$'):
        GaitManagerController(fields_)
    fields_ = _fields()
    del fields_.heel.damping
    with pytest.raises(ValueError, match='^the parameters have no field heel.damping$'):
        GaitManagerController(fields_)


def test_from_dict_nested():
    params = GaitManagerParameters.from_dict({
        'enabled': ['posture', 'yaw'],
        'posture': {'stiffness': 400, 'reference': 'standing'},
        'yaw': {'phase': 'A'},
    })
    assert params.enabled == frozenset({'posture', 'yaw'})
    assert params.posture.stiffness == 400.0 and params.posture.reference == 'standing'
    assert params.yaw.phase == 'A' and params.feedforward == FeedforwardParameters()
    assert GaitManagerParameters.from_dict({}) == GaitManagerParameters()


def test_the_constructor_checks_blocks_and_sources():
    with pytest.raises(GaitManagerError, match='posture'):
        GaitManagerParameters(posture={'stiffness': 1.0})
    with pytest.raises(GaitManagerError, match='enabled'):
        GaitManagerParameters(enabled=frozenset({'vla'}))
    assert issubclass(GaitManagerError, ValueError)


def test_defaults_follow_the_model():
    """docs/model.md §11: the posture stabiliser's joints and gains, the stance schedule."""
    p = PostureParameters()
    assert p.joints == (2, 3, 4, 9, 10) and 17 not in p.joints
    assert (p.stiffness, p.damping, p.yaw_stiffness, p.yaw_damping) == (800, 16, 20, 2)
    assert p.gravity_compensation and not p.null_space and p.bend == 0.05
    assert (p.shift_y1, p.shift_z1, p.shift_time1, p.shift_y2, p.shift_time2) == (
        0.10, 0.03, 0.6, 0.10, 0.5)
    assert (YawParameters().amplitude, YawParameters().period) == (30.0, 1.85)


def _stance_shift(stance, obs) -> tuple[float, float]:
    """(dy, dz) [m] of ``stance`` at ``obs``: smoothstep ramps over t1 after the exchange and
    over t2 after the heel strike (the schedule the C++ laws run, docs/model.md)."""
    def ramp(dt: float, duration: float) -> float:
        if duration == 0.0:
            return 1.0 if dt >= 0.0 else 0.0
        x = min(max(dt / duration, 0.0), 1.0)
        return x * x * (3.0 - 2.0 * x)

    s1 = ramp(obs.t - obs.t_exchange, stance.t1)
    dy = stance.dy1 * s1
    if math.isfinite(obs.t_touchdown):
        dy += stance.dy2 * ramp(obs.t - obs.t_touchdown, stance.t2)
    return dy, -stance.dz1 * s1


def test_head_stance_follows_the_posture_source(make_obs):
    """Visual lifting's target follows the posture source's stance while that runs with the
    'moving' reference, and no stance otherwise."""
    obs = make_obs(t=2.0, t_exchange=1.0, t_touchdown=1.5)
    params = GaitManagerParameters()
    stance = head_stance(params)
    assert stance == params.posture.stance
    assert _stance_shift(stance, obs) == pytest.approx([0.2, -0.03])
    moved = GaitManagerParameters(posture=PostureParameters(shift_y1=0.05, shift_time2=0.2))
    assert head_stance(moved) == moved.posture.stance != stance
    assert head_stance(GaitManagerParameters(enabled=frozenset({'yaw'}))) is None
    for reference in ('standing', 'balance'):
        assert head_stance(GaitManagerParameters(
            posture=PostureParameters(reference=reference))) is None
