"""Numerical-stability stress cases, short versions (the long ones: benchmarks/stress.py).

Every case must behave (finite state, constraint residual within the simulator's bound) or stop
cleanly, with ``SimulationError`` or ``Simulator.ended`` and a reason: never NaN, never a hang
(each case runs under a wall-clock alarm and a pytest timeout). The cases and their contract
live in ``benchmarks/stress.py`` so that the stress command and this suite run the same code.
"""

import importlib.util
from pathlib import Path
import sys

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]


def _load_stress():
    name = 'iceskate_benchmarks_stress'
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, REPO_ROOT / 'benchmarks' / 'stress.py')
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses resolve their annotations through sys.modules
    spec.loader.exec_module(module)
    return module


stress = _load_stress()
CASE_WALL_LIMIT = 20.0  # s, alarm per case (the slowest takes ~3 s on the 2-core machine)
# The cases that used to run away: explicit methods beyond their stability limit, a 20 ms
# implicit step and an impact at a near-singular posture. Their state grows without NaN, and the
# run used to stop as a physical end (toe-first touchdown, flight). Now the speed bound and the
# check of every physical end (rk45 at rtol 1e-8 from the period's start must reach an end too)
# report the explicit, singular and stiff ones as divergences, which this test holds them to;
# the 20 ms implicit step's end stands: from the state its steps reached, rk45 touches down
# toe first too.
RUNAWAY = ('step_large_implicit', 'step_large_rk4', 'step_large_symplectic',
                      'near_straight_double', 'stiff_damping_explicit')
DIVERGED = RUNAWAY[1:]


def _run(name, robot):
    case = stress.case_by_name(name)
    return case, stress.run_case(case, case.duration, robot, CASE_WALL_LIMIT)


@pytest.mark.timeout(60)
@pytest.mark.parametrize('name', stress.FAST)
def test_case_behaves_or_stops_with_a_reason(name, robot):
    case, result = _run(name, robot)
    problems = stress.check(case, result)
    assert not problems, f'{name} ({case.description}): {problems}\n{result.line()}'
    if result.outcome == 'completed':
        assert result.sim_time == pytest.approx(case.duration, abs=1e-9)
    if name not in RUNAWAY:
        assert result.plausible, f'ran away without SimulationError: {result.line()}'


@pytest.mark.timeout(60)
@pytest.mark.parametrize('name', RUNAWAY)
def test_runaway_state_is_reported_as_divergence(name, robot):
    _, result = _run(name, robot)
    assert result.plausible, result.line()
    if name in DIVERGED:
        assert result.outcome == 'error' and 'diverged' in result.reason, result.line()


def test_the_contract_can_fail():
    # A NaN outcome, an unbounded residual and a missing reason all break the contract.
    case = stress.case_by_name('kp_x10')
    good = dict(name='x', outcome='completed', reason=None, sim_time=0.5, wall=1.0, periods=500,
                transitions=0, events={}, energy_start=0.0, energy_end=0.0,
                energy_excursion=0.0, max_residual=0.0, residual_bound=1e-3, finite=True)
    assert stress.check(case, stress.Outcome(**good)) == []
    for change in ({'outcome': 'nan', 'finite': False}, {'max_residual': 1.0},
                   {'outcome': 'hang'}, {'outcome': 'error', 'reason': None}):
        assert stress.check(case, stress.Outcome(**{**good, **change})), change


@pytest.mark.timeout(30)
def test_alarm_turns_a_hang_into_an_outcome():
    import time
    with pytest.raises(stress.Hang):
        with stress.alarm(0.2):
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:  # bounded stand-in for a hang
                pass
