"""Reading the YAML files users write (scenes, node parameter files): YAML 1.2 numbers, and one
sentence naming the file for anything unreadable. Light to import (the nodes check their
parameter files with it before anything else)."""

from __future__ import annotations

import pathlib
import re
from typing import Any

import yaml

from iceskate_sim.errors import SimulationError


class _Yaml12Loader(yaml.SafeLoader):
    """PyYAML's safe loader with YAML 1.2's floats: ``1e-6``, ``2.0e7`` and ``1E12`` are numbers
    (YAML 1.1 wants a dot and a signed exponent and reads them as strings)."""


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
    the path and the problem (unreadable, not UTF-8 text, malformed)."""
    path = pathlib.Path(path)
    try:
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
