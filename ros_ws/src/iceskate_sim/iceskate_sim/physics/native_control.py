"""The native control laws seen from Python: ``native_kinematics`` (their robot model),
``native_observation`` (their input) and ``native_values`` (their answer as ``CommandValues``).
See docs/architecture.md, 'The control laws in C++'.
"""

from __future__ import annotations

import iceskate_native
from iceskate_sim.model.command import EMPTY, CommandValues
from iceskate_sim.model.observation import Observation
from iceskate_sim.model.robot import N_COORDINATES, PIVOTS, Robot
from iceskate_sim.physics.native import MODE_ROWS, native_robot


def native_kinematics(robot: Robot) -> iceskate_native.ModelKinematics:
    """The laws' view of ``robot`` (its own Pinocchio workspaces: one per thread)."""
    models, frames = native_robot(robot)
    return iceskate_native.ModelKinematics(models, frames, MODE_ROWS, robot.total_mass)


def native_observation(obs: Observation) -> iceskate_native.Observation:
    """``obs`` as the native laws take it."""
    return iceskate_native.Observation(
        obs.t, obs.q, obs.v, obs.mode, obs.a, PIVOTS.index(obs.pivot), obs.step_index,
        obs.t_exchange, obs.heel_anchor_y, obs.t_touchdown)


def native_values(controller: iceskate_native.Controller, obs: iceskate_native.Observation,
                  kinematics: iceskate_native.Kinematics) -> CommandValues:
    """What ``controller`` sends at ``obs`` (a native observation), as an EffortCommand carries
    it: the sum of its sources' commands (summed natively), each
    source's generalized force at (q, v) and its head target (if it steers one)."""
    # ``command``, not ``compute``: a controller written in Python overrides ``compute`` with
    # its own law; ``command`` is the checked answer of every controller
    values, impedance, steers, sources = controller.command(obs, kinematics)
    n = N_COORDINATES
    m = 4 * n if impedance else n  # the end of the total command
    head = m + n * len(sources)
    return CommandValues(values[:n], values[n:2 * n] if impedance else EMPTY,
                         values[2 * n:3 * n] if impedance else EMPTY,
                         values[3 * n:m] if impedance else EMPTY, values[m:head],
                         values[head:] if steers else EMPTY, tuple(sources))
