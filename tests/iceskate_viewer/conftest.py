"""A short recorded run for the viewer's tests: the fast skate gait (both support sides, flat
and tipped soles, support exchanges), its trajectory.npz and its bag."""

from dataclasses import replace
import pathlib

import pytest

FAST_SKATE = pathlib.Path(__file__).resolve().parents[1] / 'data' / 'fast_skate.yaml'


@pytest.fixture(scope='session')
def skate_run(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """The output folder of 1.2 s of the fast skate gait, run headless."""
    from iceskate_bringup.runner import run
    from iceskate_bringup.scene import load_scene
    out = tmp_path_factory.mktemp('viewer') / 'fast_skate'
    run(replace(load_scene(FAST_SKATE), duration=1.2), out, progress=False, picture=False)
    return out
