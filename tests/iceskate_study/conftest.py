"""Fixtures of the sweep tests: small SPEC files of short runs; Ray stays on this machine."""

from collections.abc import Callable
import copy
import os
from pathlib import Path

import pytest
import yaml

# Ray never reports usage statistics from the tests (nor from anything they start).
os.environ['RAY_USAGE_STATS_ENABLED'] = '0'

#: A 2 x 2 grid of 0.5 s runs of the skate scene (no bag).
GRID = {
    'study': 'grid',
    'scene': 'skate',
    'overrides': {'duration': 0.5},
    'axes': {'floor.mu': [0.005, 0.01],
             'inputs.gait_manager.yaw.amplitude': {'linspace': [0.0, 30.0, 2]}},
    'metrics': ['steps', 'fell', 'forward_distance_m', 'wall_time_s', 'real_time_factor',
                'head_error_rms'],
}


@pytest.fixture
def write_spec(tmp_path: Path) -> Callable[..., Path]:
    """Return a writer of SPEC files: ``write_spec(mapping, name='spec.yaml') -> path``."""

    def write(spec: dict, name: str = 'spec.yaml') -> Path:
        path = tmp_path / name
        path.write_text(yaml.safe_dump(spec, sort_keys=False))
        return path

    return write


@pytest.fixture
def grid() -> dict:
    """A fresh copy of the 2 x 2 grid SPEC (mapping)."""
    return copy.deepcopy(GRID)
