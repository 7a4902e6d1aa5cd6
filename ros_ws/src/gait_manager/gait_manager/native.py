"""The gait-manager sources, in C++ only (``src/``), as an ``iceskate_native.Controller``:
``GaitManagerController(params)``, one command per enabled source in ``SOURCES`` order.
See docs/architecture.md, 'The control laws in C++'.
"""

from gait_manager._law import GaitManagerController

__all__ = ['GaitManagerController']
