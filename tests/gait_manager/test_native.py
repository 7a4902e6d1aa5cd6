"""The native gait-manager sources (C++, gait_manager.native) equal the Python reference
(law.gait_manager_commands) on observations of the shipped scenes' runs, in every mode those
runs pass through, for every source and option; the binding refuses bad parameters in one
sentence, and a command that is not finite is a GaitManagerError."""

from dataclasses import asdict, replace
from types import SimpleNamespace

import numpy as np
import pytest

from gait_manager.errors import GaitManagerError
from gait_manager.law import SOURCES, GaitManagerParameters, gait_manager_commands
from gait_manager.native import GaitManagerController
from iceskate_bringup.scene import load_scene, node_parameters
from iceskate_sim.command import ControllerCommand
from iceskate_sim.native_control import native_command, native_kinematics, native_observation
from iceskate_sim.robot import load_robot

TOLERANCE = {'rtol': 1e-12, 'atol': 1e-12}


def assert_close(got: np.ndarray, expected: np.ndarray, what: str) -> None:
    """Equal to 1e-12 of the vector's size: a null-space projection cancels terms of ~100 N m
    into ~0.1 N m, and two SVDs differ in the last bits of those terms."""
    scale = max(1.0, float(np.abs(expected).max()))
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12 * scale, err_msg=what)
ALL = frozenset(SOURCES)

#: options beside each scene's own parameters: {block: {field: value}}, 'enabled' top level
VARIANTS = {
    'scene': {},
    'every source': {'enabled': ALL},
    'posture moving': {'enabled': ALL, 'posture': {'reference': 'moving'}},
    'posture moving, null space': {
        'enabled': ALL, 'posture': {'reference': 'moving', 'null_space': True,
                                    'pelvis_pitch': 0.1}},
    'posture standing, no gravity': {
        'enabled': ALL, 'posture': {'reference': 'standing', 'gravity_compensation': False}},
    'posture standing, null space, no joints': {
        'posture': {'reference': 'standing', 'null_space': True, 'joints': (),
                    'gravity_joints': (2, 5, 17)}},
    'posture moving, stance steps': {
        'posture': {'reference': 'moving', 'shift_time1': 0.0, 'shift_time2': 0.0}},
    'balance, no ankle strategy, no blend, push steps': {
        'posture': {'reference': 'balance'},
        'balance': {'com_stiffness': 0.0, 'com_damping': 0.0, 'blend': 0.0, 'push_ramp': 0.0}},
    'balance with a glide': {
        'posture': {'reference': 'balance'}, 'balance': {'glide_time': 0.2}},
    'balance with a bounded front knee step': {
        'posture': {'reference': 'balance'}, 'balance': {'front_knee_step': 0.05}},
    'balance with drive and pace': {
        'posture': {'reference': 'balance'}, 'balance': {'drive': 15.0, 'pace_gain': 120.0}},
    'balance with drive and a bounded pace': {
        'posture': {'reference': 'balance'},
        'balance': {'drive': 15.0, 'pace_gain': 120.0, 'feedback_limit': 4.0}},
    'weight transfer ramp': {
        'weight_transfer': {'rule': 'ramp', 'moment_arm': 0.05, 'joint1_torque': True}},
    'weight transfer ramp, steps, no moment, no q1': {
        'weight_transfer': {'rule': 'ramp', 'ramp_time': 0.0, 'start_ramp': 0.0,
                            'moment_arm': 0.0, 'joint1_torque': False}},
    'weight transfer com, floor': {
        'weight_transfer': {'rule': 'com', 'share_min': 0.3, 'ramp_time': 0.2}},
    'weight transfer com, no ramp': {
        'weight_transfer': {'rule': 'com', 'share_min': 0.3, 'ramp_time': 0.0}},
    'weight transfer com, heel share': {
        'weight_transfer': {'rule': 'com', 'share_min': 0.6, 'heel_share': 0.3}},
    'feedforward without q1, heel without ramp': {
        'enabled': ALL, 'feedforward': {'joint1_torque': False}, 'heel': {'ramp_time': 0.0}},
    'arm release': {'enabled': ALL, 'arm_assist': {'release_time': 0.5,
                                                   'release_damping': 3.0}},
    'phases A': {'enabled': ALL, 'yaw': {'phase': 'A'},
                 'arm_assist': {'phase': 'A', 'off_from_step_index': 10}},
    'phases B clipped': {'enabled': ALL, 'yaw': {'phase': 'B_clipped'},
                         'arm_assist': {'phase': 'B_clipped', 'off_from_step_index': 0}},
    'no source': {'enabled': frozenset()},
}


def variant(scene: str, name: str) -> GaitManagerParameters:
    params = node_parameters(load_scene(scene))['gait_manager']
    changes = dict(VARIANTS[name])
    enabled = changes.pop('enabled', params.enabled)
    blocks = {block: replace(getattr(params, block), **fields)
              for block, fields in changes.items()}
    return replace(params, enabled=enabled, **blocks)


@pytest.fixture(scope='module')
def kinematics():
    return native_kinematics(load_robot())


def test_the_runs_pass_through_every_kind_of_state(scene_observations):
    observations = [obs for run in scene_observations.values() for obs in run]
    swings = {obs.gait_mode.swing for obs in observations}
    assert swings == {'A', 'Hs', 'Hp', 'Fs', 'Fp'}
    assert {obs.gait_mode.q1_active for obs in observations} == {False, True}
    assert {obs.gait_mode.y0_active for obs in observations} == {False, True}
    assert {obs.side for obs in observations} == {'right', 'left'}
    assert max(obs.step_index for obs in observations) >= 4
    assert any(obs.t_touchdown > obs.t_exchange for obs in observations)
    assert any(obs.step_index == 0 and obs.t_touchdown <= obs.t_exchange
               for obs in observations)


