"""The visual-lifting law, eqs. (8)-(9), in C++ only (``src/law.cpp``), as an
``iceskate_native.Controller``.

``VisualLiftingController(params)`` takes a ``VisualLiftingParameters``
(``visual_lifting.parameters``); its ``compute(obs, kinematics)`` gives the command of source
'visual_lifting' and the head target psi_d (see
``iceskate_sim.physics.native_control.native_values``).
``parameters`` shows the values the C++ law holds, by field name.
"""

from visual_lifting._law import VisualLiftingController

__all__ = ['VisualLiftingController']
