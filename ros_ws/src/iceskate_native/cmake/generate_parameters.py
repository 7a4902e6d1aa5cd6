"""Generate a controller package's C++ parameter structs and readers from its parameter classes.

Run by CMake at build time; writes ``parameters.hpp`` (a struct per dataclass, an enum per tuple
of choices) and ``parameter_readers.hpp`` (``read_<name>``, ``as_dict``) into ``--out``.
See docs/architecture.md, 'One parameter schema'.
"""

from __future__ import annotations

import argparse
from dataclasses import MISSING, fields, is_dataclass
import importlib
import pathlib
import re
import sys
import types
import typing
from typing import Any

INT_LOW = 'std::numeric_limits<int>::min()'
INT_HIGH = 'std::numeric_limits<int>::max()'


def camel(name: str) -> str:
    """'B_clipped' -> 'BClipped', 'weight_transfer' -> 'WeightTransfer'."""
    return ''.join(part[:1].upper() + part[1:] for part in re.split(r'[_\W]+', name) if part)


def snake(name: str) -> str:
    """'GaitManagerParameters' -> 'gait_manager' (the reader's name)."""
    name = name.removesuffix('Parameters')
    return re.sub(r'(?<!^)(?=[A-Z])', '_', name).lower()


def double(value: float) -> str:
    """A C++ double literal that reads back as ``value`` exactly."""
    text = repr(float(value))
    return text if any(c in text for c in '.en') else f'{text}.0'


def quoted(text: str) -> str:
    """A C++ string literal."""
    return '"' + text.replace('\\', '\\\\').replace('"', '\\"') + '"'


def comment(text: str) -> str:
    """``text`` made safe for a // comment (one line)."""
    return ' '.join(text.split())


class Enum:
    """A module-level tuple of choices as a C++ enum."""

    def __init__(self, constant: str, choices: tuple[str, ...]) -> None:
        singular = constant[:-1] if constant.endswith('S') else constant
        self.constant = constant
        self.name = camel(singular.lower())
        self.choices = choices

    def names(self) -> str:
        return f'k{self.name}Names'

    def declaration(self) -> str:
        values = ', '.join(f'k{camel(c)}' for c in self.choices)
        names = ', '.join(quoted(c) for c in self.choices)
        return (f'/// {self.constant}: {", ".join(self.choices)}.\n'
                f'enum class {self.name}\n{{\n  {values}\n}};\n'
                f'constexpr std::array<const char *, {len(self.choices)}> {self.names()} = '
                f'{{{names}}};\n')


