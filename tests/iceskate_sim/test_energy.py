"""Energy checks of single support, mode 1 (docs/model.md §14.2): no input, no stops.

Without damping the total energy is conserved to integrator accuracy. With Table 1 damping it
never increases, and what it loses is exactly the work of the damping torques, integrated
alongside the motion. The robot has no controller, so it falls over (the floor only holds the
support foot): gravity is conservative, which is all these tests need.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from iceskate_sim.model.dynamics import ContactState, DynamicsParameters
from iceskate_sim.model.modes import get_mode
from iceskate_sim.model.robot import N_COORDINATES
from oracle.dynamics import GaitDynamics

DURATION = 5.0  # s
SAMPLES = np.linspace(0.0, DURATION, 501)
MODE = get_mode(1)
ACTIVE = MODE.active
N = ACTIVE.size


def _initial_state(rng: np.random.Generator) -> np.ndarray:
    """A bent stance, perturbed by up to 0.05 rad, moving at up to 0.2 rad/s per joint."""
    q = np.zeros(N_COORDINATES)
    q[2:8] = (-0.05, 0.1, -0.05, 0.05, -0.1, 0.05)
    q[ACTIVE] += rng.uniform(-0.05, 0.05, N)
    v = rng.uniform(-0.2, 0.2, N)
    return np.concatenate([q[ACTIVE], v])


def _simulate(robot, damping: bool, x0: np.ndarray, make_dynamics):
    """Integrate mode 1 with zero input; the last state entry is the damping work [J].

    :param make_dynamics: ``make_dynamics(params)`` -> the dynamics routine (one formulation's).
    """
    dynamics = make_dynamics(DynamicsParameters(damping=damping, joint_limits=False))
    contact = ContactState(MODE, 'right', 'toe')
    d = robot.damping[ACTIVE] if damping else np.zeros(N)
    tau = np.zeros(N_COORDINATES)
    q = np.zeros(N_COORDINATES)
    v = np.zeros(N_COORDINATES)

    def rhs(_t, x):
        q[ACTIVE] = x[:N]
        v[ACTIVE] = x[N:2 * N]
        qdd = dynamics.evaluate(contact, q, v, tau).qdd
        return np.concatenate([x[N:2 * N], qdd[ACTIVE], [np.dot(d * x[N:2 * N], x[N:2 * N])]])

    def total_energy(x):
        q[ACTIVE] = x[:N]
        v[ACTIVE] = x[N:2 * N]
        return sum(dynamics.energy(contact, q, v))

    e0 = total_energy(x0)

    def runaway(_t, x):  # stop early (and fail) once the energy balance is clearly broken
        return abs(total_energy(x) + x[-1] - e0) - 1e-6 * abs(e0)

    runaway.terminal = True
    sol = solve_ivp(rhs, (0.0, DURATION), np.append(x0, 0.0), method='DOP853', rtol=1e-12,
                    atol=1e-12, t_eval=SAMPLES, events=runaway)
    assert sol.status == 0, f'energy balance broken at t = {sol.t[-1]:.3f} s ({sol.message})'
    energies = []
    for x in sol.y.T:
        q[ACTIVE] = x[:N]
        v[ACTIVE] = x[N:2 * N]
        energies.append(dynamics.energy(contact, q, v))
    kinetic, potential = np.array(energies).T
    return sol, kinetic, potential


def _check_energy_formula(robot, x0: np.ndarray) -> None:
    """energy() is 1/2 v'Mv and m g z_com, computed here from M and the CoM."""
    dynamics = GaitDynamics(robot)
    contact = ContactState(MODE, 'right', 'toe')
    q = np.zeros(N_COORDINATES)
    v = np.zeros(N_COORDINATES)
    q[ACTIVE] = x0[:N]
    v[ACTIVE] = x0[N:]
    kinetic, potential = dynamics.energy(contact, q, v)
    M = dynamics.mass_matrix(contact, q)
    assert kinetic == pytest.approx(0.5 * v[ACTIVE] @ M @ v[ACTIVE], rel=1e-12)
    z_com = dynamics.center_of_mass(contact, q)[2]
    assert potential == pytest.approx(robot.total_mass * 9.81 * z_com, rel=1e-12)


@pytest.mark.slow
def test_energy_is_conserved_without_damping(robot, rng, make_dynamics):
    x0 = _initial_state(rng)
    _check_energy_formula(robot, x0)
    sol, kinetic, potential = _simulate(robot, damping=False, x0=x0,
                                        make_dynamics=make_dynamics)
    energy = kinetic + potential
    drift = np.max(np.abs(energy - energy[0])) / abs(energy[0])
    assert drift <= 1e-8, f'relative energy drift {drift:.2e} over {DURATION} s'
    # not vacuous: the robot falls, turning a large share of its potential energy into motion
    assert np.max(kinetic) > 0.1 * abs(energy[0])
    assert np.max(kinetic) > 100.0 * kinetic[0]
    assert np.all(sol.y[-1] == 0.0)  # no damping work


@pytest.mark.slow
def test_energy_never_increases_with_damping(robot, rng, make_dynamics):
    x0 = _initial_state(rng)
    sol, kinetic, potential = _simulate(robot, damping=True, x0=x0,
                                        make_dynamics=make_dynamics)
    energy = kinetic + potential
    scale = abs(energy[0])
    increase = np.max(np.diff(energy))
    assert increase <= 1e-9 * scale, f'energy increased by {increase:.3e} J'
    assert energy[-1] < energy[0] - 1.0  # damping dissipated something
    # energy lost = work of the damping torques (power d_i qd_i^2, integrated with the motion)
    work = sol.y[-1]
    balance = energy + work - energy[0]
    assert np.max(np.abs(balance)) <= 1e-8 * scale, np.max(np.abs(balance))

