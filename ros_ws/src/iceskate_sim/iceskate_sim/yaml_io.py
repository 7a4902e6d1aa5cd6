"""Reading the YAML files users write (scenes, node parameter files, SPECs, ``--set`` values, a
bag's metadata): YAML 1.2 numbers, bounds on size, nesting and alias expansion, and one sentence
naming the file for anything unreadable. Light to import (the nodes check their parameter files
with it before anything else)."""

from __future__ import annotations

import pathlib
import re
from typing import Any

import yaml

from iceskate_sim.errors import InputRefused
from iceskate_sim.files import regular_file

#: The largest YAML file read [bytes] (a scene or a SPEC is a few kB).
MAX_YAML_BYTES = 1 << 20
#: The deepest nesting of mappings and sequences a YAML text may have (a scene: 5 levels).
MAX_YAML_DEPTH = 64
#: The most values a YAML text may hold, an alias counted as the values it stands for: a few
#: hundred bytes of aliases of aliases expand to billions (an "alias bomb").
MAX_YAML_VALUES = 100_000


class _Yaml12Loader(yaml.SafeLoader):
    """PyYAML's safe loader with YAML 1.2's floats: ``1e-6``, ``2.0e7`` and ``1E12`` are numbers
    (YAML 1.1 wants a dot and a signed exponent and reads them as strings), and a mapping that
    gives a key twice refused (PyYAML keeps the last silently)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        """The mapping of ``node``; ConstructorError at a key given twice."""
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if isinstance(key, (str, int, float, bool)) and key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f'the key {key!r} is given twice', key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep)


_Yaml12Loader.add_implicit_resolver(
    'tag:yaml.org,2002:float',
    re.compile(r'^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$'),
    list('-+0123456789'))


def _check_bounds(text: str, what: str) -> None:
    """InputRefused naming ``what`` when ``text`` nests deeper than ``MAX_YAML_DEPTH``, holds
    more than ``MAX_YAML_VALUES`` values, each alias counted as the values its anchor stands
    for and as deep as they nest, or holds a value with an alias of itself inside. One pass over
    the parser's events, before anything is built (yaml.YAMLError where the text is malformed).
    """
    open_values: list[int] = []  # values in each open mapping or sequence so far (itself: 1)
    open_depths: list[int] = []  # the deepest nesting below each so far
    open_anchors: list[str | None] = []
    anchored: dict[str, tuple[int, int]] = {}  # anchor -> (values, nesting) it stands for
    total = 0
    for event in yaml.parse(text, Loader=_Yaml12Loader):
        if isinstance(event, yaml.CollectionStartEvent):
            if len(open_values) >= MAX_YAML_DEPTH:  # at once: the scanner slows with depth
                raise InputRefused(f'{what} nests mappings and sequences deeper than '
                                   f'{MAX_YAML_DEPTH} levels')
            open_values.append(1)
            open_depths.append(0)
            open_anchors.append(event.anchor)
            continue
        if isinstance(event, yaml.CollectionEndEvent):
            values, depth, anchor = open_values.pop(), open_depths.pop() + 1, open_anchors.pop()
        elif isinstance(event, yaml.ScalarEvent):
            values, depth, anchor = 1, 0, event.anchor
        elif isinstance(event, yaml.AliasEvent):
            if event.anchor in open_anchors:
                raise InputRefused(f'{what} holds a value with an alias of itself inside '
                                   f'(*{event.anchor})')
            (values, depth), anchor = anchored.get(event.anchor, (1, 0)), None
        else:
            continue
        if len(open_values) + depth > MAX_YAML_DEPTH:
            raise InputRefused(f'{what} nests mappings and sequences deeper than '
                               f'{MAX_YAML_DEPTH} levels')
        if anchor is not None:
            anchored[anchor] = (values, depth)
        if open_values:
            open_values[-1] += values
            open_depths[-1] = max(open_depths[-1], depth)
            count = open_values[-1]
        else:
            total += values
            count = total
        if count > MAX_YAML_VALUES:
            raise InputRefused(f'{what} expands to more than {MAX_YAML_VALUES} values (its '
                               'aliases counted as what they stand for)')


def _load(text: str, what: str) -> Any:
    """``text`` as YAML 1.2 within the bounds (``_check_bounds``); yaml.YAMLError if malformed."""
    _check_bounds(text, what)
    return yaml.load(text, Loader=_Yaml12Loader)  # noqa: S506 (a SafeLoader subclass)


def yaml_value(text: str, what: str) -> Any:
    """The value a YAML text gives (YAML 1.2 numbers: ``1e-3``, ``[30, 290, 1100]``, ``ice``),
    or InputRefused naming ``what`` (malformed, too deep, too many values)."""
    try:
        return _load(text, what)
    except yaml.YAMLError as exc:
        problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
        raise InputRefused(f'{what}: {text!r} is no YAML value ({problem})') from None


def read_yaml(path: str | pathlib.Path, what: str) -> Any:
    """The YAML document at ``path`` (YAML 1.2 numbers), or InputRefused naming ``what``,
    the path and the problem (unreadable, not a regular file, larger than ``MAX_YAML_BYTES``,
    not UTF-8 text, malformed, nested deeper than ``MAX_YAML_DEPTH``, more than
    ``MAX_YAML_VALUES`` values)."""
    path = pathlib.Path(path)
    try:
        info = regular_file(path, what)
        if info.st_size > MAX_YAML_BYTES:
            raise InputRefused(f'{what} {path} is {info.st_size} bytes, more than the '
                               f'{MAX_YAML_BYTES} a {what} file may have')
        text = path.read_bytes().decode('utf-8')
    except OSError as exc:
        raise InputRefused(f'cannot read {what} {path}: {exc.strerror or exc}') from None
    except UnicodeDecodeError:
        raise InputRefused(f'{what} {path} is not UTF-8 text (a binary file?)') from None
    try:
        return _load(text, f'{what} {path}')
    except yaml.YAMLError as exc:  # one line: where, and what the parser expected
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}, column {mark.column + 1}' if mark is not None else ''
        problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
        raise InputRefused(f'malformed YAML in {what} {path}{where}: {problem}') from None