@pytest.mark.parametrize('name', sorted(VARIANTS))
@pytest.mark.parametrize('scene', ['skate', 'skate_no_yaw', 'walk', 'stand'])
def test_the_native_sources_equal_the_reference_on_real_runs(scene, name, scene_observations,
                                                             dynamics, kinematics):
    params = variant(scene, name)
    controller = GaitManagerController(params)
    for obs in scene_observations[scene]:
        got = native_command(controller, obs, kinematics)
        expected = ControllerCommand.of(
            gait_manager_commands(obs, dynamics, params, controller.head_start_y), obs.q, obs.v)
        assert list(got.source_efforts) == list(expected.source_efforts)
        for source, effort in expected.source_efforts.items():
            assert_close(got.source_efforts[source], effort,
                         f'{source} at t = {obs.t}, mode {obs.mode}')
        assert got.command.has_impedance == expected.command.has_impedance
        for field in ('effort', 'stiffness', 'damping', 'reference'):
            if getattr(expected.command, field) is not None:
                assert_close(getattr(got.command, field), getattr(expected.command, field),
                             f'{field} at t = {obs.t}, mode {obs.mode}')
        assert got.head_target is None


def test_new_parameters_apply_from_the_next_observation(scene_observations, dynamics,
                                                        kinematics):
    obs = scene_observations['skate'][-1]
    controller = GaitManagerController(GaitManagerParameters())
    params = variant('skate', 'phases A')
    controller.set_parameters(params)
    got = native_command(controller, obs, kinematics)
    expected = ControllerCommand.of(gait_manager_commands(obs, dynamics, params), obs.q, obs.v)
    np.testing.assert_allclose(got.source_efforts['yaw'], expected.source_efforts['yaw'],
                               **TOLERANCE)


def test_the_pace_point_starts_at_the_head_of_t_0(scene_observations, dynamics, kinematics):
    """The controller latches the head top's y at its first observation and again at every
    t = 0 (a restarted run), and keeps it in between."""
    run = scene_observations['skate']
    assert run[0].t == 0.0 and run[-1].t > 1.0

    def head_y(obs) -> float:
        return dynamics.frame_placement(obs.contact(), obs.q, 'head_top').translation[1]

    controller = GaitManagerController(variant('skate', 'balance with drive and pace'))
    assert controller.head_start_y is None
    native_command(controller, run[-1], kinematics)  # joined late: starts where the head is
    assert controller.head_start_y == pytest.approx(head_y(run[-1]), abs=1e-12)
    native_command(controller, run[0], kinematics)
    native_command(controller, run[-1], kinematics)
    assert controller.head_start_y == pytest.approx(head_y(run[0]), abs=1e-12)
    assert abs(head_y(run[-1]) - head_y(run[0])) > 0.1


def test_a_command_that_is_not_finite_is_a_gait_manager_error(make_obs, kinematics):
    params = variant('skate', 'scene')  # posture with the 'balance' reference
    q = np.zeros(18)
    q[2:4] = 1e308  # phi_3 = q2 + q3 overflows: the trunk reference is not finite
    obs = native_observation(make_obs(t=1.0, t_exchange=0.5, q=q))
    with pytest.raises(GaitManagerError, match='balance command is not finite at t = 1'):
        GaitManagerController(params).compute(obs, kinematics)


def _fields(**blocks) -> SimpleNamespace:
    """The default parameters with some fields of some blocks changed, unchecked."""
    params = GaitManagerParameters()
    out = {name: SimpleNamespace(**asdict(getattr(params, name)))
           for name in ('posture', 'balance', 'feedforward', 'weight_transfer', 'heel',
                        'arm_assist', 'yaw')}
    for block, fields in blocks.items():
        for field, value in fields.items():
            setattr(out[block], field, value)
    return SimpleNamespace(**out, enabled=params.enabled)


@pytest.mark.parametrize(('blocks', 'message'), [
    ({'balance': {'speed': float('nan')}}, 'balance.speed is nan: every parameter must be finite'),
    ({'posture': {'joints': (2, 18)}}, 'posture.joints holds joint 18, expected joints 2-17'),
    ({'posture': {'gravity_joints': (1,)}}, 'posture.gravity_joints holds joint 1'),
    ({'posture': {'reference': 'sitting'}},
     "posture.reference 'sitting' is not one of moving, standing, balance"),
    ({'yaw': {'phase': 'C'}}, "yaw.phase 'C' is not one of A, B, B_clipped"),
    ({'weight_transfer': {'share': float('inf')}}, 'weight_transfer.share is inf'),
    ({'arm_assist': {'off_from_step_index': -1}},
     'arm_assist.off_from_step_index is -1, expected >= 0'),
    ({'heel': {'stiffness': None}}, 'heel.stiffness must be a number'),
])
def test_the_binding_refuses_bad_parameters_in_one_sentence(blocks, message):
    with pytest.raises(ValueError, match=message):
        GaitManagerController(_fields(**blocks))


def test_the_binding_refuses_an_unknown_source():
    fields = _fields()
    fields.enabled = frozenset({'posture', 'dance'})
    with pytest.raises(ValueError, match="enabled holds 'dance', which is no gait-manager source"):
        GaitManagerController(fields)
