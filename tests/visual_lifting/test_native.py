"""The native visual-lifting law (C++, visual_lifting.native) equals the Python reference (law.py)
on observations of the shipped scenes' runs, for every target option; its binding refuses bad
parameters in one sentence."""

from dataclasses import asdict, replace
from types import SimpleNamespace

import numpy as np
import pytest

from iceskate_bringup.scene import load_scene, node_parameters
from iceskate_sim.command import ControllerCommand, JointCommand
from iceskate_sim.native_control import native_command, native_kinematics, native_observation
from iceskate_sim.robot import load_robot
from visual_lifting.law import VisualLiftingParameters, head_origin, visual_lifting
from visual_lifting.native import VisualLiftingController

TOLERANCE = {'rtol': 1e-12, 'atol': 1e-12}

#: target and torque options beside each scene's own parameters
VARIANTS = {
    'scene': {},
    'follow': {'desired_y': 'follow'},
    'fixed, z_d and pitch_d set': {'desired_y': 'fixed', 'z_d': 1.5, 'pitch_d': 0.1},
    'unsaturated, no joint-1 torque': {'max_dy': None, 'joint1_torque': False},
    'moving stance': {'shift_y1': 0.1, 'shift_z1': 0.03, 'shift_time1': 0.6, 'shift_y2': 0.1,
                      'shift_time2': 0.5},
    'stance steps (0 s ramps)': {'shift_y1': 0.05, 'shift_z1': 0.02, 'shift_time1': 0.0,
                                 'shift_y2': 0.05, 'shift_time2': 0.0},
    'some joints, other gains': {'joints': (1, 3, 9, 17), 'kp': (5.0, 100.0, 300.0), 'v_d': -0.2},
}


@pytest.fixture(scope='module')
def kinematics():
    return native_kinematics(load_robot())


def reference_command(obs, dynamics, params, origin):
    task = visual_lifting(obs, dynamics, params, origin)
    return ControllerCommand.of({'visual_lifting': JointCommand(task.tau)}, obs.q, obs.v,
                                task.psi_d)


@pytest.mark.parametrize('variant', sorted(VARIANTS))
@pytest.mark.parametrize('scene', ['skate', 'skate_no_yaw', 'walk', 'stand'])
def test_the_native_law_equals_the_reference_on_real_runs(scene, variant, scene_observations,
                                                          dynamics, kinematics):
    params = replace(node_parameters(load_scene(scene))['visual_lifting'], **VARIANTS[variant])
    observations = scene_observations[scene]
    origin = head_origin(observations[0], dynamics)
    controller = VisualLiftingController(params)
    for obs in observations:
        expected = reference_command(obs, dynamics, params, origin)
        got = native_command(controller, obs, kinematics)
        assert list(got.source_efforts) == ['visual_lifting']
        np.testing.assert_allclose(got.source_efforts['visual_lifting'],
                                   expected.source_efforts['visual_lifting'], **TOLERANCE)
        np.testing.assert_allclose(got.command.effort, expected.command.effort, **TOLERANCE)
        assert not got.command.has_impedance
        np.testing.assert_allclose(got.head_target, expected.head_target, **TOLERANCE)
    np.testing.assert_allclose(controller.origin, origin, **TOLERANCE)


def test_the_origin_is_latched_at_t_0_or_the_first_state_and_kept_on_new_parameters(
        scene_observations, dynamics, kinematics):
    observations = scene_observations['skate']
    later = observations[len(observations) // 2]
    controller = VisualLiftingController(VisualLiftingParameters())
    assert controller.origin is None
    controller.compute(native_observation(later), kinematics)  # first state seen: not t = 0
    np.testing.assert_allclose(controller.origin, head_origin(later, dynamics), **TOLERANCE)
    controller.set_parameters(VisualLiftingParameters(v_d=0.1))
    np.testing.assert_allclose(controller.origin, head_origin(later, dynamics), **TOLERANCE)
    controller.compute(native_observation(observations[0]), kinematics)  # t = 0: again
    np.testing.assert_allclose(controller.origin, head_origin(observations[0], dynamics),
                               **TOLERANCE)


def _fields(**changes) -> SimpleNamespace:
    """The fields of the default parameters with ``changes``, unchecked by the dataclass."""
    return SimpleNamespace(**{**asdict(VisualLiftingParameters()), **changes})


@pytest.mark.parametrize(('changes', 'message'), [
    ({'kp': (1.0, 2.0)}, 'kp has 2 entries, expected 3'),
    ({'kp': (1.0, float('nan'), 2.0)}, 'kp has a non-finite entry'),
    ({'v_d': float('nan')}, 'v_d is nan: every parameter must be finite'),
    ({'z_d': float('inf')}, 'z_d is inf: every parameter must be finite'),
    ({'joints': (1, 18)}, 'joints holds joint 18, expected joints 1-17'),
    ({'desired_y': 'sideways'}, "desired_y 'sideways' is not one of moving, follow, fixed"),
    ({'joint1_torque': 1}, 'joint1_torque must be true or false'),
    ({'v_d': 'fast'}, 'v_d must be a number'),
])
def test_the_binding_refuses_bad_parameters_in_one_sentence(changes, message):
    with pytest.raises(ValueError, match=message):
        VisualLiftingController(_fields(**changes))
    fields = _fields()
    del fields.pitch_d
    with pytest.raises(ValueError, match='the parameters have no field pitch_d'):
        VisualLiftingController(fields)
