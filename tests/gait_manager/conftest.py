"""Helpers of the gait-manager tests: the shipped C++ sources called through their binding
(``GaitManagerController(params).compute``), one source at a time."""

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from gait_manager.native import GaitManagerController
from gait_manager.parameters import GaitManagerParameters
from iceskate_sim.model.observation import Observation
from iceskate_sim.model.robot import load_robot
from iceskate_sim.physics.native_control import native_kinematics, native_observation
from iceskate_sim.run.scene import standing_posture
from oracle.commands import ControllerCommand, native_command


def _parameters(enabled: tuple[str, ...] | None = None, **blocks: dict[str, Any]
               ) -> GaitManagerParameters:
    """GaitManagerParameters with ``blocks`` ({block: {field: value}}) changed, through the
    schema's own checks; ``enabled`` the sources (default: all)."""
    raw: dict[str, Any] = dict(blocks)
    if enabled is not None:
        raw['enabled'] = list(enabled)
    return GaitManagerParameters.from_dict(raw)


@pytest.fixture
def bent() -> np.ndarray:
    """A fresh copy of the bent-knee standing posture of docs/model.md §12 (a = 0.05 rad)."""
    return standing_posture('bent_knees', 0.05, 0.0)[0].copy()


@pytest.fixture
def parameters() -> Callable[..., GaitManagerParameters]:
    """``parameters(enabled=None, **blocks)``: GaitManagerParameters with ``blocks`` ({block:
    {field: value}}) changed, through the schema's checks; ``enabled`` (default all)."""
    return _parameters


@pytest.fixture(scope='session')
def kinematics() -> object:
    """The laws' native kinematics of the shipped URDF (one per test session)."""
    return native_kinematics(load_robot())


@pytest.fixture
def command(kinematics) -> Callable[..., ControllerCommand]:
    """``command(obs, params, start=None)``: what a fresh controller with ``params`` sends at
    ``obs``; with ``start`` (an observation at t = 0) the controller sees that one first, so
    its pace point starts at that head."""
    def compute(obs: Observation, params: GaitManagerParameters,
                start: Observation | None = None) -> ControllerCommand:
        controller = GaitManagerController(params)
        if start is not None:
            controller.compute(native_observation(start), kinematics)
        return native_command(controller, obs, kinematics)

    return compute


@pytest.fixture
def torque(command) -> Callable[..., np.ndarray]:
    """``torque(source, obs, **blocks)``: the generalized force [N m] source ``source`` alone
    applies at ``obs`` with ``blocks`` changed (its share of the command)."""
    def source_torque(source: str, obs: Observation, **blocks: dict[str, Any]) -> np.ndarray:
        cmd = command(obs, _parameters((source,), **blocks))
        assert list(cmd.source_efforts) == [source]
        return cmd.source_efforts[source]

    return source_torque


def _central_difference(f: Callable[[np.ndarray], float], q: np.ndarray,
                        direction: np.ndarray, h: float = 1e-6) -> float:
    return (f(q + h * direction) - f(q - h * direction)) / (2.0 * h)


@pytest.fixture
def central_difference() -> Callable[..., float]:
    """``central_difference(f, q, direction, h=1e-6)``: d f(q + s direction)/ds at s = 0."""
    return _central_difference
