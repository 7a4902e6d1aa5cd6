"""Project-wide pytest fixtures: keep ROS 2 on loopback, isolate ROS logs, domains and contexts.

ROS tests call ``pytest.importorskip('rclpy')`` (directly or through the fixtures below), so the
pure (ROS-free) tests still run on a machine without ROS.
"""

from collections.abc import Callable, Iterator
import importlib.util
import itertools
import math
import os
from pathlib import Path
import sys

import numpy as np
import pytest

#: Repository root (tests/ is directly under it).
REPO_ROOT = Path(__file__).resolve().parents[1]
#: colcon workspace sources.
ROS_SRC = REPO_ROOT / 'ros_ws' / 'src'

def _add_unbuilt_packages_to_path() -> None:
    """Make our ament_python packages importable when the workspace is not built/sourced.

    Only packages that are not importable already are added, so a sourced workspace always wins.
    """
    for setup_py in sorted(ROS_SRC.glob('*/setup.py')):
        package_dir = setup_py.parent
        for module_dir in package_dir.iterdir():
            if (module_dir / '__init__.py').is_file() and module_dir.name not in ('test', 'tests'):
                if importlib.util.find_spec(module_dir.name) is None:
                    sys.path.append(str(package_dir))
                break


_add_unbuilt_packages_to_path()
# The test oracles (tests/oracle: the Python automaton, integrators and period loop the native
# core is checked against) import as ``oracle``; appended, so no tests/<pkg>/ folder shadows
# a real package.
sys.path.append(str(REPO_ROOT / 'tests'))

# ROS tests skip themselves where rclpy is missing (``pytest.importorskip``); where ROS must be
# there (CI: ICESKATE_REQUIRE_ROS=1) its absence stops the run instead of hiding those tests.
if os.environ.get('ICESKATE_REQUIRE_ROS') == '1' and importlib.util.find_spec('rclpy') is None:
    raise pytest.UsageError('ICESKATE_REQUIRE_ROS=1 but rclpy is not importable: the ROS tests '
                            'would all be skipped')

# Session-wide guard, set at import time so that it holds before any test creates a participant:
# Fast DDS stays on loopback (the shipped rule, ``loopback_dds``). Child processes inherit it
# through os.environ.
from iceskate_sim.ros.loopback import loopback_dds  # noqa: E402

loopback_dds(os.environ)
_DDS = {key: os.environ.get(key) for key in (
    'ROS_AUTOMATIC_DISCOVERY_RANGE', 'FASTRTPS_DEFAULT_PROFILES_FILE',
    'FASTDDS_DEFAULT_PROFILES_FILE')}

# Domain ids handed out in this run: start from the pid of the pytest command so that parallel
# runs on one machine (several checkouts) use different DDS domains; 4 runs in one domain
# cross-talk. The workers of one ``pytest -n N`` (pytest-xdist) share that start and take every
# N-th id from their own offset, so no two of them ever hand out the same id. Fast DDS accepts
# ids 0..232; 0 (the default) is never used.
_MAX_DOMAIN_ID = 232
_WORKER = os.environ.get('PYTEST_XDIST_WORKER')  # 'gw0', 'gw1', ... or unset
_WORKERS = int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1'))
_domain_ids = itertools.count(
    (os.getppid() if _WORKER else os.getpid()) + (int(_WORKER[2:]) if _WORKER else 0), _WORKERS)


@pytest.fixture(autouse=True, scope='session')
def _ros_dds_on_loopback() -> Iterator[None]:
    """Re-assert DDS on loopback for the whole session (a test may have changed it)."""
    loopback_dds(os.environ)
    yield
    loopback_dds(os.environ)


@pytest.fixture(autouse=True)
def _ros_log_dir(tmp_path_factory: pytest.TempPathFactory,
                 monkeypatch: pytest.MonkeyPatch) -> Path:
    """Give every test its own ``ROS_LOG_DIR`` (rclpy.init fails if it cannot create it)."""
    log_dir = tmp_path_factory.mktemp('ros_log')
    monkeypatch.setenv('ROS_LOG_DIR', str(log_dir))
    for key, value in _DDS.items():
        if value is not None:
            monkeypatch.setenv(key, value)
    return log_dir


