"""ModelKinematics (what the native laws read of the model) equals the Python model's queries
on every support model and mode class; the native Observation refuses bad fields."""

import math

import numpy as np
import pinocchio as pin
import pytest

import iceskate_native
from iceskate_sim.model.dynamics import ContactState
from iceskate_sim.model.modes import MODES
from iceskate_sim.model.robot import PIVOTS, SIDES, load_robot
from iceskate_sim.physics.native import MODE_ROWS, NativeGaitDynamics, native_robot
from iceskate_sim.physics.native_control import native_kinematics
from oracle.dynamics import GaitDynamics

TOLERANCE = {'rtol': 1e-13, 'atol': 1e-13}
#: one mode of each support state: F-S, R-S, F-G, R-G (locked y0 and q1 columns differ)
MODE_NUMBERS = (17, 6, 3, 12)


@pytest.fixture(scope='module')
def robot():
    return load_robot()


@pytest.fixture(scope='module')
def kinematics(robot):
    return native_kinematics(robot)


def states(seed: int = 3):
    rng = np.random.default_rng(seed)
    for number in MODE_NUMBERS:
        for side in SIDES:
            for pivot in PIVOTS:
                yield number, side, pivot, rng.normal(0.0, 0.3, 18), rng.normal(0.0, 0.8, 18)


def test_the_queries_equal_the_python_model(robot, kinematics):
    dynamics = GaitDynamics(robot)
    for number, side, pivot, q, v in states():
        mode = MODES[number]
        key = (number, SIDES.index(side), PIVOTS.index(pivot))
        contact = ContactState(mode, side, pivot)
        psi, jacobian = dynamics.head_pose(contact, q)
        got_psi, got_jacobian = kinematics.head_pose(*key, q)
        np.testing.assert_allclose(got_psi, psi, **TOLERANCE)
        np.testing.assert_allclose(got_jacobian, jacobian, **TOLERANCE)
        gravity = np.zeros(18)
        gravity[mode.active] = dynamics.gravity_terms(contact, q)
        # the kernel's g(q) = -m J_com^T g0 against the Python model's gravity pass (RNEA):
        # two formulations, equal to rounding of the largest entry (y0's is 0 in the first)
        np.testing.assert_allclose(kinematics.gravity(*key, q), gravity, rtol=0.0,
                                   atol=1e-13 * max(1.0, float(np.max(np.abs(gravity)))))

        support = robot.support_model(side, pivot)
        model, data = support.model, support.new_data()
        pin.centerOfMass(model, data, q, v)
        position, velocity = data.com[0].copy(), data.vcom[0].copy()
        jacobian_y = pin.jacobianCenterOfMass(model, data, q)[1]
        got = kinematics.centre_of_mass(*key, q, v)
        for value, expected in zip(got, (position, velocity, jacobian_y), strict=True):
            np.testing.assert_allclose(value, expected, **TOLERANCE)

        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        heel = support.frame_ids['swing_heel']
        row = pin.getFrameJacobian(model, data, heel, pin.LOCAL_WORLD_ALIGNED)[2].copy()
        row[[i for i in (0, 1) if not (mode.y0_active, mode.q1_active)[i]]] = 0.0
        np.testing.assert_allclose(kinematics.swing_heel_z_row(*key, q), row, **TOLERANCE)
        for frame in ('head_top', 'swing_heel', 'support_toe', 'support_heel', 'pelvis_centre'):
            np.testing.assert_allclose(kinematics.frame_position(*key, q, frame),
                                       data.oMf[support.frame_ids[frame]].translation,
                                       **TOLERANCE)
            np.testing.assert_array_equal(
                kinematics.frame_offset(key[1], key[2], frame),
                model.frames[support.frame_ids[frame]].placement.translation)
        pin.forwardKinematics(model, data, q, v)
        for joint in range(18):
            pid = model.getJointId('y0' if joint == 0 else f'q{joint}')
            np.testing.assert_allclose(kinematics.joint_position(*key, q, joint),
                                       data.oMi[pid].translation, **TOLERANCE)
            np.testing.assert_allclose(
                kinematics.joint_velocity(*key, q, v, joint),
                pin.getVelocity(model, data, pid, pin.LOCAL_WORLD_ALIGNED).linear, **TOLERANCE)
            np.testing.assert_array_equal(kinematics.joint_placement(key[1], key[2], joint),
                                          model.jointPlacements[pid].translation)
    assert kinematics.total_mass == robot.total_mass


