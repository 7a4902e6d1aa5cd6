"""Gait-manager entry point: every gait-manager torque source, ROS-free (docs/model.md,
gait-manager sources).

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

from collections.abc import Mapping
from dataclasses import dataclass
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
from gait_manager.posture import PostureParameters, posture_command
from gait_manager.yaw import YawParameters, yaw_torque
from iceskate_sim.command import JointCommand
from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.observation import Observation
from iceskate_sim.parameters import block, check_fields, from_mapping, setting
from iceskate_sim.stance import StanceSchedule

SOURCES = ('posture', 'feedforward', 'weight_transfer', 'heel', 'arm_assist', 'yaw')


@dataclass(frozen=True)
class GaitManagerParameters:
    """All gait-manager parameter blocks and the set of enabled sources (default: all). Each
    block and ``enabled`` is a ``block``/``setting`` with its description."""

    posture: PostureParameters = block(
        PostureParameters, "posture stabiliser and stance reference (source 'posture')")
    balance: BalanceParameters = block(
        BalanceParameters, "walking stabiliser (source 'posture' with reference 'balance')")
    feedforward: FeedforwardParameters = block(
        FeedforwardParameters, "swing pulses and push-off (source 'feedforward')")
    weight_transfer: WeightTransferParameters = block(
        WeightTransferParameters, "weight transfer after heel strike (source 'weight_transfer')")
    heel: HeelParameters = block(HeelParameters, "heel-first landing input (source 'heel')")
    arm_assist: ArmAssistParameters = block(
        ArmAssistParameters, "arm assist of steps 1-3 (source 'arm_assist')")
    yaw: YawParameters = block(YawParameters, "torso-yaw input of eq. (10) (source 'yaw')")
    enabled: frozenset[str] = setting(frozenset(SOURCES), 'torque sources to compute and send',
                                      choices=SOURCES)

    def __post_init__(self) -> None:
        """Check every block's type and the enabled set (GaitManagerError naming the key)."""
        check_fields(self, GaitManagerError)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> GaitManagerParameters:
        """Build from a nested mapping {block: {key: value}, 'enabled': [sources]}.

        Missing blocks keep their defaults; unknown keys and bad values raise
        GaitManagerError with a message naming the key (e.g. 'posture.stiffness').
        """
        return from_mapping(cls, d, GaitManagerError)


def gait_manager_commands(obs: Observation, dynamics: GaitDynamics,
                          params: GaitManagerParameters,
                          head_start_y: float = 0.0) -> dict[str, JointCommand]:
    """Return {source: JointCommand} for the enabled sources only, in SOURCES order.

    The posture stabiliser carries a joint impedance (its PD runs at the physics rate); the
    other sources are torques held over the control period. ``dynamics`` is used only by
    'posture' and 'weight_transfer'; ``head_start_y`` [m] (the head top's y at t = 0) only by
    the walking stabiliser's pace term.
    """
    out: dict[str, JointCommand] = {}
    enabled = params.enabled
    if 'posture' in enabled:
        posture = params.posture
        out['posture'] = (balance_command(obs, dynamics, params.balance, posture.yaw_stiffness,
                                          posture.yaw_damping, head_start_y)
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
                         params: GaitManagerParameters,
                         head_start_y: float = 0.0) -> dict[str, np.ndarray]:
    """Return {source: 18-vector torque [N m]} at ``obs`` for the enabled sources only
    (``head_start_y`` as in ``gait_manager_commands``)."""
    return {source: command.torque(obs.q, obs.v) for source, command
            in gait_manager_commands(obs, dynamics, params, head_start_y).items()}


def total_torque(torques: Mapping[str, np.ndarray]) -> np.ndarray:
    """Sum of the per-source torques (18 entries [N m]; zeros if there is none)."""
    total = zeros()
    for tau in torques.values():
        total += tau
    return total


def head_stance(params: GaitManagerParameters) -> StanceSchedule | None:
    """The moving stance visual lifting's head target should follow: the posture source's
    schedule while it runs with the 'moving' reference, else None (no shift)."""
    if 'posture' not in params.enabled or params.posture.reference != 'moving':
        return None
    return params.posture.stance
