"""The parameter schema (iceskate_native.parameters) on small example classes: every kind of field,
its checks and messages, building from mappings, and the flat form of ROS parameters."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
import math
from typing import Any

import pytest

from iceskate_native.parameters import (
    Rules,
    block,
    check_fields,
    flatten,
    from_mapping,
    leaf_fields,
    rules_of,
    setting,
    unflatten,
)

COLOURS = ('red', 'green', 'blue')


class ExampleError(ValueError):
    """The error type of the example classes."""


@dataclass(frozen=True)
class Inner2:
    """A block two levels down."""

    limit: float | None = setting(None, 'an optional limit; unset: none', unit='m', low=0.0,
                                  open_low=True)

    def __post_init__(self) -> None:
        check_fields(self, ExampleError)


@dataclass(frozen=True)
class Inner:
    """A nested block."""

    gain: float = setting(2.0, 'a gain', unit='N m/rad', low=0.0)
    depth: Inner2 = block(Inner2, 'a block inside the block')

    def __post_init__(self) -> None:
        check_fields(self, ExampleError)


@dataclass(frozen=True)
class Example:
    """One field of every kind."""

    flag: bool = setting(True, 'a switch')
    count: int = setting(3, 'a count', low=0, high=10)
    closed: float = setting(0.5, 'a fraction', low=0.0, high=1.0)
    positive: float = setting(1.0, 'a duration', unit='s', low=0.0, open_low=True)
    half_open: float = setting(0.1, 'a bounded duration', unit='s', low=0.0, high=2.0,
                               open_low=True)
    below: float = setting(-1.0, 'a number with an upper bound only', high=0.0)
    free: float = setting(0.0, 'a number without bounds')
    optional: float | None = setting(None, 'an optional height', unit='m', low=0.0)
    colour: str = setting('red', 'a colour', choices=COLOURS)
    gains: tuple[float, float, float] = setting((1.0, 2.0, 3.0), 'three gains', low=0.0)
    joints: tuple[int, ...] = setting((1, 2), 'joint numbers', low=1, high=17, distinct=True)
    palette: frozenset[str] = setting(frozenset({'red'}), 'colours', choices=COLOURS)
    inner: Inner = block(Inner, 'a nested block')

    def __post_init__(self) -> None:
        check_fields(self, ExampleError)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Example:
        return from_mapping(cls, d, ExampleError)


def _error(d: Mapping[str, Any]) -> str:
    with pytest.raises(ExampleError) as exc:
        Example.from_dict(d)
    return str(exc.value)


def test_defaults_and_rules():
    assert Example() == Example.from_dict({}) == Example.from_dict(None)
    rules = rules_of(Example)
    assert rules['joints'] == Rules('joint numbers', low=1, high=17, distinct=True)
    assert rules['positive'].unit == 's' and rules['colour'].choices == COLOURS
    assert rules['inner'].description == 'a nested block'
    assert [r.bounds_text() for r in (rules['closed'], rules['positive'], rules['half_open'],
                                      rules['below'], rules['free'])] == [
        '[0, 1]', '> 0', '(0, 2]', '<= 0', '']


def test_values_are_normalised():
    e = Example.from_dict({'closed': 1, 'gains': [0, 1, 2], 'joints': [17, 3],
                           'palette': ['blue', 'red', 'blue'], 'optional': 2,
                           'inner': {'gain': 5, 'depth': {'limit': 1}}})
    assert type(e.closed) is float and e.closed == 1.0
    assert e.gains == (0.0, 1.0, 2.0) and all(type(g) is float for g in e.gains)
    assert e.joints == (17, 3)  # order kept
    assert e.palette == frozenset({'red', 'blue'})
    assert e.optional == 2.0 and type(e.optional) is float
    assert e.inner == Inner(gain=5.0, depth=Inner2(limit=1.0))
    assert Example.from_dict({'inner': e.inner}).inner is e.inner


@pytest.mark.parametrize(('d', 'message'), [
    ({'flag': 1}, 'flag must be true or false, got 1'),
    ({'flag': 'yes'}, "flag must be true or false, got 'yes'"),
    ({'count': 2.5}, 'count must be an integer, got 2.5'),
    ({'count': True}, 'count must be an integer, got True'),
    ({'count': -1}, 'count must be in [0, 10], got -1'),
    ({'count': 11}, 'count must be in [0, 10], got 11'),
    ({'closed': -0.01}, 'closed must be in [0, 1], got -0.01'),
    ({'closed': 1.5}, 'closed must be in [0, 1], got 1.5'),
    ({'closed': '0.5'}, "closed must be a number, got '0.5'"),
    ({'closed': False}, 'closed must be a number, got False'),
    ({'closed': math.nan}, 'closed must be finite, got nan'),
    ({'free': -math.inf}, 'free must be finite, got -inf'),
    ({'positive': 0.0}, 'positive must be > 0, got 0.0'),
    ({'half_open': 0}, 'half_open must be in (0, 2], got 0'),
    ({'half_open': 2.5}, 'half_open must be in (0, 2], got 2.5'),
    ({'below': 0.1}, 'below must be <= 0, got 0.1'),
    ({'closed': None}, 'closed must be set, got None'),
    ({'optional': -1.0}, 'optional must be >= 0, got -1.0'),
    ({'optional': 'high'}, "optional must be a number, got 'high'"),
    ({'colour': 'pink'}, "colour must be one of ['red', 'green', 'blue'], got 'pink'"),
    ({'colour': 1}, 'colour must be text, got 1'),
    ({'gains': [1.0, 2.0]}, 'gains must have 3 entries, got 2'),
    ({'gains': 1.0}, 'gains must be a list, got 1.0'),
    ({'gains': '123'}, "gains must be a list, got '123'"),
    ({'gains': [1.0, -2.0, 3.0]}, 'gains entries must be >= 0, got -2.0'),
    ({'joints': [1, 18]}, 'joints entries must be in [1, 17], got 18'),
    ({'joints': [1, 2.0]}, 'joints entries must be an integer, got 2.0'),
    ({'joints': [4, 2, 4]}, 'joints must not repeat an entry, got [4, 2, 4]'),
    ({'palette': ['red', 'pink']},
     "palette entries must be one of ['red', 'green', 'blue'], got 'pink'"),
    ({'palette': 'red'}, "palette must be a list, got 'red'"),
    ({'inner': 3}, 'inner must be a mapping, got int'),
    ({'inner': {'gain': -1}}, 'inner.gain must be >= 0, got -1'),
    ({'inner': {'depth': {'limit': 0.0}}}, 'inner.depth.limit must be > 0, got 0.0'),
    ({'inner': {'depth': []}}, 'inner.depth must be a mapping, got list'),
])
def test_bad_values_are_refused_with_a_message_naming_the_key(d, message):
    assert _error(d) == message


def test_the_constructor_checks_too():
    with pytest.raises(ExampleError, match=r'^count must be in \[0, 10\]'):
        Example(count=20)
    with pytest.raises(ExampleError, match='^inner must be a Inner'):
        Example(inner={'gain': 1.0})
    assert issubclass(ExampleError, ValueError)


def test_unknown_keys_are_named_with_their_dotted_path():
    assert _error({'colours': []}).startswith('unknown key colours; expected one of [')
    assert _error({'inner': {'gian': 1.0}}) == (
        "unknown key inner.gian; expected one of ['depth', 'gain']")
    assert _error({'inner': {'depth': {'lim': 1.0}}}) == (
        "unknown key inner.depth.lim; expected one of ['limit']")
    with pytest.raises(ExampleError, match='^parameters must be a mapping'):
        Example.from_dict([1, 2])


def test_leaf_fields():
    leaves = leaf_fields(Example)
    assert list(leaves)[-2:] == ['inner.gain', 'inner.depth.limit']
    tp, rules, default = leaves['inner.depth.limit']
    assert tp == float | None and rules.open_low and default is None
    assert leaves['palette'][2] == frozenset({'red'})
    assert {name for name, (_tp, r, _d) in leaves.items() if not r.description} == set()


def test_flatten_and_unflatten():
    flat = flatten(Example())
    assert flat == {
        'flag': True, 'count': 3, 'closed': 0.5, 'positive': 1.0, 'half_open': 0.1,
        'below': -1.0, 'free': 0.0, 'optional': flat['optional'], 'colour': 'red',
        'gains': [1.0, 2.0, 3.0], 'joints': [1, 2], 'palette': ['red'],
        'inner.gain': 2.0, 'inner.depth.limit': flat['inner.depth.limit']}
    assert math.isnan(flat['optional']) and math.isnan(flat['inner.depth.limit'])
    nested = unflatten(Example, flat)
    assert nested['optional'] is None and nested['inner'] == {'gain': 2.0,
                                                              'depth': {'limit': None}}
    assert Example.from_dict(nested) == Example()
    changed = Example.from_dict({'flag': False, 'count': 0, 'optional': 0.0, 'colour': 'blue',
                                 'joints': [], 'palette': ['green', 'blue'], 'free': 0.1 + 0.2,
                                 'inner': {'gain': 7.5, 'depth': {'limit': 1e-12}}})
    flat = flatten(changed)
    assert flat['palette'] == ['blue', 'green'] and flat['joints'] == []
    assert flat['optional'] == 0.0 and flat['inner.depth.limit'] == 1e-12
    back = Example.from_dict(unflatten(Example, flat))
    assert back == changed and flatten(back) == flat


def test_every_example_field_has_rules():
    for cls in (Example, Inner, Inner2):
        assert all('rules' in f.metadata for f in fields(cls))
