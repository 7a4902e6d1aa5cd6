"""Native (C++) kernels of the iceskate simulator, with their Python bindings.

The C++ code is the static library ``iceskate_native_core`` (``src/``, ``include/``) on
Pinocchio's C++ API; ``iceskate_native._kernel`` is its nanobind module. Models cross the
boundary as Pinocchio's binary archive: the same ``pinocchio.Model`` that Python built (for
instance ``iceskate_sim.model.robot.load_robot().support_model('right', 'toe').model``) is
deserialised once into a ``RobotModel`` on the C++ side::

    native = iceskate_native.load_model(support.model)

``Dynamics`` solves the paper's eq. (7) in every gait mode (``iceskate_sim.physics.native``
wraps it beside the model terms); ``HybridSimulator`` runs whole control periods on it (events,
transitions, projection, health checks), wrapped by ``iceskate_sim.physics.simulation.Simulator``.

The controller interface: a ``Controller`` (the control laws of visual_lifting and
gait_manager implement it in C++) answers an ``Observation``, reading the robot through a
``Kinematics``; ``ModelKinematics`` is that kinematics on the four support models
(``iceskate_sim.physics.native_control`` makes it from a ``Robot``). A ``ControlLoop`` runs many
control periods in one call: controllers, zero-order hold, pushes and ``HybridSimulator``
periods, returning the samples as arrays (``iceskate_sim.physics.simulation.NativeControlLoop``).
A Python subclass of ``Controller`` implements ``compute(obs, kinematics)`` and runs inside that
loop too (docs/usage.md, "Your own controller"); its failures are ``ControllerError``.

Messages: a ``CdrProgram`` writes CDR messages of one layout from columns of samples
(``encode_rows`` for a block of numpy columns, ``ControlLoop.live_messages`` for the live
sample); ``iceskate_sim.recording.cdr.Layout.program`` makes it from a message definition.

Bad input (wrong length, NaN, bytes that are no model) raises ``ValueError``; a failure inside a
kernel raises ``NativeError`` (a ``RuntimeError``; ``DivergenceError`` and ``ChatteringError`` are
its kinds for a run that left the physical range), which the simulator wraps in its own error.
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
