"""Fixtures and inputs of the physics tests, shared by the oracle's own tests (tests/oracle) and
the tests of the shipped physics (tests/iceskate_sim): the robot, a dynamics object, seeded
randomness, the approximate-comparison helper.

Each folder's conftest.py imports the fixtures it uses from here (pytest registers a fixture a
conftest imports), so both folders share one definition.

``assert_close`` is the one helper for approximate comparisons: every call states its tolerance.
``random_state(mode)`` draws a state that respects the mode (locked velocities 0, q1 = 0 when
q1 is locked) and, by default, stays inside the soft joint stops of docs/model.md §2.6.
"""

from collections.abc import Callable
import itertools

import numpy as np
import pytest

from iceskate_sim.model.dynamics import DynamicsParameters
from iceskate_sim.model.modes import GaitMode, get_mode
from iceskate_sim.model.robot import JOINT_LIMITS, N_COORDINATES, Q1, Y0, Robot, load_robot
from oracle.dynamics import GaitDynamics

SEED = 20190605  # ROBOMECH 2019
#: The bent-knee double-support posture of docs/model.md §12, q2..q7 = (-a, 2a, -a, a, -2a, a).
BENT_KNEE_A = 0.05


def bent_knee_posture(a: float = BENT_KNEE_A) -> np.ndarray:
    """Return the 18-vector of the bent-knee stance (both soles flat, swing heel on the floor)."""
    q = np.zeros(N_COORDINATES)
    q[2:8] = (-a, 2 * a, -a, a, -2 * a, a)
    return q


def _assert_close(actual, expected, *, atol: float = 0.0, rtol: float = 0.0,
                  what: str = 'value') -> None:
    """Assert max|actual - expected| <= atol + rtol * max(1, max|expected|).

    The relative part is scaled by the reference's largest magnitude (at least 1), the error
    measure the cross-checks of this suite use. At least one tolerance must be given.
    """
    assert atol > 0.0 or rtol > 0.0, 'assert_close needs an explicit tolerance'
    actual = np.asarray(actual, dtype=float)
    expected = np.asarray(expected, dtype=float)
    assert actual.shape == expected.shape, f'{what}: shape {actual.shape} != {expected.shape}'
    assert np.all(np.isfinite(actual)), f'{what}: non-finite entries {actual}'
    error = float(np.max(np.abs(actual - expected))) if actual.size else 0.0
    scale = max(1.0, float(np.max(np.abs(expected)))) if expected.size else 1.0
    bound = atol + rtol * scale
    assert error <= bound, (
        f'{what}: max abs error {error:.3e} > {bound:.3e} (atol {atol:g}, rtol {rtol:g}, '
        f'reference scale {scale:.3e})\nactual   {actual}\nexpected {expected}')


@pytest.fixture
def assert_close() -> Callable[..., None]:
    """The approximate-comparison helper (see ``_assert_close``)."""
    return _assert_close


@pytest.fixture(scope='session')
def robot() -> Robot:
    """The humanoid loaded from the package URDF (four support-rooted models)."""
    return load_robot()


@pytest.fixture
def dynamics(robot: Robot) -> GaitDynamics:
    """Gait dynamics with the default parameters (ice mu, damping and soft stops on)."""
    return GaitDynamics(robot, DynamicsParameters())


@pytest.fixture
def rng() -> np.random.Generator:
    """A freshly seeded generator per test, so every test sees the same numbers every run."""
    return np.random.default_rng(SEED)


def make_random_state(mode: GaitMode | int, rng: np.random.Generator, *,
                      scale: float = 0.4, speed: float = 1.0, within_limits: bool = True,
                      base: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Draw (q, v) for ``mode``.

    Joints 2..17 are ``base`` (default: the bent-knee stance) plus U(-scale, scale), clipped
    0.05 rad inside the soft stops when ``within_limits``; q1 ~ U(-0.3, 0.3) when active, else
    0; y0 ~ U(-1, 1) always (a locked y0 keeps its value). Velocities ~ U(-speed, speed) on the
    active coordinates and exactly 0 on the locked ones.
    """
    mode = get_mode(mode) if not isinstance(mode, GaitMode) else mode
    q = bent_knee_posture() if base is None else np.array(base, dtype=float)
    q[2:] += rng.uniform(-scale, scale, N_COORDINATES - 2)
    if within_limits:
        for i, (lower, upper) in JOINT_LIMITS.items():
            q[i] = np.clip(q[i], lower + 0.05, upper - 0.05)
    q[Y0] = rng.uniform(-1.0, 1.0)
    q[Q1] = rng.uniform(-0.3, 0.3) if mode.q1_active else 0.0
    v = np.zeros(N_COORDINATES)
    v[mode.active] = rng.uniform(-speed, speed, mode.n_coordinates)
    return q, v


@pytest.fixture
def random_state(rng: np.random.Generator) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """``random_state(mode, **options)`` -> (q, v) from the test's seeded generator."""
    def draw(mode: GaitMode | int, **options) -> tuple[np.ndarray, np.ndarray]:
        return make_random_state(mode, options.pop('rng', rng), **options)
    return draw


# ------------------------------------------------------------- inputs of the eq. (7) tests
def random_torques(rng: np.random.Generator) -> np.ndarray:
    """Input torques: +-20 N m on the legs and trunk, +-2 N m on arms and neck."""
    tau = rng.uniform(-20.0, 20.0, N_COORDINATES)
    tau[11:] = rng.uniform(-2.0, 2.0, N_COORDINATES - 11)
    return tau


def mode_cases(modes, sides=('right', 'left'), pivots=('toe', 'heel')):
    """Every (mode number, side, pivot) of ``modes``."""
    return list(itertools.product(modes, sides, pivots))
