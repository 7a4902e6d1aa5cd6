"""The hybrid simulation on the native core: the discrete state and guard table (``hybrid``),
integrator settings (``integrators``), the native kernels seen from Python (``native``,
``native_control``) and the ``Simulator`` facade (``simulation``).
"""
