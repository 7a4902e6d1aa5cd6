"""The commands in Python, the test oracle of the native sum (``ControllerOutput::total``).

A source's ``JointCommand`` is ``effort + stiffness * (reference - q) - damping * v`` per
coordinate; a controller sums its sources' into one (``JointCommand.total``) and sends it with
each source's generalized force (``ControllerCommand``); the simulator holds the sum of its
controllers' (``held_of``). The shipped code holds a command as ``CommandValues`` only
(``values_of`` and ``command_of`` convert).
All arrays have 18 entries [y0, q1..q17]; units N m (N), N m/rad, N m s/rad, rad (m).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

import iceskate_native
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import EMPTY, CommandValues, HeldCommand, all_finite
from iceskate_sim.model.observation import Observation
from iceskate_sim.model.robot import N_COORDINATES
from iceskate_sim.physics.native_control import native_observation, native_values


def _vector(name: str, value: np.ndarray | None) -> np.ndarray:
    x = np.zeros(N_COORDINATES) if value is None else np.asarray(value, dtype=float)
    if x.shape != (N_COORDINATES,):
        raise SimulationError(f'joint command {name} must have {N_COORDINATES} entries, '
                              f'got shape {x.shape}')
    if not all_finite(x):
        raise SimulationError(f'joint command {name} has non-finite entries')
    return x


def _sum(arrays: Iterable[np.ndarray]) -> np.ndarray:
    """Entry-wise sum of equal-length arrays, added in order."""
    arrays = iter(arrays)
    total = next(arrays).copy()
    for x in arrays:
        total += x
    return total


@dataclass(frozen=True)
class JointCommand:
    """effort + stiffness * (reference - q) - damping * v, per coordinate."""

    effort: np.ndarray
    stiffness: np.ndarray | None = None
    damping: np.ndarray | None = None
    reference: np.ndarray | None = None

    def __post_init__(self) -> None:
        """Validate lengths, finiteness and non-negative gains."""
        object.__setattr__(self, 'effort', _vector('effort', self.effort))
        given = [x is not None for x in (self.stiffness, self.damping, self.reference)]
        if any(given) and not all(given):
            raise SimulationError('joint command impedance needs stiffness, damping and '
                                  'reference together')
        if all(given):
            for name in ('stiffness', 'damping', 'reference'):
                object.__setattr__(self, name, _vector(name, getattr(self, name)))
            if min(self.stiffness.tolist()) < 0.0 or min(self.damping.tolist()) < 0.0:
                raise SimulationError('joint command stiffness and damping must be >= 0')

    @property
    def has_impedance(self) -> bool:
        """Whether the command carries a joint impedance."""
        return self.stiffness is not None

    def torque(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The generalized force this command applies at (q, v) [N m]."""
        if not self.has_impedance:
            return self.effort.copy()
        return self.effort + self.stiffness * (self.reference - q) - self.damping * v

    @classmethod
    def total(cls, commands: Iterable[JointCommand]) -> JointCommand:
        """One command applying the sum of ``commands``: efforts, stiffnesses and dampings add
        up; the reference is the stiffness-weighted mean (0 where no stiffness acts)."""
        commands = list(commands)
        effort = _sum(c.effort for c in commands) if commands else None
        impedance = [c for c in commands if c.has_impedance]
        if not impedance:
            return cls(effort)
        if len(impedance) == 1:
            only = impedance[0]
            return cls(effort, only.stiffness, only.damping, only.reference)
        stiffness = _sum(c.stiffness for c in impedance)
        pull = _sum(c.stiffness * c.reference for c in impedance)
        reference = np.divide(pull, stiffness, out=np.zeros(N_COORDINATES),
                              where=stiffness > 0.0)
        return cls(effort, stiffness, _sum(c.damping for c in impedance), reference)


@dataclass(frozen=True)
class ControllerCommand:
    """What one controller sends for one control instant.

    :param command: the sum of its sources' commands (what the simulator applies).
    :param source_efforts: the generalized force [N m] each source applies at the state the
        controller answered, by source name, in the controller's order (what is recorded).
    :param head_target: the head-top target (y [m], z [m], pitch [rad]) it steers to; None.
    """

    command: JointCommand
    source_efforts: dict[str, np.ndarray]
    head_target: np.ndarray | None = None

    @classmethod
    def of(cls, commands: dict[str, JointCommand], q: np.ndarray, v: np.ndarray,
           head_target: np.ndarray | None = None) -> ControllerCommand:
        """The controller command of its sources' ``commands`` at the state (q, v) answered."""
        return cls(JointCommand.total(commands.values()),
                   {source: c.torque(q, v) for source, c in commands.items()}, head_target)


def values_of(answer: ControllerCommand) -> CommandValues:
    """The ``CommandValues`` of ``answer``."""
    command, efforts = answer.command, answer.source_efforts
    return CommandValues(command.effort, *((command.stiffness, command.damping, command.reference)
                                           if command.has_impedance else (EMPTY,) * 3),
                         np.concatenate(list(efforts.values())) if efforts else EMPTY,
                         EMPTY if answer.head_target is None else answer.head_target,
                         tuple(efforts))


def command_of(values: CommandValues) -> ControllerCommand:
    """The ControllerCommand of ``values`` (copies; checked as ``JointCommand`` checks)."""
    command = (JointCommand(values.effort.copy(), values.stiffness.copy(), values.damping.copy(),
                            values.reference.copy()) if values.stiffness.size
               else JointCommand(values.effort.copy()))
    rows = values.source_efforts.reshape(len(values.sources), N_COORDINATES).copy()
    return ControllerCommand(command, dict(zip(values.sources, rows, strict=True)),
                             values.head_target.copy() if values.head_target.size else None)


def held_of(commands: Iterable[JointCommand]) -> HeldCommand:
    """The held sum of ``commands`` (bias - stiffness * q - damping * v)."""
    bias = np.zeros(N_COORDINATES)
    stiffness = np.zeros(N_COORDINATES)
    damping = np.zeros(N_COORDINATES)
    for c in commands:
        bias += c.effort
        if c.has_impedance:
            bias += c.stiffness * c.reference
            stiffness += c.stiffness
            damping += c.damping
    return HeldCommand(bias, stiffness, damping)


def held_of_controllers(commands: Iterable[ControllerCommand]) -> HeldCommand:
    """The held sum of the controllers' commands (each already the sum of its sources)."""
    return held_of(c.command for c in commands)


def native_command(controller: iceskate_native.Controller, obs: Observation,
                   kinematics: iceskate_native.Kinematics) -> ControllerCommand:
    """What a native ``controller`` sends at ``obs``, as a ``ControllerCommand``."""
    return command_of(native_values(controller, native_observation(obs), kinematics))


def stack_commands(stack: object, obs: Observation) -> dict[str, ControllerCommand]:
    """What each controller node of a ``ControlStack`` sends at ``obs``, in summing order."""
    return {node: native_command(controller, obs, stack.kinematics)
            for node, controller in stack.controllers.items()}
