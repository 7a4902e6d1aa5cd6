"""The gait-manager sources, in C++ only (``src/``), as an ``iceskate_native.Controller``.

``GaitManagerController(params)`` takes a ``GaitManagerParameters`` (``gait_manager.parameters``);
its ``compute(obs, kinematics)`` gives the command of each enabled source, in ``SOURCES`` order
(see ``iceskate_sim.physics.native_control.native_values``); a command that is not finite raises
``GaitManagerError``. ``parameters`` shows the values the C++ sources hold, by field name.
"""

from gait_manager._law import GaitManagerController

__all__ = ['GaitManagerController']