class Field:
    """One dataclass field in C++: member declaration, reader and writer statements."""

    def __init__(self, cls: type, f: Any, tp: Any, rules: Any,
                 enums: dict[tuple[str, ...], Enum]) -> None:
        self.name, self.tp, self.rules = f.name, tp, rules
        self.default = f.default if f.default is not MISSING else f.default_factory()
        self.where = f'{cls.__name__}.{f.name}'
        self.enum: Enum | None = None
        choices = rules.choices
        if choices is not None:
            self.enum = enums.get(tuple(choices))
            if self.enum is None:
                raise SystemExit(f'{self.where}: its choices {choices} are no module-level tuple '
                                 'constant, which names their C++ enum')
        self.kind = self._kind()

    def _kind(self) -> str:
        tp, origin, args = self.tp, typing.get_origin(self.tp), typing.get_args(self.tp)
        if is_dataclass(tp):
            return 'block'
        if tp is float:
            return 'float'
        if tp is bool:
            return 'bool'
        if tp is int:
            if self.rules.high is not None:  # Fields.integer checks a lower bound only
                raise SystemExit(f'{self.where}: an integer with an upper bound is not '
                                 'generated yet; bound it in C++ or extend Fields.integer')
            return 'int'
        if tp is str and self.enum is not None:
            return 'choice'
        if origin in (typing.Union, types.UnionType) and set(args) == {float, type(None)}:
            return 'optional'
        if origin is tuple and args == (int, Ellipsis):
            return 'ints'
        if origin is tuple and args and all(a is float for a in args):
            return 'floats'
        if origin is frozenset and args == (str,) and self.enum is not None:
            return 'set'
        raise SystemExit(f'{self.where}: no C++ form for the type {tp!r}')

    def cpp_type(self) -> str:
        return {
            'block': getattr(self.tp, '__name__', ''),
            'float': 'double', 'bool': 'bool', 'int': 'int',
            'choice': self.enum.name if self.enum else '',
            'optional': 'std::optional<double>',
            'ints': 'std::vector<int>',
            'floats': f'std::array<double, {len(typing.get_args(self.tp))}>',
            'set': f'std::array<bool, {len(self.enum.choices) if self.enum else 0}>',
        }[self.kind]

    def cpp_default(self) -> str:
        d, kind = self.default, self.kind
        if kind == 'block':
            return ''
        if kind == 'float':
            return f' = {double(d)}'
        if kind == 'bool':
            return f' = {"true" if d else "false"}'
        if kind == 'int':
            return f' = {int(d)}'
        if kind == 'choice':
            return f' = {self.enum.name}::k{camel(d)}'
        if kind == 'optional':
            return '' if d is None else f' = {double(d)}'
        if kind == 'ints':
            return ' = {' + ', '.join(str(int(x)) for x in d) + '}'
        if kind == 'floats':
            return ' = {' + ', '.join(double(x) for x in d) + '}'
        return ' = {' + ', '.join('true' if c in d else 'false' for c in self.enum.choices) + '}'

    def doc(self) -> str:
        r = self.rules
        text = comment(r.description)
        if r.unit:
            text += f' [{r.unit}]'
        bounds = r.bounds_text()
        if bounds and self.kind in ('float', 'int', 'optional', 'ints', 'floats'):
            text += f'; {bounds}'
        if self.kind == 'optional':
            text += '; unset: nullopt'
        return text

    def member(self) -> str:
        return f'  /// {self.doc()}\n  {self.cpp_type()} {self.name}{self.cpp_default()};\n'

    def read(self) -> str:
        n, r, q = self.name, self.rules, quoted(self.name)
        if self.kind == 'block':
            return f'  p.{n} = read_{snake(self.tp.__name__)}(f.block({q}));\n'
        if self.kind == 'float':
            return f'  p.{n} = f.number({q});\n'
        if self.kind == 'bool':
            return f'  p.{n} = f.flag({q});\n'
        if self.kind == 'int':
            low = INT_LOW if r.low is None else str(int(r.low))
            return f'  p.{n} = f.integer({q}, {low});\n'
        if self.kind == 'choice':
            return f'  p.{n} = f.choice<{self.enum.name}>({q}, {self.enum.names()});\n'
        if self.kind == 'optional':
            return f'  p.{n} = f.optional_number({q});\n'
        if self.kind == 'ints':
            low = INT_LOW if r.low is None else str(int(r.low))
            high = INT_HIGH if r.high is None else str(int(r.high))
            return f'  p.{n} = f.joints({q}, {low}, {high});\n'
        if self.kind == 'floats':
            size = len(typing.get_args(self.tp))
            return (f'  {{\n    const std::vector<double> values = f.numbers({q}, {size});\n'
                    f'    std::copy(values.begin(), values.end(), p.{n}.begin());\n  }}\n')
        return f'  p.{n} = f.set({q}, {self.enum.names()});\n'

    def write(self) -> str:
        n, q = self.name, quoted(self.name)
        if self.kind == 'block':
            return f'  d[{q}] = as_dict(p.{n});\n'
        if self.kind == 'choice':
            return f'  d[{q}] = {self.enum.names()}[static_cast<std::size_t>(p.{n})];\n'
        if self.kind == 'set':
            return (f'  nanobind::list {n};\n'
                    f'  for (std::size_t k = 0; k < p.{n}.size(); ++k) {{\n'
                    f'    if (p.{n}[k]) {{\n      {n}.append({self.enum.names()}[k]);\n    }}\n'
                    f'  }}\n  d[{q}] = {n};\n')
        return f'  d[{q}] = nanobind::cast(p.{n});\n'


def parameter_classes(module: Any) -> list[type]:
    """The parameter dataclasses defined in ``module``, in definition order."""
    return [obj for obj in vars(module).values()
            if isinstance(obj, type) and is_dataclass(obj) and obj.__module__ == module.__name__]


def choice_enums(module: Any) -> dict[tuple[str, ...], Enum]:
    """The module-level tuples of text (UPPER_CASE names) as enums, by their choices."""
    return {value: Enum(name, value) for name, value in vars(module).items()
            if name.isupper() and isinstance(value, tuple) and value
            and all(isinstance(v, str) for v in value)}


