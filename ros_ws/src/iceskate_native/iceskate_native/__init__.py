"""Native (C++) kernels of the iceskate simulator: re-exports the nanobind module ``_kernel``
(``Dynamics``, ``HybridSimulator``, ``ControlLoop``, ``Controller``, ``ModelKinematics``,
``CdrProgram``, ``NativeError``, ...) and makes a model's C++ copy (``load_model``).
See this package's ``README.md`` and docs/architecture.md, 'The native core and its test oracle'.
"""

from ._kernel import (
    CdrProgram,
    ChatteringError,
    Controller,
    ControllerError,
    ControlLoop,
    DivergenceError,
    Dynamics,
    HybridSimulator,
    Kinematics,
    ModelKinematics,
    NativeError,
    Observation,
    RobotModel,
    encode_rows,
)

__all__ = ['CdrProgram', 'ChatteringError', 'ControlLoop', 'Controller', 'ControllerError',
           'DivergenceError', 'Dynamics', 'HybridSimulator', 'Kinematics', 'ModelKinematics',
           'NativeError', 'Observation', 'RobotModel', 'encode_rows', 'load_model',
           'model_bytes']


def model_bytes(model) -> bytes:
    """Return Pinocchio's binary archive of ``model`` (a ``pinocchio.Model``)."""
    import pinocchio  # deferred: importing the kernel alone does not load Pinocchio's Python side

    buffer = pinocchio.serialization.StreamBuffer()
    model.saveToBinary(buffer)
    return bytes(buffer.tobytes())


def load_model(model) -> RobotModel:
    """Return the C++ copy of ``model`` (a ``pinocchio.Model``), to pass to the kernels."""
    return RobotModel.from_bytes(model_bytes(model))
