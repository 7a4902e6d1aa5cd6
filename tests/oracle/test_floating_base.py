"""Cross-check (docs/model.md §4.8): the support-rooted eq. (7) against the free-flyer formulation.

Every mode, both support sides, both pivots, both slide directions of the support foot and of
the swing heel, with mu = 0.3 so that friction matters, with the soft stops off and engaged.
The error measure is max|a - b| / max(1, max|reference|) per quantity.
"""

import itertools
import zlib

import numpy as np
import pytest

from iceskate_sim.model.dynamics import ContactState, DynamicsParameters
from iceskate_sim.model.modes import MODES, get_mode
from iceskate_sim.model.robot import JOINT_LIMITS, N_COORDINATES
from oracle.dynamics import GaitDynamics
from oracle.floating_base import FloatingBaseDynamics

MU = 0.3
TOLERANCE = 1e-9
SLIDE_DIRECTIONS = [(1.0, 1.0), (-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0)]  # (support, heel)


@pytest.fixture(scope='module')
def solvers(robot):
    """(GaitDynamics, FloatingBaseDynamics) for the stops off and engaged."""
    out = {}
    for limits in ('off', 'engaged'):
        params = DynamicsParameters(mu=MU, joint_limits=limits == 'engaged')
        out[limits] = (GaitDynamics(robot, params), FloatingBaseDynamics(robot, params))
    return out


def _relative_error(actual, reference) -> float:
    actual, reference = np.atleast_1d(actual), np.atleast_1d(reference)
    return float(np.max(np.abs(actual - reference)) / max(1.0, np.max(np.abs(reference))))


def _push_into_stops(q: np.ndarray, rng: np.random.Generator) -> None:
    """Move every joint that has a soft stop 0.005..0.05 rad beyond one of its two stops.

    That is 50..500 N m of stop torque. Deeper (2000 N m on a 0.4 kg hand) makes qdd ~ 1e5 and
    N_s a small difference of kN-sized terms, which no formulation resolves to 1e-9 of N_s.
    """
    for i, (lower, upper) in JOINT_LIMITS.items():
        depth = rng.uniform(0.005, 0.05)
        q[i] = lower - depth if rng.random() < 0.5 else upper + depth


@pytest.mark.parametrize('limits', ['off', 'engaged'])
@pytest.mark.parametrize(('side', 'pivot'), list(itertools.product(('right', 'left'),
                                                                   ('toe', 'heel'))))
@pytest.mark.parametrize('number', sorted(MODES))
def test_formulations_agree(solvers, random_state, number, side, pivot, limits):
    reduced, floating = solvers[limits]
    mode = get_mode(number)
    seed = zlib.crc32(f'{number}-{side}-{pivot}-{limits}'.encode())
    rng = np.random.default_rng(seed)
    worst = {}
    for support_dir, heel_dir in SLIDE_DIRECTIONS:
        contact = ContactState(mode, side, pivot, heel_anchor_y=rng.uniform(-0.3, 0.3),
                               support_slide_dir=support_dir, heel_slide_dir=heel_dir)
        q, v = random_state(mode, rng=rng, scale=0.5, speed=1.5)
        if limits == 'engaged':
            _push_into_stops(q, rng)
        tau = rng.uniform(-20.0, 20.0, N_COORDINATES)
        tau[11:] = rng.uniform(-2.0, 2.0, N_COORDINATES - 11)
        result = reduced.evaluate(contact, q, v, tau)
        passive = -reduced.robot.damping * v
        engaged = not np.allclose(result.applied[2:], tau[2:] + passive[2:], rtol=0, atol=1e-9)
        assert engaged == (limits == 'engaged')
        other = floating.evaluate(contact, q, v, result.applied)
        pairs = {'qdd': (other.qdd, result.qdd),
                 'multipliers': (other.multipliers, result.multipliers),
                 'N_s': (other.support_normal, result.support_normal),
                 'F_y': (other.support_friction, result.support_friction)}
        for name, (got, reference) in pairs.items():
            error = _relative_error(got, reference)
            worst[name] = max(worst.get(name, 0.0), error)
            assert error <= TOLERANCE, (
                f'mode {number} {side}/{pivot} dirs {support_dir:+}/{heel_dir:+}: {name} '
                f'relative error {error:.2e}\nfloating {got}\nreduced  {reference}')
        # friction really acts: a gliding support foot feels mu N_s, a sliding heel mu f_nz
        # (N_s and F_y come from an RNEA pass after the solve: agree to solver accuracy)
        if mode.y0_active:
            assert result.support_friction == pytest.approx(
                -MU * support_dir * result.support_normal, rel=1e-9, abs=1e-9)
        if mode.swing_sliding:
            assert result.heel_friction == pytest.approx(
                -MU * heel_dir * result.multipliers[0], rel=1e-12)  # f_nz
    assert worst  # every case compared something


def test_friction_changes_the_answer(robot, rng, random_state):
    """Guard against a vacuous cross-check: mu and the slide directions matter in mode 16."""
    mode = get_mode(16)
    q, v = random_state(mode)
    tau = np.zeros(N_COORDINATES)
    results = {}
    for mu, dirs in ((0.0, (1.0, 1.0)), (MU, (1.0, 1.0)), (MU, (-1.0, -1.0))):
        dynamics = GaitDynamics(robot, DynamicsParameters(mu=mu))
        contact = ContactState(mode, 'right', 'toe', support_slide_dir=dirs[0],
                               heel_slide_dir=dirs[1])
        results[(mu, dirs)] = dynamics.evaluate(contact, q, v, tau).qdd
    values = list(results.values())
    assert _relative_error(values[0], values[1]) > 1e-3
    assert _relative_error(values[1], values[2]) > 1e-3