def generate(module_name: str, namespace: str) -> tuple[str, str]:
    """(parameters.hpp, parameter_readers.hpp) of ``module_name``."""
    module = importlib.import_module(module_name)
    from iceskate_native.parameters import field_types, rules_of
    classes = parameter_classes(module)
    if not classes:
        raise SystemExit(f'{module_name} defines no parameter dataclass')
    enums = choice_enums(module)
    source = module_name.replace('.', '/') + '.py'
    banner = (f'// Generated at build time from {source} by iceskate_native/cmake/'
              'generate_parameters.py: do not edit.\n')
    used = {}
    structs, readers, writers = [], [], []
    for cls in classes:
        types_, rules = field_types(cls), rules_of(cls)
        items = [Field(cls, f, types_[f.name], rules[f.name], enums) for f in fields(cls)]
        used.update({id(x.enum): x.enum for x in items if x.enum is not None})
        summary = comment((cls.__doc__ or cls.__name__).split('\n\n')[0]).split('. ')[0]
        doc = summary.rstrip('.') + '.'
        structs.append(f'/// {doc}\nstruct {cls.__name__}\n{{\n'
                       + ''.join(x.member() for x in items) + '};\n')
        reader = snake(cls.__name__)
        readers.append(f'/// {cls.__name__} from its Python object, every field by its name.\n'
                       f'inline {cls.__name__} read_{reader}('
                       'const iceskate_native::binding::Fields & f)\n'
                       f'{{\n  {cls.__name__} p;\n' + ''.join(x.read() for x in items)
                       + '  return p;\n}\n')
        writers.append(f'/// {cls.__name__} as Python values by field name (blocks as dicts).\n'
                       f'inline nanobind::dict as_dict(const {cls.__name__} & p)\n{{\n'
                       '  nanobind::dict d;\n' + ''.join(x.write() for x in items)
                       + '  return d;\n}\n')
    enum_text = '\n'.join(e.declaration() for e in enums.values() if id(e) in used)
    open_ns, close_ns = f'namespace {namespace}\n{{\n\n', f'\n}}  // namespace {namespace}\n'
    structs_hpp = '\n'.join([
        banner + '// The C++ form of the parameter dataclasses: one member per field '
        '(description [unit]; range).',
        '#pragma once', '', *includes(['array', 'optional', 'vector']), '',
        open_ns + enum_text, '\n'.join(structs) + close_ns])
    readers_hpp = '\n'.join([
        banner + '// Reading the parameter dataclasses into their structs by field name, and '
        'back (binding code only).',
        '#pragma once', '',
        *includes(['algorithm', 'cstddef', 'limits', 'stdexcept', 'string', 'vector']), '',
        *includes(['nanobind/nanobind.h', 'nanobind/stl/array.h', 'nanobind/stl/optional.h',
                   'nanobind/stl/string.h', 'nanobind/stl/vector.h']), '',
        f'#include "{namespace}/parameters.hpp"',
        '#include "iceskate_native/binding_parameters.hpp"', '',
        open_ns + '\n'.join(readers), '\n'.join(writers) + close_ns])
    return structs_hpp, readers_hpp


def includes(headers: list[str]) -> list[str]:
    """``#include <header>`` lines."""
    return [f'#include <{h}>' for h in headers]


def project_sources() -> list[pathlib.Path]:
    """The Python files of the modules imported so far that belong to the project, not to the
    interpreter or the installed packages (the generated headers depend on them)."""
    installed = {pathlib.Path(p).resolve() for p in (sys.prefix, sys.base_prefix)}
    files = set()
    for module in list(sys.modules.values()):
        path = getattr(module, '__file__', None)
        if path and path.endswith('.py'):
            resolved = pathlib.Path(path).resolve()
            if not any(resolved.is_relative_to(root) for root in installed):
                files.add(resolved)
    return sorted(files)


def write_depfile(path: pathlib.Path, outputs: list[pathlib.Path]) -> None:
    """A make-style depfile: ``outputs`` depend on every project source imported."""
    def escaped(p: pathlib.Path) -> str:
        return str(p).replace(' ', '\\ ')
    path.write_text(' '.join(escaped(o) for o in outputs) + ': '
                    + ' \\\n  '.join(escaped(f) for f in project_sources()) + '\n')


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--path', action='append', default=[],
                        help='directory put first on sys.path (the package source)')
    parser.add_argument('--module', required=True, help='e.g. gait_manager.parameters')
    parser.add_argument('--namespace', required=True, help='C++ namespace, e.g. gait_manager')
    parser.add_argument('--out', required=True, type=pathlib.Path,
                        help='directory of the two headers')
    parser.add_argument('--depfile', type=pathlib.Path,
                        help='write the Python sources the headers depend on here (make syntax)')
    args = parser.parse_args(argv)
    sys.path[:0] = args.path
    try:
        structs, readers = generate(args.module, args.namespace)
    except ImportError as exc:
        raise SystemExit(f"cannot import {args.module} ({exc}): the package's dependencies "
                         'must be importable in the build environment') from None
    args.out.mkdir(parents=True, exist_ok=True)
    outputs = [args.out / 'parameters.hpp', args.out / 'parameter_readers.hpp']
    for path, text in zip(outputs, (structs, readers), strict=True):
        path.write_text(text)  # only when a source changed: CMake runs this from the depfile
    if args.depfile is not None:
        write_depfile(args.depfile, outputs)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
