"""Joint commands: the sum a controller sends equals its sources applied one by one."""

import numpy as np
import pytest

from iceskate_sim.errors import SimulationError
from oracle.commands import ControllerCommand, JointCommand, held_of, held_of_controllers

RNG = np.random.default_rng(7)


def _random_pd() -> JointCommand:
    stiffness = RNG.uniform(0.0, 500.0, 18)
    stiffness[:3] = 0.0  # joints no impedance acts on: reference 0
    return JointCommand(RNG.normal(size=18), stiffness, RNG.uniform(0.0, 20.0, 18),
                        RNG.normal(size=18))


@pytest.mark.parametrize('kinds', [('plain',), ('pd',), ('plain', 'pd'), ('pd', 'plain', 'pd')])
def test_total_applies_the_sum_of_its_sources_at_any_state(kinds):
    commands = [_random_pd() if k == 'pd' else JointCommand(RNG.normal(size=18)) for k in kinds]
    total = JointCommand.total(commands)
    for _ in range(5):
        q, v = RNG.normal(size=18), RNG.normal(size=18)
        expected = sum(c.torque(q, v) for c in commands)
        np.testing.assert_allclose(total.torque(q, v), expected, rtol=1e-12, atol=1e-9)
        held = held_of(commands)
        np.testing.assert_allclose(held.torque(q, v), expected, rtol=1e-12, atol=1e-9)
    if kinds.count('pd') > 1:  # a weighted mean; 0 where no stiffness acts
        assert (total.reference[:3] == 0.0).all()


def test_total_of_one_impedance_source_keeps_its_gains_exactly():
    pd = _random_pd()
    plain = JointCommand(RNG.normal(size=18))
    total = JointCommand.total([plain, pd])
    for name in ('stiffness', 'damping', 'reference'):
        np.testing.assert_array_equal(getattr(total, name), getattr(pd, name))
    np.testing.assert_array_equal(total.effort, plain.effort + pd.effort)


def test_controller_command_records_each_source_at_the_state_answered():
    sources = {'posture': _random_pd(), 'yaw': JointCommand(RNG.normal(size=18))}
    q, v = RNG.normal(size=18), RNG.normal(size=18)
    answer = ControllerCommand.of(sources, q, v)
    assert list(answer.source_efforts) == ['posture', 'yaw']
    for name, command in sources.items():
        np.testing.assert_array_equal(answer.source_efforts[name], command.torque(q, v))
    np.testing.assert_allclose(held_of_controllers([answer]).torque(q, v),
                               sum(answer.source_efforts.values()), rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize('bad', [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize('field', ['effort', 'stiffness', 'damping', 'reference'])
def test_a_command_refuses_a_non_finite_entry(field, bad):
    values = {f: np.ones(18) for f in ('effort', 'stiffness', 'damping', 'reference')}
    values[field][7] = bad
    with pytest.raises(SimulationError, match=f'{field} has non-finite entries'):
        JointCommand(**values)


def test_a_command_refuses_opposite_infinities_and_takes_an_overflowing_finite_sum():
    with pytest.raises(SimulationError, match='non-finite'):
        JointCommand(np.r_[np.inf, -np.inf, np.zeros(16)])  # the sum is nan
    huge = JointCommand(np.full(18, 1e308))  # the sum overflows, every entry is finite
    assert np.isfinite(huge.effort).all()


@pytest.mark.parametrize('field', ['stiffness', 'damping'])
def test_a_command_refuses_a_negative_gain(field):
    values = {f: np.ones(18) for f in ('stiffness', 'damping', 'reference')}
    values[field][17] = -1e-12
    with pytest.raises(SimulationError, match='>= 0'):
        JointCommand(np.zeros(18), **values)
