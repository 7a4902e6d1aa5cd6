"""Static checks of the tree: ruff is clean, and the last colcon build printed no warnings."""

from pathlib import Path
import shutil
import subprocess
import sys

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
BUILD_LOGS = REPO_ROOT / 'ros_ws' / 'log' / 'latest_build'
OUR_PACKAGES = ('iceskate_interfaces', 'iceskate_native', 'iceskate_sim', 'visual_lifting',
                'gait_manager')


def _ruff_command() -> list[str]:
    """Return how to start ruff: the module of this interpreter, else a ruff on PATH."""
    probe = subprocess.run([sys.executable, '-m', 'ruff', '--version'], capture_output=True)
    if probe.returncode == 0:
        return [sys.executable, '-m', 'ruff']
    if shutil.which('ruff'):
        return ['ruff']
    pytest.skip('ruff is not installed (make setup installs it)')


def test_ruff_reports_nothing_on_sources_and_tests():
    # The configuration is pyproject.toml's [tool.ruff] at the repository root.
    result = subprocess.run(
        [*_ruff_command(), 'check', '--no-cache', 'ros_ws/src', 'tests'],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, f'ruff check failed:\n{result.stdout}{result.stderr}'


def test_last_colcon_build_printed_no_warnings_for_our_packages():
    if not BUILD_LOGS.is_dir():
        pytest.skip('ros_ws has not been built here (make setup builds it)')
    warnings = []
    for package in OUR_PACKAGES:
        for name in ('stderr.log', 'stdout.log'):
            log = BUILD_LOGS / package / name
            if not log.is_file():
                continue
            for line in log.read_text(errors='replace').splitlines():
                if 'warning' in line.lower():
                    warnings.append(f'{package}/{name}: {line}')
    assert not warnings, 'colcon build warnings:\n' + '\n'.join(warnings)