@pytest.mark.parametrize(('call', 'message'), [
    (lambda k: k.head_pose(21, 0, 0, np.zeros(18)), 'unknown gait mode 21'),
    (lambda k: k.gravity(1, 2, 0, np.zeros(18)), 'side and pivot must be 0 or 1'),
    (lambda k: k.joint_position(1, 0, 0, np.zeros(18), 18), 'joint 18 out of range'),
    (lambda k: k.frame_position(1, 0, 0, np.zeros(18), 'nose'), "unknown frame 'nose'"),
    (lambda k: k.head_pose(1, 0, 0, np.zeros(17)), 'q has 17 entries, expected 18'),
])
def test_bad_queries_are_value_errors(kinematics, call, message):
    with pytest.raises(ValueError, match=message):
        call(kinematics)


def test_the_four_models_and_a_known_mass_are_needed(robot):
    model = iceskate_native.load_model(robot.support_model('right', 'toe').model)
    frames = dict(robot.support_model('right', 'toe').frame_ids)
    modes = [(m.number, m.y0_active, m.q1_active, m.swing_sliding, [int(i) for i in m.active],
              list(m.constraints)) for m in MODES.values()]
    with pytest.raises(ValueError, match='four support models'):
        iceskate_native.ModelKinematics([model] * 3, [frames] * 3, modes, 30.0)
    with pytest.raises(ValueError, match='total_mass must be a finite mass > 0 kg'):
        iceskate_native.ModelKinematics([model] * 4, [frames] * 4, modes, math.nan)
    del frames['pelvis_centre']
    with pytest.raises(ValueError, match="unknown frame 'pelvis_centre'"):
        iceskate_native.ModelKinematics([model] * 4, [frames] * 4, modes, 30.0)


def test_the_kinematics_adopt_the_passes_of_the_same_models_only(robot, kinematics):
    """A control loop hands the laws' kinematics the dynamics' passes only over equal models
    (the runs that adopt them equal the nodes' runs bit for bit: test_control_loop.py)."""
    models, frames = native_robot(robot)
    dynamics = NativeGaitDynamics(robot).kernel
    assert kinematics.can_adopt_from(dynamics)
    heavier = []
    for side in SIDES:
        for pivot in PIVOTS:
            model = pin.Model(robot.support_model(side, pivot).model)
            inertia = model.inertias[model.getJointId('q8')]
            model.inertias[model.getJointId('q8')] = pin.Inertia(
                inertia.mass * 1.1, inertia.lever, inertia.inertia)
            heavier.append(iceskate_native.load_model(model))
    other = iceskate_native.ModelKinematics(heavier, frames, MODE_ROWS, robot.total_mass)
    assert not other.can_adopt_from(dynamics)
    assert iceskate_native.ModelKinematics(models, frames, MODE_ROWS,
                                           robot.total_mass).can_adopt_from(dynamics)


def _observation(**changes):
    fields = {'t': 0.5, 'q': np.zeros(18), 'v': np.zeros(18), 'mode': 1, 'side': 0, 'pivot': 0,
              'step_index': 0, 't_exchange': 0.0, 'heel_anchor_y': 0.0, 't_touchdown': math.nan}
    return iceskate_native.Observation(**{**fields, **changes})


@pytest.mark.parametrize(('changes', 'message'), [
    ({'q': np.zeros(17)}, 'q has 17 entries, expected 18'),
    ({'v': np.full(18, np.nan)}, r'v\[0\] is nan: every entry must be finite'),
    ({'t': math.inf}, "the observation's t, t_exchange and heel_anchor_y must be finite"),
    ({'t_touchdown': -math.inf}, 't_touchdown must be finite or NaN'),
    ({'mode': 0}, 'observation mode 0 is not a mode'),
    ({'pivot': 2}, 'side and pivot must be 0 or 1'),
])
def test_the_observation_refuses_bad_fields(changes, message):
    with pytest.raises(ValueError, match=message):
        _observation(**changes)
    assert math.isnan(_observation().t_touchdown)
