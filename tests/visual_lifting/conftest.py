"""Helpers of the visual-lifting tests: the shipped C++ law called through its binding."""

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from iceskate_sim.model.observation import Observation
from iceskate_sim.model.robot import load_robot
from iceskate_sim.physics.native_control import native_kinematics, native_observation
from oracle.commands import ControllerCommand, native_command
from visual_lifting.native import VisualLiftingController
from visual_lifting.parameters import VisualLiftingParameters


@pytest.fixture(scope='session')
def kinematics() -> object:
    """The laws' native kinematics of the shipped URDF (one per test session)."""
    return native_kinematics(load_robot())


@pytest.fixture
def lift(kinematics) -> Callable[..., ControllerCommand]:
    """``lift(obs, origin=None, **fields)``: what a fresh VisualLiftingController with
    ``fields`` changed sends at ``obs``, its target's origin psi(0) latched at ``origin`` (an
    observation) first if given."""
    def command(obs: Observation, origin: Observation | None = None,
                **fields: Any) -> ControllerCommand:
        controller = VisualLiftingController(VisualLiftingParameters.from_dict(fields))
        if origin is not None:
            controller.latch_origin(native_observation(origin), kinematics)
        return native_command(controller, obs, kinematics)

    return command


@pytest.fixture
def pulled(lift, dynamics) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """``pulled(obs, error, **fields)``: (torque [N m], head target) of the law at ``obs`` (t
    > 0) with its target set ``error`` = (dy [m], dz [m], dpitch [rad]) away from the head
    pose psi of the core's kinematics: origin psi(0) = psi, y_d = y_H(0) + v_d t, z_d and
    pitch_d given, no saturation unless ``max_dy`` is passed."""
    def law(obs: Observation, error: tuple[float, float, float],
            **fields: Any) -> tuple[np.ndarray, np.ndarray]:
        psi, _ = dynamics.head_pose(obs.contact(), obs.q)
        settings = {'desired_y': 'moving', 'v_d': error[0] / obs.t, 'z_d': psi[1] + error[1],
                    'pitch_d': psi[2] + error[2], 'max_dy': None, **fields}
        cmd = lift(obs, obs, **settings)
        assert list(cmd.source_efforts) == ['visual_lifting']
        assert not cmd.command.has_impedance
        return cmd.source_efforts['visual_lifting'], cmd.head_target

    return law
