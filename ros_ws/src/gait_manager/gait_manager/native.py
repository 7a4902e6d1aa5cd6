"""The gait-manager sources in C++ (``src/``), as an ``iceskate_native.Controller``.

``GaitManagerController(params)`` takes a ``GaitManagerParameters``; its ``compute(obs,
kinematics)`` gives the command of each enabled source, in ``law.SOURCES`` order (see
``iceskate_sim.native_control.native_command``). It equals ``law.gait_manager_commands``, the
readable reference (tests/gait_manager/test_native.py); a command that is not finite raises
``GaitManagerError``.
"""

from gait_manager._law import GaitManagerController

__all__ = ['GaitManagerController']
