"""GaitManagerController, the C++ sources behind iceskate_native's controller interface: the
enabled sources only, in their order, summed as JointCommand.total does; new parameters from
the next observation; the pace point's start; a command that is not finite."""

from dataclasses import replace

import numpy as np
import pytest

from gait_manager.errors import GaitManagerError
from gait_manager.native import GaitManagerController
from gait_manager.parameters import SOURCES
from iceskate_bringup.scene import load_scene, node_parameters
from iceskate_sim.physics.native_control import native_observation
from oracle.commands import JointCommand, native_command


def test_every_source_by_default_in_order(make_obs, command, parameters):
    obs = make_obs(t=1.2, t_exchange=1.0, mode=2)
    cmd = command(obs, parameters())
    assert tuple(cmd.source_efforts) == SOURCES
    for name, tau in cmd.source_efforts.items():
        assert tau.shape == (18,) and tau[0] == 0.0, name
    assert cmd.command.has_impedance  # the posture source's joint impedance
    np.testing.assert_allclose(cmd.command.torque(obs.q, obs.v),
                               sum(cmd.source_efforts.values()), rtol=1e-12, atol=1e-9)
    assert cmd.head_target is None


@pytest.mark.parametrize('enabled', [('yaw',), ('heel', 'arm_assist'),
                                     ('feedforward', 'yaw', 'heel', 'arm_assist'),
                                     ('weight_transfer', 'posture')])
def test_only_the_enabled_sources_are_sent(make_obs, command, parameters, enabled):
    obs = make_obs(t=1.2, t_exchange=1.0, mode=10, t_touchdown=1.1)
    cmd = command(obs, parameters(enabled))
    assert tuple(cmd.source_efforts) == tuple(s for s in SOURCES if s in enabled)
    alone = {s: command(obs, parameters((s,))).source_efforts[s] for s in enabled}
    for source, tau in cmd.source_efforts.items():
        np.testing.assert_array_equal(tau, alone[source])
    assert cmd.command.has_impedance == ('posture' in enabled)
    np.testing.assert_allclose(cmd.command.torque(obs.q, obs.v), sum(alone.values()),
                               rtol=1e-12, atol=1e-9)


def test_no_source_sends_an_empty_command(make_obs, command, parameters):
    cmd = command(make_obs(t=1.0), parameters(()))
    assert cmd.source_efforts == {} and not np.any(cmd.command.effort)


def test_new_parameters_apply_from_the_next_observation(make_obs, kinematics, parameters):
    obs = make_obs(t=2.4, t_exchange=2.0)
    controller = GaitManagerController(parameters(('yaw',)))
    before = native_command(controller, obs, kinematics).source_efforts['yaw'][8]
    controller.set_parameters(parameters(('yaw',), yaw={'amplitude': 10.0}))
    after = native_command(controller, obs, kinematics).source_efforts['yaw'][8]
    assert after == pytest.approx(before / 3.0, rel=1e-12) and before > 1.0


def test_the_pace_point_starts_at_the_head_of_t_0(make_obs, kinematics, dynamics, parameters,
                                                  bent):
    """The head top's y is latched at the first observation, again at every t = 0 (a restarted
    run), and kept in between."""
    def head_y(obs) -> float:
        return dynamics.frame_placement(obs.contact(), obs.q, 'head_top').translation[1]

    q = bent
    q[0] = 0.4  # 0.4 m further on the glide
    start, later = make_obs(t=0.0, mode=3), make_obs(t=3.0, q=q, mode=3)
    controller = GaitManagerController(parameters(('posture',)))
    assert controller.head_start_y is None
    native_command(controller, later, kinematics)  # joined late: starts where the head is
    assert controller.head_start_y == pytest.approx(head_y(later), abs=1e-12)
    native_command(controller, start, kinematics)
    native_command(controller, later, kinematics)
    assert controller.head_start_y == pytest.approx(head_y(start), abs=1e-12)
    assert head_y(later) - head_y(start) == pytest.approx(0.4, abs=1e-12)


