"""The native (C++) kernel seen from Python: eq. (7) (``NativeGaitDynamics``) and many control
periods with the controllers (``NativeControlLoop``); ``simulation.Simulator`` runs the periods.
Errors come back as ``SimulationError``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

import iceskate_native
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import CommandValues
from iceskate_sim.model.dynamics import DynamicsParameters, ModelTerms
from iceskate_sim.model.modes import MODES
from iceskate_sim.model.robot import JOINT_LIMITS, PIVOTS, SIDES, SOLE_HEEL_Y, SOLE_TOE_Y, Robot
from iceskate_sim.physics.hybrid import COP_BAND, FORCE_BAND, MOMENT_BAND, TOE_SCUFF

if TYPE_CHECKING:
    from iceskate_sim.physics.simulation import Simulator

#: The guards' dead bands and sole geometry, in the kernel's order.
GUARD_CONSTANTS = (COP_BAND, FORCE_BAND, MOMENT_BAND, TOE_SCUFF, SOLE_TOE_Y, SOLE_HEEL_Y)


def _native_robot(robot: Robot) -> tuple[list, list[dict[str, int]]]:
    """The four support models in the kernel's order (side * 2 + pivot) and their frames."""
    keys = [(side, pivot) for side in SIDES for pivot in PIVOTS]
    models = [iceskate_native.load_model(robot.models[key].model) for key in keys]
    frames = [dict(robot.models[key].frame_ids) for key in keys]
    return models, frames


class NativeGaitDynamics(ModelTerms):
    """Eq. (7) in C++ (``kernel``: ``iceskate_native.Dynamics``, which the ``Simulator``
    integrates) beside the model terms (one kernel per instance: not thread-safe)."""

    def __init__(self, robot: Robot, params: DynamicsParameters | None = None) -> None:
        super().__init__(robot, params)
        p = self.params
        models, frames = _native_robot(robot)
        modes = [(m.number, m.y0_active, m.q1_active, m.swing_sliding,
                  [int(i) for i in m.active], list(m.constraints)) for m in MODES.values()]
        limits = [(i, lo, hi) for i, (lo, hi) in sorted(JOINT_LIMITS.items())]
        try:
            self.kernel = iceskate_native.Dynamics(
                models, frames, modes, robot.damping, robot.total_mass, limits,
                (p.mu, p.baumgarte, p.joint_limits, p.limit_stiffness, p.limit_damping,
                 p.damping))
        except ValueError as exc:
            raise SimulationError(f'native dynamics: {exc}') from None


class NativeControlLoop:
    """Many control periods in one C++ call (``iceskate_native.ControlLoop``): at each control
    instant the native ``controllers`` answer the observation through ``kinematics``, the sum of
    their commands and the active push are held over the period, and ``periods`` advances; the
    samples come back as arrays (``Session.run_periods``: the headless runner's
    ``ControlStack`` answers in C++, without Python in between).

    Without controllers it holds the commands of controller nodes received from outside (the
    ROS graph): ``receive`` each node's command, ``hold`` one period (its sample kept in the
    block), ``take_block`` the samples held; ``live`` is the live view of the current state.
    A sample holds what the recording encodes, among it the /tf transforms of the URDF's links
    (``Robot.tf_frames``).

    :param simulator: the simulator it advances (which mirrors the kernel after each block).
    :param kinematics: the controllers' view of the robot (``native_control.native_kinematics``;
        None without controllers).
    :param controllers: the native laws, in summing order.
    :param pushes: the scene's pushes (``start``, ``duration``, ``frame``, ``force``).
    :param head_origin: psi at t = 0, the head target recorded while no controller steers one.
    :param inbox: the sources of each controller node whose commands ``receive`` takes, in
        summing order.
    :raises SimulationError: for an unknown push frame or a non-finite value.
    """

    def __init__(self, simulator: Simulator, kinematics: iceskate_native.Kinematics | None,
                 controllers: list[iceskate_native.Controller], pushes: tuple,
                 head_origin: np.ndarray, inbox: tuple[tuple[str, ...], ...] = ()) -> None:
        self._simulator = simulator
        rows = [(p.start, p.duration, p.frame, np.asarray(p.force, dtype=float)) for p in pushes]
        try:
            self._kernel = iceskate_native.ControlLoop(
                simulator.kernel, kinematics, list(controllers), rows,
                np.asarray(head_origin, dtype=float), simulator.robot.tf_frames,
                [list(s) for s in inbox])
        except (ValueError, TypeError) as exc:
            raise SimulationError(f'native control loop: {exc}') from None

    def run(self, periods: int) -> tuple[dict, Exception | None]:
        """Up to ``periods`` control periods: (their samples as ``iceskate_native.ControlLoop.run``
        returns them, what stopped the block early or None). A failure of the physics comes as
        the ``SimulationError`` that ``Simulator.advance`` raises; a controller's own error
        (e.g. a non-finite command) as it was raised."""
        block = self._kernel.run(periods)
        error: Exception | None = None
        if self._kernel.failed:
            try:
                self._kernel.raise_error()
            except Exception as exc:  # noqa: BLE001 - handed back beside the samples taken
                error = self._simulator.failure(exc) if self._kernel.physics_failed else exc
        return block, error

    def receive(self, index: int, values: CommandValues) -> None:
        """Keep the command ``values`` of the inbox's controller node ``index`` for the next
        ``hold`` (its sources' efforts in the inbox's order).

        :raises SimulationError: naming the field with a wrong size, a non-finite value or a
            negative gain (the command is not kept).
        """
        try:
            self._kernel.receive(index, *values[:6])
        except (ValueError, TypeError) as exc:
            raise SimulationError(f'command: {exc}') from None

    def hold(self, clear: bool = True) -> None:
        """One control period holding the commands received (``iceskate_native.ControlLoop.hold``;
        ``clear``: forget them afterwards).

        :raises SimulationError: where the physics failed (``Simulator.failure``).
        """
        if not self._kernel.hold(clear):
            try:
                self._kernel.raise_error()
            except Exception as exc:  # noqa: BLE001 - the kernel's failure, in our words
                raise self._simulator.failure(exc) from None

    def forget(self) -> None:
        """Drop the commands received (none is held until the next ``receive``)."""
        self._kernel.forget()

    @property
    def block_size(self) -> int:
        """Samples held and not taken yet."""
        return self._kernel.block_size

    def take_block(self) -> dict:
        """The samples held since the last call, as ``run`` returns them."""
        return self._kernel.take_block()

    def live(self) -> dict:
        """The live view of the current state, what the simulator publishes at t_k before the
        commands of t_k exist: one sample with ``take_block``'s keys (one row), its dynamics
        under the inputs held over the last period, the held input's generalized force at the
        state as the one source ``held`` and that period's head target."""
        return self._kernel.live()

    def live_fill(self) -> tuple[int, int, int]:
        """Take ``live``'s sample in the loop for ``live_messages``; its (mode, index of the
        latest transition or -1, sources present)."""
        return self._kernel.live_fill()

    def live_messages(self, columns: Sequence[str],
                      programs: Sequence[iceskate_native.CdrProgram]) -> list[bytes]:
        """The bytes of one message per program (``cdr.Layout.program``, numbering
        ``columns``) of the sample ``live_fill`` took."""
        return self._kernel.live_messages(list(columns), list(programs))
