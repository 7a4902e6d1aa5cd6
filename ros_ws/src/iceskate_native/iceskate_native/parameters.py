"""One schema for every parameter set: frozen dataclasses whose fields say their rules
(``setting``, ``block``, ``check_fields``, ``checked``, ``from_mapping``, ``flatten``,
``unflatten``).
See docs/architecture.md, 'Parameters'.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import MISSING, dataclass, field, fields, is_dataclass
import functools
import math
import numbers
import types
import typing
from typing import Any, TypeVar

T = TypeVar('T')


@dataclass(frozen=True)
class Rules:
    """The rules of one field.

    :param description: what the value is (shown by ``ros2 param describe``).
    :param unit: SI unit ('' for none).
    :param low: inclusive lower bound of a number or of each entry of a sequence.
    :param high: inclusive upper bound.
    :param open_low: the lower bound is exclusive.
    :param choices: allowed names of a text field, or of each entry of a set of names.
    :param distinct: a sequence must not repeat an entry.
    """

    description: str
    unit: str = ''
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    choices: tuple[str, ...] | None = None
    distinct: bool = False

    def bounds_text(self) -> str:
        """The range in words, e.g. '>= 0', '(0, 5]' ('' without bounds)."""
        if self.low is not None and self.high is not None:
            return f'{"(" if self.open_low else "["}{self.low:g}, {self.high:g}]'
        if self.low is not None:
            return f'{">" if self.open_low else ">="} {self.low:g}'
        if self.high is not None:
            return f'<= {self.high:g}'
        return ''


def setting(default: Any, description: str, **rules: Any) -> Any:
    """A dataclass field with its default and its ``Rules`` (keywords of ``Rules``)."""
    return field(default=default, metadata={'rules': Rules(description, **rules)})


def block(factory: Any, description: str) -> Any:
    """A field holding a nested parameter block (a parameter class), default-constructed."""
    return field(default_factory=factory, metadata={'rules': Rules(description)})


@functools.cache
def rules_of(cls: type) -> types.MappingProxyType[str, Rules]:
    """The rules of every field of a parameter class (a description-only rule if none)."""
    return types.MappingProxyType({f.name: f.metadata.get('rules', Rules(f.name))
                                   for f in fields(cls)})


@functools.cache
def field_types(cls: type) -> dict[str, Any]:
    """The resolved type annotation of every field of a parameter class."""
    return typing.get_type_hints(cls)


def optional_inner(tp: Any) -> Any:
    """``X`` of an ``X | None`` annotation (``tp`` itself otherwise)."""
    args = typing.get_args(tp)
    if (typing.get_origin(tp) in (typing.Union, types.UnionType) and type(None) in args
            and len(args) == 2):
        return next(a for a in args if a is not type(None))
    return tp


@functools.cache
def _shape(tp: Any) -> tuple[bool, Any, Any, tuple[Any, ...]]:
    """Of annotation ``tp``: whether it is ``X | None``, then ``X`` and ``X``'s origin and
    arguments (``typing.get_origin``, ``get_args``); cached by the annotation's equality."""
    inner = optional_inner(tp)
    return inner is not tp, inner, typing.get_origin(inner), typing.get_args(inner)


def _number(name: str, value: Any, r: Rules, error: type[Exception], kind: type) -> Any:
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise error(f'{name} must be an integer, got {value!r}')
        x: float = int(value)
    else:  # a float skips the slower ABC checks
        if type(value) is not float and (isinstance(value, bool)
                                         or not isinstance(value, numbers.Real)):
            raise error(f'{name} must be a number, got {value!r}')
        x = float(value)
        if not math.isfinite(x):
            raise error(f'{name} must be finite, got {value!r}')
    if ((r.low is not None and (x < r.low or (r.open_low and x == r.low)))
            or (r.high is not None and x > r.high)):
        both = r.low is not None and r.high is not None
        raise error(f'{name} must be {"in " if both else ""}{r.bounds_text()}, got {value!r}')
    return x


def check_value(name: str, value: Any, tp: Any, r: Rules, error: type[Exception]) -> Any:
    """``value`` checked against type ``tp`` and rules ``r``, normalised (floats, tuples,
    frozensets); raises ``error`` with a message starting with ``name``."""
    if tp is Any:  # taken as given (checked by whoever reads it)
        return value
    optional, tp, origin, args = _shape(tp)
    if value is None:
        if optional:
            return None
        raise error(f'{name} must be set, got None')
    if tp is bool:
        if not isinstance(value, bool):
            raise error(f'{name} must be true or false, got {value!r}')
        return value
    if tp in (int, float):
        return _number(name, value, r, error, tp)
    if tp is str:
        if not isinstance(value, str):
            raise error(f'{name} must be text, got {value!r}')
        if r.choices is not None and value not in r.choices:
            raise error(f'{name} must be one of {list(r.choices)}, got {value!r}')
        return value
    if origin in (tuple, frozenset):
        if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, set, frozenset)):
            raise error(f'{name} must be a list, got {value!r}')
        items = list(value)
        fixed = origin is tuple and not (len(args) == 2 and args[1] is Ellipsis)
        if fixed and len(items) != len(args):
            raise error(f'{name} must have {len(args)} entries, got {len(items)}')
        kind = args[0]
        checked = [check_value(f'{name} entries', item, kind, r, error) for item in items]
        if r.distinct and len(set(checked)) != len(checked):
            raise error(f'{name} must not repeat an entry, got {checked}')
        return frozenset(checked) if origin is frozenset else tuple(checked)
    if is_dataclass(tp):
        if not isinstance(value, tp):
            raise error(f'{name} must be a {tp.__name__}, got {value!r}')
        return value
    raise TypeError(f'parameter {name}: unsupported type {tp!r}')


