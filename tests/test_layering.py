"""The packages stay layered: every import of another workspace package is declared, and
neither the packages nor the modules inside one import each other in a cycle.

Every import statement counts, also those inside functions (an import deferred to run time is
still a dependency). Package dependencies are the ``<depend>``/``<exec_depend>`` entries of each
``package.xml``; a Python package's import name is its directory under ``ros_ws/src/<pkg>/``
(``iceskate_interfaces`` is the ``interfaces`` folder's messages).
"""

import ast
from pathlib import Path
import xml.etree.ElementTree as ET

import pytest

SRC = Path(__file__).resolve().parents[1] / 'ros_ws' / 'src'


def _packages() -> dict[str, Path]:
    """ROS package name -> its folder."""
    return {ET.parse(xml).getroot().findtext('name'): xml.parent
            for xml in sorted(SRC.glob('*/package.xml'))}


PACKAGES = _packages()


def _modules(package: str) -> dict[str, Path]:
    """Dotted module name -> file, of a package's Python modules (none for a message package)."""
    root = PACKAGES[package] / package
    if not (root / '__init__.py').is_file():
        return {}
    out = {}
    for path in sorted(root.rglob('*.py')):
        parts = path.relative_to(PACKAGES[package]).with_suffix('').parts
        out['.'.join(parts[:-1] if parts[-1] == '__init__' else parts)] = path
    return out


def _imports(path: Path, module: str) -> set[str]:
    """Every module name ``path`` imports (absolute, also inside functions)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                anchor = module.split('.')[:len(module.split('.')) - node.level + (
                    1 if path.name == '__init__.py' else 0)]
                base = '.'.join([*anchor, base] if base else anchor)
            names.add(base)
            names.update(f'{base}.{alias.name}' for alias in node.names)
    return names


def _declared(package: str) -> set[str]:
    root = ET.parse(PACKAGES[package] / 'package.xml').getroot()
    return {e.text for tag in ('depend', 'exec_depend', 'build_depend') for e in root.iter(tag)}


def _sources(package: str) -> dict[str, Path]:
    """Every Python file of a package: its modules (by dotted name) and the files beside them
    (by path: a build's code generators, launch files, setup.py), which its build or its users
    run and so depend on what they import."""
    out = _modules(package)
    modules = set(out.values())
    root = PACKAGES[package]
    for path in sorted(root.rglob('*.py')):
        if path not in modules:
            out[str(path.relative_to(root))] = path
    return out


def _package_graph() -> dict[str, set[str]]:
    """Workspace package -> the workspace packages its Python files import."""
    graph: dict[str, set[str]] = {}
    for package in PACKAGES:
        used = set()
        for module, path in _sources(package).items():
            for name in _imports(path, module):
                top = name.split('.')[0]
                if top in PACKAGES and top != package:
                    used.add(top)
        graph[package] = used
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle of ``graph`` as a list of nodes (first == last), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_the_workspace_has_the_layered_packages():
    assert {'iceskate_interfaces', 'iceskate_native', 'iceskate_sim', 'visual_lifting',
            'gait_manager', 'iceskate_bringup', 'iceskate_analysis'} <= set(PACKAGES)


@pytest.mark.parametrize('package', sorted(PACKAGES))
def test_every_workspace_import_is_declared(package):
    undeclared = _package_graph()[package] - _declared(package)
    assert not undeclared, f'{package} imports {sorted(undeclared)} without declaring them'


def test_no_cycle_between_packages():
    assert _cycle(_package_graph()) is None


def test_the_core_and_the_laws_stay_below_the_bringup():
    graph = _package_graph()
    assert graph['iceskate_native'] == set()  # the C++ kernels sit below everything
    assert graph['iceskate_sim'] <= {'iceskate_interfaces', 'iceskate_native'}
    for law in ('visual_lifting', 'gait_manager'):
        assert graph[law] <= {'iceskate_sim', 'iceskate_native', 'iceskate_interfaces'}, law


@pytest.mark.parametrize('package', sorted(PACKAGES))
def test_no_cycle_between_the_modules_of_a_package(package):
    modules = _modules(package)
    graph = {}
    for module, path in modules.items():
        targets = set()
        for name in _imports(path, module):
            while name and name not in modules:  # 'pkg.mod.Name' -> 'pkg.mod'
                name = name.rpartition('.')[0]
            if name and name != module and name != package:
                targets.add(name)
        graph[module] = targets
    assert _cycle(graph) is None


#: The layers of the core (``iceskate_sim``), bottom up: the package root (errors, the parameter
#: schema, YAML reading, signals), the robot model, the physics on the native core, recording,
#: one run, the ROS side. A module imports only from its own layer and those below it.
CORE_LAYERS = ('', 'model', 'physics', 'recording', 'run', 'ros')


def _core_layer(module: str) -> str:
    """'iceskate_sim.physics.simulation' -> 'physics'; a module at the package root -> ''."""
    parts = module.split('.')
    return parts[1] if len(parts) > 2 or (len(parts) == 2 and parts[1] in CORE_LAYERS) else ''


def _layer_violations(modules: dict[str, Path]) -> list[str]:
    """'importer -> imported' for every import of a core module from a higher layer."""
    found = set()
    for module, path in modules.items():
        for name in _imports(path, module):
            while name and name not in modules:  # 'pkg.mod.Name' -> 'pkg.mod'
                name = name.rpartition('.')[0]
            if name and name != 'iceskate_sim' and (
                    CORE_LAYERS.index(_core_layer(name)) > CORE_LAYERS.index(_core_layer(module))):
                found.add(f'{module} -> {name}')
    return sorted(found)


def test_the_core_shows_its_layers_and_imports_downward_only():
    modules = _modules('iceskate_sim')
    folders = {module.split('.')[1] for module in modules if module.count('.') >= 2}
    assert folders == set(CORE_LAYERS) - {''}, 'every folder of iceskate_sim is a named layer'
    assert _layer_violations(modules) == []


def test_the_layer_check_finds_an_upward_import(tmp_path):
    model = tmp_path / 'robot.py'
    model.write_text('def f():\n    from iceskate_sim.run.session import Session\n')
    session = tmp_path / 'session.py'
    session.write_text('from iceskate_sim.model.robot import Robot\n')
    assert _layer_violations({'iceskate_sim.model.robot': model,
                              'iceskate_sim.run.session': session}) == [
        'iceskate_sim.model.robot -> iceskate_sim.run.session']


def test_the_checks_find_a_cycle_and_a_deferred_import(tmp_path):
    assert _cycle({'a': {'b'}, 'b': {'c'}, 'c': {'a'}}) == ['a', 'b', 'c', 'a']
    assert _cycle({'a': {'b'}, 'b': set()}) is None
    probe = tmp_path / 'probe.py'
    probe.write_text('def f():\n    from gait_manager.parameters import SOURCES\n'
                     'from .session import Session\n')
    names = _imports(probe, 'iceskate_sim.probe')
    assert {'gait_manager.parameters', 'iceskate_sim.session.Session'} <= names
