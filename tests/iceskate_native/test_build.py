"""What keeps the cold build light (docs/usage.md, "Set-up time"), checked on the built
artefacts: one nanobind core that every extension module links, and no Pinocchio algorithm
compiled into the core a second time."""

import importlib
from pathlib import Path
import re
import shutil
import subprocess

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
CORE_LIBRARY = REPO_ROOT / 'ros_ws' / 'build' / 'iceskate_native' / 'libiceskate_native_core.a'
#: The project's extension modules.
MODULES = ('iceskate_native._kernel', 'visual_lifting._law', 'gait_manager._law')
#: A pass of a Pinocchio algorithm (its per-joint visitor step), e.g.
#: ``pinocchio::impl::ForwardKinematicZeroStep`` or ``JacobianCenterOfMassBackwardStep``.
ALGORITHM_STEP = re.compile(r'pinocchio::(?:impl::)?\w+(?:Forward|Backward|Zero|Order)Step\b')


def _tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        pytest.fail(f'{name} (binutils, beside the C++ compiler) is needed to read the build')
    return path


def test_every_extension_module_links_the_one_nanobind_core():
    for name in MODULES:
        module = importlib.import_module(name)
        dynamic = subprocess.run([_tool('readelf'), '--dynamic', module.__file__],
                                 capture_output=True, text=True, check=True, timeout=60).stdout
        needed = re.findall(r'\(NEEDED\)\s+Shared library: \[([^\]]+)\]', dynamic)
        assert [lib for lib in needed if 'nanobind' in lib] == ['libiceskate_nanobind.so'], (
            name, needed)
    with open('/proc/self/maps', encoding='ascii') as maps:
        cores = {line.split()[-1] for line in maps if 'libiceskate_nanobind' in line}
    assert len(cores) == 1, cores


def test_the_core_compiles_no_pinocchio_algorithm_of_its_own():
    """The core calls Pinocchio's algorithms with the argument types its library is compiled
    for; a call that would instantiate one again (15-20 s of compile each) leaves its visitor
    steps in the core's objects."""
    if not CORE_LIBRARY.is_file():
        pytest.fail(f'{CORE_LIBRARY} is missing: build the workspace first (make setup)')
    symbols = subprocess.run([_tool('nm'), '--demangle', '--defined-only', str(CORE_LIBRARY)],
                             capture_output=True, text=True, check=True, timeout=120).stdout
    steps = sorted({m.group(0) for m in ALGORITHM_STEP.finditer(symbols)})
    assert not steps, steps
