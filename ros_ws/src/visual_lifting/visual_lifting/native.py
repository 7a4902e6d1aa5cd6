"""The visual-lifting law, eqs. (8)-(9), in C++ only (``src/law.cpp``), as an
``iceskate_native.Controller``: ``VisualLiftingController(params)``, the command of source
'visual_lifting' and the head target psi_d. See docs/architecture.md, 'The control laws in C++'.
"""

from visual_lifting._law import VisualLiftingController

__all__ = ['VisualLiftingController']