def test_a_command_that_is_not_finite_is_a_gait_manager_error(make_obs, kinematics,
                                                              parameters):
    q = np.zeros(18)
    q[2:4] = 1e308  # phi_3 = q2 + q3 overflows: the trunk reference is not finite
    obs = native_observation(make_obs(t=1.0, t_exchange=0.5, q=q))
    balance = GaitManagerController(parameters(('posture',), posture={'reference': 'balance'}))
    with pytest.raises(GaitManagerError, match='^balance command is not finite at t = 1'):
        balance.compute(obs, kinematics)
    moving = GaitManagerController(parameters(('posture',), posture={'null_space': True}))
    with pytest.raises(GaitManagerError, match='^posture torque is not finite at t = 1'):
        moving.compute(obs, kinematics)


def test_the_sum_is_joint_command_total(make_obs, command, parameters):
    """Two impedance-free sources and the posture impedance add up as JointCommand.total."""
    obs = make_obs(t=1.3, t_exchange=1.0, mode=1, step_index=1)
    cmd = command(obs, parameters(('posture', 'arm_assist', 'yaw')))
    posture = command(obs, parameters(('posture',))).command
    others = [JointCommand(cmd.source_efforts[s]) for s in ('arm_assist', 'yaw')]
    total = JointCommand.total([posture, *others])
    for field in ('effort', 'stiffness', 'damping', 'reference'):
        np.testing.assert_allclose(getattr(cmd.command, field), getattr(total, field),
                                   rtol=1e-12, atol=1e-12)


#: the coordinates each impedance-free source may act on (docs/model.md §11.4-11.8)
REACH = {'feedforward': {1, 2, 3, 5, 6}, 'heel': {7}, 'arm_assist': set(range(11, 17)),
         'yaw': {8}, 'weight_transfer': set(range(1, 18))}


def test_the_runs_pass_through_every_kind_of_state(scene_observations):
    observations = [obs for run in scene_observations.values() for obs in run]
    assert {obs.gait_mode.swing for obs in observations} == {'A', 'Hs', 'Hp', 'Fs', 'Fp'}
    assert {obs.gait_mode.q1_active for obs in observations} == {False, True}
    assert {obs.gait_mode.y0_active for obs in observations} == {False, True}
    assert {obs.side for obs in observations} == {'right', 'left'}
    assert max(obs.step_index for obs in observations) >= 4
    assert any(obs.t_touchdown > obs.t_exchange for obs in observations)
    assert any(obs.step_index == 0 and obs.t_touchdown <= obs.t_exchange
               for obs in observations)


@pytest.mark.parametrize('scene', ['skate', 'skate_no_yaw', 'walk', 'stand'])
@pytest.mark.parametrize('reference', ['scene', 'moving', 'standing'])
def test_on_real_runs_every_source_acts_where_it_may(scene, reference, scene_observations,
                                                    kinematics):
    """On the states of the shipped scenes' runs (every mode they pass through), with each
    scene's parameters and every source on: finite commands, nothing on y0, each source only
    on its joints, the sum as JointCommand.total, no head target."""
    params = node_parameters(load_scene(scene))['gait_manager']
    posture = params.posture if reference == 'scene' else replace(params.posture,
                                                                  reference=reference)
    controller = GaitManagerController(replace(params, posture=posture,
                                               enabled=frozenset(SOURCES)))
    for obs in scene_observations[scene]:
        cmd = native_command(controller, obs, kinematics)
        assert tuple(cmd.source_efforts) == SOURCES
        for source, tau in cmd.source_efforts.items():
            assert np.all(np.isfinite(tau)) and tau[0] == 0.0, (source, obs.t)
            outside = [j for j in range(18) if j not in REACH.get(source, range(18))]
            assert not np.any(tau[outside]), (source, obs.t, obs.mode)
        np.testing.assert_allclose(cmd.command.torque(obs.q, obs.v),
                                   sum(cmd.source_efforts.values()), rtol=1e-9, atol=1e-8)
        assert cmd.head_target is None
