"""Gait-manager entry point: every gait-manager torque source, ROS-free (model-spec §7, §13-14).

``gait_manager_torques`` returns one 18-vector [N m] per *enabled* source and computes nothing
for the others, so a scene pays only for what it uses. Sources:

* 'posture': posture stabiliser with the moving stance reference (``posture``), or the
  walking stabiliser (``balance``) when ``posture.reference`` is 'balance';
* 'feedforward': swing hip/knee pulses and push-off (``feedforward``);
* 'weight_transfer': -J_c^T f_des after heel strike (``feedforward``);
* 'heel': heel-first landing input on the swing ankle (``heel``);
* 'arm_assist': shoulder sinusoid and elbow/wrist PD of steps 1-3 (``arm_assist``);
* 'yaw': torso-yaw input of eq. (10) (``yaw``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from gait_manager._params import zeros
from gait_manager.arm_assist import ArmAssistParameters, arm_assist_torque
from gait_manager.balance import BalanceParameters, balance_command
from gait_manager.errors import GaitManagerError
from gait_manager.feedforward import (
    FeedforwardParameters,
    WeightTransferParameters,
    feedforward_torque,
    weight_transfer_torque,
)
from gait_manager.heel import HeelParameters, heel_torque
from gait_manager.posture import PostureParameters, head_offset_of, posture_command
from gait_manager.yaw import YawParameters, yaw_torque
from iceskate_sim.command import JointCommand
from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.observation import Observation

SOURCES = ('posture', 'feedforward', 'weight_transfer', 'heel', 'arm_assist', 'yaw')
_BLOCKS = {'posture': PostureParameters, 'balance': BalanceParameters,
           'feedforward': FeedforwardParameters,
           'weight_transfer': WeightTransferParameters, 'heel': HeelParameters,
           'arm_assist': ArmAssistParameters, 'yaw': YawParameters}


def _enabled(value: Any) -> frozenset[str]:
    if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
        raise GaitManagerError(f'enabled must be a list of sources among {SOURCES}, '
                               f'got {value!r}')
    items = list(value)
    for item in items:
        if item not in SOURCES:
            raise GaitManagerError(f'enabled: unknown source {item!r}; expected among {SOURCES}')
    return frozenset(items)


@dataclass(frozen=True)
class GaitManagerParameters:
    """All gait-manager parameter blocks and the set of enabled sources (default: all)."""

    posture: PostureParameters = field(default_factory=PostureParameters)
    balance: BalanceParameters = field(default_factory=BalanceParameters)
    feedforward: FeedforwardParameters = field(default_factory=FeedforwardParameters)
    weight_transfer: WeightTransferParameters = field(default_factory=WeightTransferParameters)
    heel: HeelParameters = field(default_factory=HeelParameters)
    arm_assist: ArmAssistParameters = field(default_factory=ArmAssistParameters)
    yaw: YawParameters = field(default_factory=YawParameters)
    enabled: frozenset[str] = frozenset(SOURCES)

    def __post_init__(self) -> None:
        """Validate the blocks' types and the enabled set (GaitManagerError naming the key)."""
        for name, cls in _BLOCKS.items():
            if not isinstance(getattr(self, name), cls):
                raise GaitManagerError(f'{name} must be a {cls.__name__}, '
                                       f'got {getattr(self, name)!r}')
        object.__setattr__(self, 'enabled', _enabled(self.enabled))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> GaitManagerParameters:
        """Build from a nested mapping {block: {key: value}, 'enabled': [sources]}.

        Missing blocks keep their defaults; unknown keys and bad values raise
        GaitManagerError with a message naming the key (e.g. 'posture.stiffness').
        """
        if not isinstance(d, Mapping):
            raise GaitManagerError(f'gait-manager parameters must be a mapping, got {d!r}')
        known = [f.name for f in fields(cls)]
        kwargs: dict[str, Any] = {}
        for key, value in d.items():
            if key not in known:
                raise GaitManagerError(f'unknown key {key!s}; expected one of {known}')
            if key == 'enabled':
                kwargs[key] = _enabled(value)
            else:
                kwargs[key] = _BLOCKS[key].from_dict(value)
        return cls(**kwargs)


def gait_manager_commands(obs: Observation, dynamics: GaitDynamics,
                          params: GaitManagerParameters) -> dict[str, JointCommand]:
    """Return {source: JointCommand} for the enabled sources only, in SOURCES order.

    The posture stabiliser carries a joint impedance (its PD runs at the physics rate); the
    other sources are torques held over the control period. ``dynamics`` is used only by
    'posture' and 'weight_transfer'.
    """
    out: dict[str, JointCommand] = {}
    enabled = params.enabled
    if 'posture' in enabled:
        posture = params.posture
        out['posture'] = (balance_command(obs, dynamics, params.balance, posture.yaw_stiffness,
                                          posture.yaw_damping)
                          if posture.reference == 'balance'
                          else posture_command(obs, dynamics, posture))
    if 'feedforward' in enabled:
        out['feedforward'] = JointCommand(feedforward_torque(obs, params.feedforward))
    if 'weight_transfer' in enabled:
        out['weight_transfer'] = JointCommand(
            weight_transfer_torque(obs, dynamics, params.weight_transfer))
    if 'heel' in enabled:
        out['heel'] = JointCommand(heel_torque(obs, params.heel))
    if 'arm_assist' in enabled:
        out['arm_assist'] = JointCommand(arm_assist_torque(obs, params.arm_assist))
    if 'yaw' in enabled:
        out['yaw'] = JointCommand(yaw_torque(obs, params.yaw))
    return out


def gait_manager_torques(obs: Observation, dynamics: GaitDynamics,
                         params: GaitManagerParameters) -> dict[str, np.ndarray]:
    """Return {source: 18-vector torque [N m]} at ``obs`` for the enabled sources only."""
    return {source: command.torque(obs.q, obs.v)
            for source, command in gait_manager_commands(obs, dynamics, params).items()}


def total_torque(torques: Mapping[str, np.ndarray]) -> np.ndarray:
    """Sum of the per-source torques (18 entries [N m]; zeros if there is none)."""
    total = zeros()
    for tau in torques.values():
        total += tau
    return total


def head_offset(obs: Observation, dynamics: GaitDynamics,
                params: GaitManagerParameters) -> np.ndarray:
    """(dy, dz) [m] to add to visual lifting's y_d, z_d: the moving-stance shift while the
    posture source is enabled with the 'moving' reference, else (0, 0)."""
    del dynamics  # the shift is a function of time only; kept for a uniform signature
    if 'posture' not in params.enabled:
        return np.zeros(2)
    return head_offset_of(obs, params.posture)
