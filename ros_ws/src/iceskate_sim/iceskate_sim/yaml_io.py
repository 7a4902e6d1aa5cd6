"""Reading the YAML files users write (scenes, node parameter files): YAML 1.2 numbers, and one
sentence naming the file for anything unreadable. Light to import (the nodes check their
parameter files with it before anything else)."""

from __future__ import annotations

import pathlib
import re
import stat
from typing import Any

import yaml

from iceskate_sim.errors import SimulationError

#: The largest YAML file read [bytes] (a scene or a SPEC is a few kB).
MAX_YAML_BYTES = 1 << 20


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


def yaml_value(text: str, what: str) -> Any:
    """The value a YAML text gives (YAML 1.2 numbers: ``1e-3``, ``[30, 290, 1100]``, ``ice``),
    or SimulationError naming ``what``."""
    try:
        return yaml.load(text, Loader=_Yaml12Loader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as exc:
        problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
        raise SimulationError(f'{what}: {text!r} is no YAML value ({problem})') from None


def read_yaml(path: str | pathlib.Path, what: str) -> Any:
    """The YAML document at ``path`` (YAML 1.2 numbers), or SimulationError naming ``what``,
    the path and the problem (unreadable, not a regular file, larger than ``MAX_YAML_BYTES``,
    not UTF-8 text, malformed)."""
    path = pathlib.Path(path)
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            raise SimulationError(f'{what} {path} is not a regular file')
        if info.st_size > MAX_YAML_BYTES:
            raise SimulationError(f'{what} {path} is {info.st_size} bytes, more than the '
                                  f'{MAX_YAML_BYTES} a {what} file may have')
        text = path.read_bytes().decode('utf-8')
    except OSError as exc:
        raise SimulationError(f'cannot read {what} {path}: {exc.strerror or exc}') from None
    except UnicodeDecodeError:
        raise SimulationError(f'{what} {path} is not UTF-8 text (a binary file?)') from None
    try:
        return yaml.load(text, Loader=_Yaml12Loader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as exc:  # one line: where, and what the parser expected
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}, column {mark.column + 1}' if mark is not None else ''
        problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
        raise SimulationError(f'malformed YAML in {what} {path}{where}: {problem}') from None
