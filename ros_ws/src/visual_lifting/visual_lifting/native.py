"""The visual-lifting law in C++ (``src/law.cpp``), as an ``iceskate_native.Controller``.

``VisualLiftingController(params)`` takes a ``VisualLiftingParameters``; its ``compute(obs,
kinematics)`` gives the command of source 'visual_lifting' and the head target psi_d (see
``iceskate_sim.native_control.native_command``). It equals ``law.visual_lifting``, the
readable reference (tests/visual_lifting/test_native.py).
"""

from visual_lifting._law import VisualLiftingController

__all__ = ['VisualLiftingController']
