"""Every gait-manager parameter class on the one schema: settings, ranges, types, flat form."""

from collections.abc import Iterator
from dataclasses import fields
import math
import typing
from typing import Any

import pytest

from gait_manager.arm_assist import ArmAssistParameters
from gait_manager.balance import BalanceParameters
from gait_manager.errors import GaitManagerError
from gait_manager.feedforward import FeedforwardParameters, WeightTransferParameters
from gait_manager.heel import HeelParameters
from gait_manager.law import SOURCES, GaitManagerParameters
from gait_manager.posture import PostureParameters
from gait_manager.yaw import YawParameters
from iceskate_sim.parameters import Rules, field_types, flatten, leaf_fields, unflatten

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
