"""The native control laws seen from Python: ``native_kinematics`` (their robot model),
``native_observation`` (their input) and ``native_values`` (their answer as ``CommandValues``).
See docs/architecture.md, 'The control laws in C++'.
"""

from __future__ import annotations

import iceskate_native
from iceskate_sim.model.command import EMPTY, CommandValues
from iceskate_sim.model.modes import MODES
from iceskate_sim.model.observation import Observation
from iceskate_sim.model.robot import N_COORDINATES, PIVOTS, SIDES, Robot


def native_kinematics(robot: Robot) -> iceskate_native.ModelKinematics:
    """The laws' view of ``robot`` (its own Pinocchio workspaces: one per thread)."""
    keys = [(side, pivot) for side in SIDES for pivot in PIVOTS]  # index side * 2 + pivot
    models = [iceskate_native.load_model(robot.models[key].model) for key in keys]
    frames = [dict(robot.models[key].frame_ids) for key in keys]
    modes = [(m.number, m.y0_active, m.q1_active, m.swing_sliding, [int(i) for i in m.active],
              list(m.constraints)) for m in MODES.values()]
    return iceskate_native.ModelKinematics(models, frames, modes, robot.total_mass)


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