def check_fields(obj: Any, error: type[Exception]) -> None:
    """Check and normalise every field of a frozen parameter object (its ``__post_init__``)."""
    types_, rules = field_types(type(obj)), rules_of(type(obj))
    for name, tp in types_.items():
        value = check_value(name, getattr(obj, name), tp, rules[name], error)
        object.__setattr__(obj, name, value)


def checked(error: type[Exception]) -> Callable[[Any], None]:
    """A parameter class's ``__post_init__``: ``check_fields`` raising ``error``."""
    return lambda obj: check_fields(obj, error)


def from_mapping(cls: type[T], d: Any, error: type[Exception], prefix: str = '') -> T:
    """Build parameter class ``cls`` from mapping ``d``: missing keys keep their defaults (a
    field without a default must be given), nested blocks are built from nested mappings; an
    unknown or missing key or a bad value raises ``error`` naming its dotted path (``prefix`` +
    key)."""
    if isinstance(d, cls):
        return d
    if d is None:
        d = {}
    if not isinstance(d, Mapping):
        raise error(f'{prefix.rstrip(".") or "parameters"} must be a mapping, got '
                    f'{type(d).__name__}')
    types_ = field_types(cls)
    kwargs: dict[str, Any] = {}
    for key, value in d.items():
        if key not in types_:
            raise error(f'unknown key {prefix}{key!s}; expected one of {sorted(types_)}')
        tp = types_[key]
        kwargs[key] = (from_mapping(tp, value, error, f'{prefix}{key}.') if is_dataclass(tp)
                       else value)
    for f in fields(cls):
        if f.name not in kwargs and f.default is MISSING and f.default_factory is MISSING:
            raise error(f'{prefix}{f.name} must be given')
    try:
        return cls(**kwargs)
    except error as exc:
        if prefix and not str(exc).startswith(prefix):
            raise error(f'{prefix}{exc}') from None
        raise


def keyed_from_mapping(cls: type[T], d: Any, error: type[Exception],
                       fail: Callable[[str, str], Exception], prefix: str = '') -> T:
    """``from_mapping`` of a file's block (a scene's, a study's; ``error`` is the classes' own
    error type) whose error is ``fail(dotted key, problem)``, e.g. "scene key 'floor.mu': must be
    in [0, 2], got -0.1"."""
    try:
        return from_mapping(cls, d, error, f'{prefix}.' if prefix else '')
    except error as exc:
        text = str(exc)
        if text.startswith('unknown key '):  # 'unknown key K; expected one of [...]'
            key, _, allowed = text.removeprefix('unknown key ').partition('; expected one of ')
            raise fail(key, f'unknown key; allowed: {allowed}') from None
        key, _, problem = text.partition(' ')  # 'K must be ...'
        raise fail(key, problem) from None


def flatten(obj: Any, prefix: str = '') -> dict[str, Any]:
    """``{dotted name: value}`` of a parameter object: sequences as sorted-or-ordered lists,
    an unset optional number as NaN, nested blocks flattened under their field name."""
    out: dict[str, Any] = {}
    for f in fields(obj):
        value = getattr(obj, f.name)
        name = f'{prefix}{f.name}'
        if is_dataclass(value):
            out |= flatten(value, f'{name}.')
        elif value is None:
            out[name] = math.nan
        elif isinstance(value, frozenset):
            out[name] = sorted(value)
        elif isinstance(value, tuple):
            out[name] = list(value)
        else:
            out[name] = value
    return out


def unflatten(cls: type, flat: Mapping[str, Any]) -> dict[str, Any]:
    """The nested mapping ``from_mapping(cls, ...)`` takes, from ``{dotted name: value}``
    (NaN of an optional number back to None)."""
    out: dict[str, Any] = {}
    types_ = field_types(cls)
    for name, value in flat.items():
        head, _, rest = name.partition('.')
        if rest and head in types_ and is_dataclass(types_[head]):
            out.setdefault(head, {})[rest] = value
            continue
        tp = types_.get(name, Any)
        if optional_inner(tp) is not tp and isinstance(value, float) and math.isnan(value):
            value = None
        out[name] = value
    for head, sub in list(out.items()):
        if head in types_ and is_dataclass(types_[head]) and isinstance(sub, dict):
            out[head] = unflatten(types_[head], sub)
    return out


def leaf_fields(cls: type, prefix: str = '') -> dict[str, tuple[Any, Rules, Any]]:
    """``{dotted name: (type, rules, default)}`` of every leaf field of a parameter class."""
    out: dict[str, tuple[Any, Rules, Any]] = {}
    rules = rules_of(cls)
    for f in fields(cls):
        tp = field_types(cls)[f.name]
        if is_dataclass(tp):
            out |= leaf_fields(tp, f'{prefix}{f.name}.')
        else:
            default = f.default if f.default is not MISSING else f.default_factory()
            out[f'{prefix}{f.name}'] = (tp, rules[f.name], default)
    return out