@pytest.fixture
def ros_domain_id() -> int:
    """Return a ROS_DOMAIN_ID in 1..232 used by no other test of this run (pid-derived start).

    Pass it to ``rclpy.init(domain_id=...)`` and as ``ROS_DOMAIN_ID`` to child processes.
    """
    return 1 + next(_domain_ids) % _MAX_DOMAIN_ID


@pytest.fixture
def ros_env(ros_domain_id: int) -> dict[str, str]:
    """Return an environment for ROS child processes: this one plus the test's domain id."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(ros_domain_id)
    loopback_dds(env)
    return env


@pytest.fixture
def ros_context(ros_domain_id: int) -> Iterator[object]:
    """Yield a private, initialised ``rclpy.Context`` on the test's own domain.

    Skips the test when rclpy is not installed. The context is shut down afterwards even when
    the test fails.
    """
    rclpy = pytest.importorskip('rclpy')
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_domain_id)
    try:
        yield context
    finally:
        context.try_shutdown()


# ---------------------------------------------------------------- control-law tests
# Shared by tests/visual_lifting and tests/gait_manager (tests/iceskate_sim overrides
# ``dynamics`` with its own fixture).


@pytest.fixture(scope='session')
def dynamics() -> object:
    """GaitDynamics of the shipped URDF (one per test session)."""
    from iceskate_sim.model.robot import load_robot
    from oracle.dynamics import GaitDynamics
    return GaitDynamics(load_robot())


@pytest.fixture
def make_obs() -> Callable[..., object]:
    """Return a factory of Observations; defaults: bent-knee stance, mode 1, right support."""
    from iceskate_sim.model.observation import Observation
    from iceskate_sim.run.scene import standing_posture

    def make(t: float = 0.0, q: np.ndarray | None = None, v: np.ndarray | None = None,
             mode: int = 1, side: str = 'right', pivot: str = 'toe', step_index: int = 0,
             t_exchange: float = 0.0, heel_anchor_y: float = 0.0,
             t_touchdown: float = math.nan) -> Observation:
        bent = standing_posture('bent_knees', 0.05, 0.0)[0]  # docs/model.md §12
        return Observation(t, bent if q is None else np.asarray(q, dtype=float),
                           np.zeros(18) if v is None else np.asarray(v, dtype=float), mode,
                           side, pivot, step_index, t_exchange, heel_anchor_y, t_touchdown)

    return make


@pytest.fixture
def needs_fifo() -> None:
    """Skip the test where this process may not use SCHED_FIFO (not root, no rtprio limit)."""
    from iceskate_bringup.graph import realtime_scheduling
    from iceskate_sim.errors import SimulationError
    try:
        with realtime_scheduling(10):
            pass
    except SimulationError as exc:
        pytest.skip(str(exc))


# ---------------------------------------------------------------- observations of real runs
# Shared by the native-law tests of tests/visual_lifting and tests/gait_manager.

#: (scene, seconds simulated, every how many control periods an observation is kept)
SCENE_RUNS = (('skate', 6.0, 7), ('skate_no_yaw', 2.0, 11), ('walk', 6.0, 7), ('stand', 3.0, 9))


@pytest.fixture(scope='session')
def scene_observations() -> dict[str, list[object]]:
    """Observations of the shipped scenes' runs (headless, their own controllers), per scene:
    every n-th control instant and every instant whose mode, side, pivot or step just changed,
    so that each mode a scene passes through is in it."""
    from dataclasses import replace

    from iceskate_bringup.composition import ControlStack
    from iceskate_bringup.scene import load_scene
    from iceskate_sim.run.session import Session

    out: dict[str, list[object]] = {}
    for name, seconds, every in SCENE_RUNS:
        scene = replace(load_scene(name), duration=seconds)
        session = Session(scene)
        stack = ControlStack(scene, session.robot, session.observation())
        kept, last = [], None
        while not session.done:
            obs = session.observation()
            key = (obs.mode, obs.side, obs.pivot, obs.step_index)
            if session.periods % every == 0 or key != last:
                kept.append(obs)
            last = key
            session.run_periods(stack, 1)
        out[name] = kept
    return out
